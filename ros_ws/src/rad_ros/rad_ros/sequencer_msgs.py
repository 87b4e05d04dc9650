"""rad_msgs/Sequence <-> rad_core.sequencing.decide.sequencer (Ranking), and AssemblyAction <-> SceneAction.

Message types only, never rclpy: the sequencer node converts a request with
`sequence_inputs` and answers with `fill_sequence_response`; its clients build the
request with `sequence_request` and read the answer with `ranking_from_response`.
"""

from __future__ import annotations

import math

from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.gamp.action import SceneAction
from rad_core.sequencing.decide.sequencer import Ranking
from rad_msgs.msg import AssemblyAction, StageTiming
from rad_msgs.srv import Sequence

from rad_ros.conversions import placement_from_msg, placement_to_msg, scene_from_request


def action_to_msg(action: SceneAction) -> AssemblyAction:
    msg = AssemblyAction(block_id=action.block_id, unit=int(action.unit), target=action.target,
                         rotation=int(action.rotation))
    msg.cell.i, msg.cell.j, msg.cell.k = (int(v) for v in action.cell)
    return msg


def action_from_msg(msg: AssemblyAction) -> SceneAction:
    return SceneAction(msg.block_id, int(msg.unit), msg.target, (int(msg.cell.i), int(msg.cell.j), int(msg.cell.k)),
                       int(msg.rotation))


def sequence_request(scene: Scene, placements, start=None, max_actions: int = 0,
                     scorer_only: bool = False) -> Sequence.Request:
    """The request ranking the next actions of `scene` (its current state) for these placements."""
    return Sequence.Request(scene_json=scene.dumps(), allocation=[placement_to_msg(p) for p in placements],
                            start_positions=[] if start is None else [float(v) for v in start],
                            max_actions=int(max_actions), scorer_only=bool(scorer_only))


def sequence_inputs(request) -> tuple[Scene, list, list[float] | None, int]:
    """(scene, placements, start joints or None, max_actions) of a request; RadError names what is wrong."""
    scene = scene_from_request(request.scene, request.scene_json)
    placements = [placement_from_msg(p) for p in request.allocation]
    start = [float(v) for v in request.start_positions] or None
    return scene, placements, start, int(request.max_actions)


def fill_sequence_response(response, ranking: Ranking, policy: str):
    response.success, response.reason = True, ranking.reason
    response.actions = [action_to_msg(a) for a in ranking.actions]
    # The message carries float64: a value of +-inf (HEUR's "never") goes as is, NaN would not compare.
    response.values = [float(v) if not math.isnan(v) else -math.inf for v in ranking.values]
    response.terminate = bool(ranking.terminate)
    response.fallbacks = int(ranking.fallbacks)
    response.policy = policy
    response.timings = [StageTiming(stage=k, seconds=float(v)) for k, v in ranking.timings.items()]
    return response


def ranking_from_response(response) -> Ranking:
    """The ranking a successful response carries; RadError with the sequencer's reason otherwise."""
    if not response.success:
        raise RadError(f'sequencer: {response.reason}')
    if len(response.values) != len(response.actions):
        raise RadError(f'sequencer: {len(response.values)} values for {len(response.actions)} actions')
    if response.fallbacks > len(response.actions):
        raise RadError(f'sequencer: {response.fallbacks} fallbacks among {len(response.actions)} actions')
    return Ranking([action_from_msg(a) for a in response.actions], [float(v) for v in response.values],
                   bool(response.terminate), response.reason, {t.stage: float(t.seconds) for t in response.timings},
                   fallbacks=int(response.fallbacks))

"""Moving a block out of the way on the table before a blocked pick (gamp.action.MotionPlanner),
and the plan, the twin and execution following the blocks it moves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rad_core.cell.motion import Motion
from rad_core.domain.scene import Scene
from rad_core.domain.shapes import LayoutConfig, footprint, move_aside_spot
from rad_core.gamp.action import MotionPlanner, SceneAction, table_neighbours
from rad_core.gamp.planner import GampConfig
from rad_core.sequencing.planning.plan import PlanStep, local_motion_planner

from scenes import packed
from scenes import scene as make_scene

REPO = Path(__file__).resolve().parents[2]


def hard(name: str) -> Scene:
    return Scene.loads((REPO / 'scenes' / 'hard' / f'{name}.json').read_text())


def gap_between(scene: Scene, a: str, b: str) -> float:
    """Smallest face-to-face gap (m, Chebyshev) between two blocks' units on the table."""
    fa, fb = (footprint(scene.block(x), scene.block_types, scene.unit) for x in (a, b))
    return float(np.abs(fa[:, None] - fb[None]).max(axis=-1).min()) - scene.unit


@pytest.fixture(scope='module')
def planners():
    plain, moving = MotionPlanner(GampConfig(move_aside=0)), MotionPlanner(GampConfig())
    yield plain, moving
    plain.close()
    moving.close()


def test_a_spot_is_free_within_reach_clear_of_targets_and_of_the_block_to_free():
    scene = hard('pento_floor')
    config = LayoutConfig()
    position, yaw = move_aside_spot(scene, 'b1', clear_of=['b4'])
    from rad_core.sequencing.planning.plan import moved as moved_scene
    moved = moved_scene(scene, 'b1', position, yaw)
    units = footprint(moved.block('b1'), moved.block_types, moved.unit)
    r = np.linalg.norm(units, axis=1)
    assert np.all((r >= config.reach[0]) & (r <= config.reach[1]))
    for other in moved.blocks:
        if other.id != 'b1':
            assert gap_between(moved, 'b1', other.id) >= config.gap - 1e-9, other.id
    assert gap_between(moved, 'b1', 'b4') >= 0.12 - 1e-9
    for t in moved.targets:
        lo, hi = t.bounds(moved.unit)
        assert not np.any(np.all((units > lo[:2] - moved.unit / 2) & (units < hi[:2] + moved.unit / 2), axis=1))
    # Nowhere to go: a reach band too narrow for any block.
    assert move_aside_spot(scene, 'b1', LayoutConfig(reach=(0.40, 0.401))) is None


def test_table_neighbours_are_the_close_blocks_on_the_table_nearest_first():
    scene = hard('pento_floor')
    near = table_neighbours(scene, 'b4')
    assert 'b1' in near
    gaps = [gap_between(scene, 'b4', b) for b in near]
    assert gaps == sorted(gaps) and max(gaps) < 0.08


def test_a_blocked_pick_moves_the_neighbour_aside_first_and_plans_both_motions(planners):
    plain, moving = planners
    scene = packed()
    target = scene.targets[0]
    action = SceneAction('b4', 0, target.name, tuple(target.filled[-1]), 0)
    blocked, _, _ = plain(scene, action, move_aside=True)         # move_aside 0 in the config: never
    assert not blocked.success and blocked.failure == 'grasp' and 'hits block b1' in blocked.reason
    assert 'moving a neighbour aside' not in blocked.reason
    assert not moving(scene, action)[0].success           # asked for one pick and place: as blocked
    result, position, yaw = moving(scene, action, move_aside=True)
    assert result.success, result.reason
    [aside] = result.moved_aside
    assert aside['block'] == 'b1'
    # One motion: pick and place b1 on the table, then pick and place b4; two grasps, two releases.
    actions = [g.action for g in result.motion.gripper]
    assert actions.count('grasp') == 2 and actions.count('release') == 2
    assert actions.index('release') < len(actions) - 2
    # It starts where the plain motion would (home) and is as legal (limits checked by plan_motion).
    again = Motion.from_dict(result.motion.to_dict())
    assert len(again.trajectories) == len(result.motion.trajectories) >= 6
    # The planning world is as it was: b1 still where the scene has it.
    p, _ = moving.world.block_pose('b1')
    assert np.allclose(p, scene.block('b1').position, atol=1e-6)


def test_move_aside_off_says_why_and_a_block_nothing_frees_keeps_its_reason(planners):
    _, moving = planners
    # b5's grasps hit b8 and b9 (1 and 1.5 cm off), 2x2 blocks the hand cannot take from above at a 4 cm unit.
    u = 0.04
    o4 = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
    blocks = {'b5': ('cube', 0.45, -0.25), 'b8': ('O4', 0.45 + u + 0.01, -0.25),
              'b9': ('O4', 0.45 - u, -0.25 + u + 0.015)}
    scene = make_scene(unit=u, types={'cube': [[0, 0, 0]], 'O4': o4},
                       blocks=[{'id': b, 'type': t, 'position': [x, y, u / 2], 'yaw': 0}
                               for b, (t, x, y) in blocks.items()],
                       targets=[{'name': 't', 'origin': [0.4, 0.25, u / 2], 'size': [2, 1, 1], 'filled': [[0, 0, 0]]}])
    target = scene.targets[0]
    result, _, _ = moving(scene, SceneAction('b5', 0, target.name, tuple(target.filled[0]), 0), move_aside=True)
    assert not result.success and result.failure == 'grasp'
    assert 'moving a neighbour aside first: b8' in result.reason and 'no top-down grasp' in result.reason


def test_plan_steps_carry_the_moves_and_the_scene_after_follows_them(planners):
    _, moving = planners
    scene = packed()
    target = scene.targets[0]
    plan = local_motion_planner(moving)(scene, SceneAction('b4', 0, target.name, tuple(target.filled[-1]), 0), None,
                                        move_aside=True)
    assert plan.success and [d['block'] for d in plan.moved_aside] == ['b1']
    step = PlanStep('b4', 'cube', target.name, 0, [list(target.filled[-1])], position=[0.45, 0.1, 0.02],
                    motion=plan.motion, moved_aside=plan.moved_aside)
    assert PlanStep.from_dict(step.to_dict()) == step
    after = step.scene_after(scene)
    assert list(after.block('b1').position) == pytest.approx(plan.moved_aside[0]['position'])
    assert list(after.block('b4').position) == pytest.approx([0.45, 0.1, 0.02])
    # A step with nothing moved aside keeps its dict form as before (no key).
    assert 'moved_aside' not in PlanStep('b0', 'cube', 't', 0, [[0, 0, 0]]).to_dict()


def test_the_twin_puts_moved_blocks_where_the_step_says():
    from rad_core.sequencing.execution.twin_build import build_teleported
    scene = hard('pento_floor')
    spot, yaw = move_aside_spot(scene, 'b1', clear_of=['b4'])
    target = scene.targets[0]
    position = target.cell_center(tuple(target.filled[0]), scene.unit)
    step = PlanStep('b4', 'cube', target.name, 0, [list(target.filled[0])], position=list(position),
                    moved_aside=[{'block': 'b1', 'position': list(spot), 'yaw': yaw}])
    registered = build_teleported(scene, [step])
    assert np.allclose(registered.scene.block('b1').position[:2], spot[:2], atol=0.005)

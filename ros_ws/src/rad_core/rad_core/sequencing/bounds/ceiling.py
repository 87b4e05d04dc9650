"""What the best order of the allocation's poses can build without the robot.

The ceiling a sequencer is measured against: a depth-first search over the
orders in which the allocated poses can be filled, each placement judged by the
env's own stability check (physics), that returns the largest target coverage
any order reaches. Without the robot, which block of a type fills a pose does
not matter (same shape, same cells), so a search state is the set of poses
filled; states are memoized and the search stops at `max_states`, answering
None (unknown) rather than a wrong number.
"""

from __future__ import annotations

from rad_core.env.mdp import AssemblyEnv
from rad_core.sequencing.decide.actions import AllocationActions


def coverage_ceiling(env: AssemblyEnv, space: AllocationActions, max_states: int = 20_000) -> float | None:
    """Best coverage reachable from env's state by the allocation's poses; None when
    the search needed more than max_states states. env's state is left unchanged."""
    guide = space.guide
    start = env.snapshot()
    seen: set[frozenset[int]] = set()
    best = env.coverage()

    def pose_actions():
        # One representative action per open pose (the first block of its type).
        out = {}
        for action in space(env):
            cells, _ = env.resulting_cells(action)
            key = frozenset(int(c) for c in cells)
            out.setdefault(key, action)
        return list(out.values())

    def search(filled: frozenset[int]) -> bool:
        nonlocal best
        if filled in seen:
            return True
        seen.add(filled)
        if len(seen) > max_states:
            return False
        best = max(best, env.coverage())
        if best >= 1.0:
            return True
        here = env.snapshot()
        for action in pose_actions():
            result = env.step(action)   # an invalid placement changes nothing but ends the episode
            if not result.outcome.is_invalid:
                best = max(best, env.coverage())
                key = frozenset(k for k, pc in enumerate(guide.pose_cells) if (env.state.occupancy[pc] >= 0).all())
                if not result.done and not search(key):
                    env.restore(here)
                    return False
            env.restore(here)
            if best >= 1.0:
                return True
        return True

    try:
        finished = search(frozenset())
    finally:
        env.restore(start)
    return best if finished else None

"""Bounds on what the arm can still cover from a state: the blocks it can still pick
(`blocks_left`) and the coverage bound without what it can never do, with a hand order
(`ArmCoverageBound`), for the robot ceiling and the course line."""

from __future__ import annotations

import math

import numpy as np
from ortools.sat.python import cp_model

from rad_core.allocation.constraints import cp_solver
from rad_core.allocation.cpsat import max_coverage
from rad_core.allocation.order import candidate_poses, cover_candidates, order_model
from rad_core.allocation.placements import Candidate
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Scene


def blocks_left(scene: Scene, env, unpickable) -> dict[str, int]:
    """The blocks per type the env (an `AssemblyEnv`) has not placed, but for the indices in
    `unpickable` (blocks the arm cannot pick where they lie)."""
    counts: dict[str, int] = {}
    for b in env.unplaced():
        if b not in unpickable:
            name = scene.blocks[b].type
            counts[name] = counts.get(name, 0) + 1
    return counts


class ArmCoverageBound:
    """`cpsat.coverage_bound` of the states of one scene, without what the arm can never do, and
    (`ordered`) with an order the hand can place it in.

    A bound over what any continuation can still cover, for the robot ceiling: the most target
    cells disjoint free poses of the blocks left can cover, where the poses are those an allocation
    may propose (at least as many target as non-target cells, as `cpsat` enumerates them with a
    support rule: no scaffolding outside the target, fillers worth 0 under an overhang) and the
    poses and blocks are only those the arm might still build. Left out, as `arm_filter` leaves
    them out whatever the order:
    types with no top-down grasp, blocks on the table it cannot pick where they lie (blocks are
    not moved there), poses whose every grasp is out of reach; and, of the state, poses the hand
    can no longer place (`HandBlocked`). Each is conservative, so it stays a bound; it is tighter
    than `coverage_bound` where built cells hem poses in.

    ordered: the poses chosen must also have an order (`allocation.order.order_model`) in
    which each, when its turn comes, has a way of being held that no pose before it is in the
    way of, and rests on something. Every build GAMP verifies has one: GAMP refuses what
    `HandBlocked` blocks and the MDP a block resting on nothing, and blocks stay where they are
    put. So it is still a bound, and the one that sees that the last block of a flush, closed
    course has nowhere for the fingers (a 3x3x3 cube: 26 of 27 cells at most). CP-SAT proves it
    within `time_limit_s` (its proven bound where the limit cuts it); the looser bound is
    computed first and kept where the ordered one is not proven below it.

    Call it with an env (`AssemblyEnv`) of the scene between steps."""

    def __init__(self, scene: Scene, grid: Grid, gamp=None, time_limit_s: float = 2.0, ordered: bool = True):
        self.candidates, _, self.hand, self.unpickable = cover_candidates(scene, grid, gamp)
        self.grid, self.scene, self.time_limit_s, self.ordered = grid, scene, time_limit_s, ordered
        self.hand_blocked = 0     # poses the last call left out as hand-blocked
        self.last_loose = None    # the last call's bound without the order (None before a call)
        self._memo: dict[tuple, tuple] = {}     # a state's (bound, loose bound, hand-blocked)

    def _state(self, env) -> tuple[np.ndarray, dict[str, int], tuple]:
        """The env's built cells, the blocks left the arm can pick, and the memo's key of both."""
        occupied = env.state.occupancy >= 0
        counts = blocks_left(self.scene, env, self.unpickable)
        return occupied, counts, (occupied.tobytes(), tuple(sorted(counts.items())))

    def __call__(self, env, time_limit_s: float | None = None) -> float:
        """The bound of the env's state (remembered per state); time_limit_s: CP-SAT's for each of
        the two bounds here (default the bound's own)."""
        occupied, counts, key = self._state(env)
        known = self._memo.get(key)
        if known is not None:
            value, self.last_loose, self.hand_blocked = known
            return value
        free = [c for c in self.candidates if not occupied[list(c.cell_ids)].any()]
        kept = [c for c in free if not self.hand(c, occupied)]
        self.hand_blocked = len(free) - len(kept)
        limit = self.time_limit_s if time_limit_s is None else time_limit_s
        loose = self.last_loose = max_coverage(self.grid, occupied, kept, counts, limit)
        filled = int((self.grid.is_target & occupied).sum()) / max(1, int(self.grid.is_target.sum()))
        value = loose
        if self.ordered and loose > filled:     # with nothing to place, nothing the order can take away
            value = min(loose, self.ordered_bound(occupied, kept, counts, limit))
        self._memo[key] = (value, loose, self.hand_blocked)
        return value

    def cap(self, env, value: float) -> float:
        """Lower the remembered bound of the env's state (asked before) to `value` where that is
        tighter (another bound of the same state, `sequencing.planning.courses.course_bound`); the bound now."""
        key = self._state(env)[2]
        bound, loose, blocked = self._memo[key]
        self._memo[key] = (min(bound, value), loose, blocked)
        return self._memo[key][0]

    def ordered_bound(self, occupied: np.ndarray, kept: list[Candidate], counts: dict[str, int],
                      time_limit_s: float) -> float:
        """The coverage bound over `kept` (free poses the hand may still place) with a hand order."""
        grid = self.grid
        total = int(grid.is_target.sum())
        filled = int((grid.is_target & occupied).sum())
        poses, _ = candidate_poses(grid, self.hand, occupied, kept, counts)
        if not poses:
            return filled / total
        model, *_ = order_model(grid, occupied, poses, counts)
        solver = cp_solver(time_limit_s)
        status = solver.solve(model)
        if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
            return 1.0                          # nothing proven: the caller keeps the looser bound
        return min(1.0, (filled + math.floor(float(solver.best_objective_bound) + 1e-9)) / total)

"""CP-SAT building blocks that the allocation and the hand's order model share: a solver that
leaves signals alone, and the 'stable' support rule as the sets of cells that can hold a pose up."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from ortools.sat.python import cp_model

from rad_core.domain import support
from rad_core.domain.grid import Grid


def cp_solver(time_limit_s: float, num_workers: int = 1, seed: int | None = None) -> cp_model.CpSolver:
    """A CP-SAT solver with a wall-time limit and `num_workers` workers (and `seed`, where given),
    that leaves SIGINT alone: CP-SAT would install its own handler for the solve and leave SIGINT
    at the default action afterwards, so a node would die by the signal instead of shutting down.
    Signals belong to the process owner, not to a library call."""
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = float(time_limit_s)
    solver.parameters.num_workers = num_workers
    if seed is not None:
        solver.parameters.random_seed = seed
    solver.parameters.catch_sigint_signal = False
    return solver


def support_options(grid: Grid, ids: list[int], occupied, holders: dict) -> list[list[list]] | None:
    """How a pose (its cell ids) can stand, as the 'stable' rule asks: None where it stands on the
    table or built cells whatever else is chosen; else, per sufficient support set that can be held
    up, per unit of it not resting already, `holders` of the cell below it (holders: cell -> what
    may fill it, e.g. the poses covering it). Sets with a unit nothing can hold up are left out."""
    below, sets, trivial = _support_sets(grid, ids, occupied)
    if any(set(S) <= trivial for S in sets):
        return None
    out = []
    for S in sets:
        unders = [holders.get(below[i], []) if below[i] >= 0 else [] for i in S if i not in trivial]
        if all(unders):
            out.append(unders)
    return out


def _support_sets(grid: Grid, ids: list[int], occupied):
    """(cell below each unit, the sufficient support sets of the pose's bottom units,
    the bottom units already resting on the table or an occupied cell). Studded bricks (`grid.clutch`)
    are held by any one stud: each bottom unit is a set (the statics of the whole say how far out)."""
    own = set(ids)
    below = [int(grid.below_idx[c]) for c in ids]
    bottom = [i for i, b in enumerate(below) if b not in own]
    trivial = {i for i in bottom if grid.on_table[ids[i]] or (below[i] >= 0 and occupied[below[i]])}
    if grid.clutch is not None:
        return below, tuple((i,) for i in bottom), trivial
    return below, _sufficient_supports(grid.ijk[ids].tobytes(), tuple(bottom)), trivial


@lru_cache(maxsize=65536)
def _sufficient_supports(ijk: bytes, bottom: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """`support.sufficient_supports` of the pose with these cells (ijk, bytes of a [k, 3] int64
    array, as `Grid.ijk` holds them): the same candidate poses come back in every re-allocation of
    a scene, so it is remembered."""
    cells = np.frombuffer(ijk, dtype=np.int64).reshape(-1, 3)
    return tuple(support.sufficient_supports(cells, list(bottom)))


def rests_now(grid: Grid, ids, occupied) -> bool:
    """Whether a pose (its cell ids) would stand on what is there now: some sufficient set
    of its bottom units rests on the table or on occupied cells (the 'stable' rule)."""
    _, sets, trivial = _support_sets(grid, [int(i) for i in ids], occupied)
    return any(set(S) <= trivial for S in sets)

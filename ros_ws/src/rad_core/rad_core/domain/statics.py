"""Whether a structure of blocks stands as a whole: forces through its contacts balance gravity.

`support` asks one block at a time whether its centre of mass lies over what holds it. That misses
load that gathers: plates stacked each a little further out, every one over the plate below, tip
the lowest of them once the top one is on. Here every block is a rigid body of unit cubes (uniform
density) resting on the table or on the blocks under it, on unit squares. Each square carries a
compressive force at each of its four corners, set `margin` units in from its edges (a centre of
mass exactly over an edge tips in physics too, `support.com_inside`). The structure stands when
corner forces >= 0 exist under which every block's weight, the forces from below and the forces of
the blocks on it balance: three equations per block (the vertical force and the moments about x
and y), a linear program solved by GLOP, OR-Tools' linear solver. Side contacts, friction and
studs carry nothing here.

Where no such forces exist, the same program with slack on each block's equations, the slack
minimised, names the blocks whose balance needs it: those that would tip. A structure whose
every block has each bottom unit on the table or on another block stands without a solve (each
unit's weight goes straight down), so the program runs only where something overhangs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rad_core.domain.grid import Grid

MARGIN = 0.05
"""How far (cell units) inside a contact square's edges its corner forces act."""

_TOL = 1e-6


@dataclass(frozen=True)
class Statics:
    """The verdict on a structure: whether it stands, and if not, the pieces (indices into what was
    asked) whose balance needs help that nothing gives."""

    stands: bool
    falling: tuple[int, ...] = ()

    def __bool__(self) -> bool:
        return self.stands


def _under(grid: Grid, owner: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Per unit: what is below it: -1 the table (or ground), a piece index, -2 nothing."""
    below = grid.below_idx[cells]
    under = np.where(below >= 0, owner[np.maximum(below, 0)], -2)
    return np.where(grid.on_table[cells], -1, under)


def _owner(grid: Grid, pieces: Sequence[np.ndarray], ground) -> np.ndarray:
    owner = np.full(grid.num_cells, -2, dtype=int)
    if ground is not None:
        owner[np.asarray(ground, dtype=bool)] = -1
    for n, cells in enumerate(pieces):
        owner[cells] = n
    return owner


def overhangs(grid: Grid, pieces: Sequence[Sequence[int]], ground=None) -> list[int]:
    """The pieces (indices) with a bottom unit over nothing: only these can make a structure tip."""
    pieces = [np.asarray(p, dtype=int).ravel() for p in pieces]
    owner = _owner(grid, pieces, ground)
    return [n for n, cells in enumerate(pieces) if (_under(grid, owner, cells) == -2).any()]


def structure_statics(grid: Grid, pieces: Sequence[Sequence[int]], ground=None, margin: float = MARGIN) -> Statics:
    """Whether the pieces (grid cell ids each) stand together on the table (module docstring).
    ground: a mask of grid cells built before, taken as fixed as the table (None: none)."""
    pieces = [np.asarray(p, dtype=int).ravel() for p in pieces]
    owner = _owner(grid, pieces, ground)
    if not any((_under(grid, owner, cells) == -2).any() for cells in pieces):
        return Statics(True)
    from ortools.linear_solver import pywraplp
    solver = pywraplp.Solver.CreateSolver('GLOP')
    xy = grid.centres[:, :2] / grid.unit
    com = [xy[p].mean(axis=0) for p in pieces]
    rows = []                     # per piece: vertical force, moment about x, moment about y
    for n, cells in enumerate(pieces):
        rows.append([solver.Constraint(float(len(cells)), float(len(cells))),
                     solver.Constraint(0.0, 0.0), solver.Constraint(0.0, 0.0)])
    d = 0.5 - margin
    inf = solver.infinity()
    for n, cells in enumerate(pieces):
        for c, m in zip(cells, _under(grid, owner, cells)):
            if m == -2 or m == n:
                continue
            for dx in (-d, d):
                for dy in (-d, d):
                    f = solver.NumVar(0.0, inf, '')
                    x, y = xy[c, 0] + dx, xy[c, 1] + dy
                    for k, sign in ((n, 1.0), (int(m), -1.0)):
                        if k < 0:
                            continue                  # the table takes whatever it is given
                        rows[k][0].SetCoefficient(f, sign)
                        rows[k][1].SetCoefficient(f, sign * (y - com[k][1]))
                        rows[k][2].SetCoefficient(f, sign * (x - com[k][0]))
    slack = []
    for n, equations in enumerate(rows):
        for ct in equations:
            up, down = solver.NumVar(0.0, inf, ''), solver.NumVar(0.0, inf, '')
            ct.SetCoefficient(up, 1.0)
            ct.SetCoefficient(down, -1.0)
            slack.append((n, up, down))
    objective = solver.Objective()
    for _, up, down in slack:
        objective.SetCoefficient(up, 1.0)
        objective.SetCoefficient(down, 1.0)
    objective.SetMinimization()
    if solver.Solve() != pywraplp.Solver.OPTIMAL:
        return Statics(False, tuple(range(len(pieces))))
    scale = max(1.0, float(sum(len(p) for p in pieces)))
    if objective.Value() <= _TOL * scale:
        return Statics(True)
    falling = sorted({n for n, up, down in slack if up.solution_value() + down.solution_value() > _TOL * scale})
    return Statics(False, tuple(falling))


def order_statics(grid: Grid, pieces: Sequence[Sequence[int]], ground=None,
                  margin: float = MARGIN) -> tuple[list[int], list[int]]:
    """(the order the pieces are placed in, the pieces that wait to the end), indices into `pieces`,
    of a walk that keeps the structure standing.

    The pieces go on `ground` (cells built before, as fixed as the table) in the order given; one
    that would leave a structure that does not stand waits, and is tried again after each piece
    placed after it (a block further back may hold it down). The walk does not ask whether a piece
    that waited can still be reached (GAMP does, step by step)."""
    placed, walk, waiting = [], [], []
    for n, cells in enumerate(pieces):
        trial = placed + [np.asarray(cells, dtype=int).ravel()]
        if not structure_statics(grid, trial, ground, margin):
            waiting.append(n)
            continue
        placed = trial
        walk.append(n)
        progress = True
        while progress and waiting:
            progress = False
            for k in list(waiting):
                trial = placed + [np.asarray(pieces[k], dtype=int).ravel()]
                if structure_statics(grid, trial, ground, margin):
                    placed, progress = trial, True
                    walk.append(k)
                    waiting.remove(k)
    return walk, waiting

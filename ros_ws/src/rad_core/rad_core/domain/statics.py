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
from rad_core.domain.support import convex_hull

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
    patches: dict[tuple[int, int], list] = {}       # (upper piece, lower piece or -1): corner points
    for n, cells in enumerate(pieces):
        for c, m in zip(cells, _under(grid, owner, cells)):
            if m != -2 and m != n:
                patches.setdefault((n, int(m)), []).extend(
                    (xy[c, 0] + dx, xy[c, 1] + dy) for dx in (-d, d) for dy in (-d, d))
    for (n, m), corners in patches.items():
        # Forces anywhere on a contact patch are forces at the corners of its convex hull.
        for x, y in convex_hull(np.asarray(corners)):
            f = solver.NumVar(0.0, inf, '')
            for k, sign in ((n, 1.0), (m, -1.0)):
                if k < 0:
                    continue                  # the table (or ground) takes whatever it is given
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
    that would leave a structure that does not stand waits, and is tried again once a piece placed
    after it could hold it down: one on a piece its own load reaches, or under it. The walk does
    not ask whether a piece that waited can still be reached (GAMP does, step by step).

    A piece every unit of which rests on something, on pieces that each rest so all the way down,
    leaves a standing structure standing (its weight goes straight down, column by column), so
    the program is solved only for pieces whose load reaches an overhang."""
    walk_ = _Walk(grid, ground, margin)
    walk, waiting = [], []
    pieces = [np.asarray(p, dtype=int).ravel() for p in pieces]
    for n, cells in enumerate(pieces):
        added, _ = walk_.add(cells)
        if not added:
            waiting.append(n)
            continue
        walk.append(n)
        new = [len(walk) - 1]                       # the walk's own indices: walk[i] is pieces' index
        while new and waiting:
            # A piece can hold down what waits only through the pieces its load reaches.
            reach = set(new).union(*(walk_.closure(walk_.placed[i]) for i in new))
            new = []
            for k in list(waiting):
                if reach & walk_.closure(pieces[k]) and walk_.add(pieces[k])[0]:
                    walk.append(k)
                    waiting.remove(k)
                    new.append(len(walk) - 1)
    return walk, waiting


class _Walk:
    """A standing structure that pieces are added to, one at a time, each only if it still stands."""

    def __init__(self, grid: Grid, ground, margin: float):
        self.grid, self.ground, self.margin = grid, ground, margin
        self.owner = _owner(grid, [], ground)
        self.placed: list[np.ndarray] = []

    def _under_pieces(self, cells: np.ndarray, n: int) -> tuple[set[int], bool]:
        """(the placed pieces right under cells, whether a unit of them is over nothing)."""
        under = _under(self.grid, self.owner, cells)
        return {int(m) for m in under if m >= 0 and m != n}, bool((under == -2).any())

    def _down(self, start: set[int]) -> tuple[set[int], bool]:
        """(the placed pieces reached going down from `start`, start included; whether one of them
        has a unit over nothing)."""
        seen, todo, over = set(start), list(start), False
        while todo:
            below, over_nothing = self._under_pieces(self.placed[todo.pop()], -3)
            over |= over_nothing
            todo += [m for m in below - seen]
            seen |= below
        return seen, over

    def closure(self, cells: np.ndarray) -> set[int]:
        """The placed pieces the load of `cells` reaches: those right under them, and under those."""
        return self._down(self._under_pieces(cells, -3)[0])[0]

    def add(self, cells: np.ndarray) -> tuple[bool, bool]:
        """(added, whether its load reaches an overhang: it may hold down what waits)."""
        n = len(self.placed)
        below, over_nothing = self._under_pieces(cells, n)
        heavy = over_nothing or self._down(below)[1]
        if heavy and not structure_statics(self.grid, self.placed + [cells], self.ground, self.margin):
            return False, heavy
        self.placed.append(cells)
        self.owner[cells] = n
        return True, heavy

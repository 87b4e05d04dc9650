"""Whether a structure of blocks stands as a whole: forces through its contacts balance gravity.

`support` asks one block at a time whether its centre of mass lies over what holds it. That misses
load that gathers: plates stacked each a little further out, every one over the plate below, tip
the lowest of them once the top one is on. Here every block is a rigid body of unit cubes (uniform
density) resting on the table or on the blocks under it, on unit squares. Each square carries a
compressive force at each of its four corners, set `margin` units in from its edges (a centre of
mass exactly over an edge tips in physics too, `support.com_inside`). The structure stands when
corner forces >= 0 exist under which every block's weight, the forces from below and the forces of
the blocks on it balance: three equations per block (the vertical force and the moments about x
and y), a linear program solved by GLOP, OR-Tools' linear solver. Side contacts and friction carry
nothing here.

Studded bricks (LEGO, Duplo) also hold by clutch: a stud gripped by the brick on it resists a pull
up to a limit. With `clutch` given, every unit square where a unit of one block rests on a unit of
another (or on `ground`, built before and fixed, which takes the pull) holds one stud (the stud
pitch is the grid's unit), and the stud carries a pull 0 <= t <= clutch at the square's centre,
down on the upper block and up on the lower one. This is the force model of the published LEGO
stability analyses, kept linear: each brick balanced under gravity, contact pushes and a bounded
pull at its knobs (Luo et al., "Legolization", SIGGRAPH Asia 2015; Liu et al., "StableLego", 2024,
whose knob friction is capped per contact point; Kollsker & Malaguti, EJOR 2021, with a capacity
per connection; Funes & Pollack, 1998, measured joint capacities). One capped pull per stud stands
for a knob's friction points. `clutch` is in units of one cell's weight (the caller converts
newtons); the table holds nothing down (rad's bricks sit loose on it) unless `table_clutch` (a baseplate,
``studs.baseplate``). The
stud is at the square's centre, the pushes `margin` in from its edges: a bar of L units resting on
one stud by its end needs a pull of L ((L - 1) / 2 / d - 1), d = 0.5 - margin (9.33 for L = 4).

Where no such forces exist, the same program with slack on each block's equations, the slack
minimised, names the blocks whose balance needs it: those that would fall. Why each falls: with
clutch, the program is solved again with the pull unlimited. A block that needs slack even then
tips over the edge of what holds it (or rests on nothing); for the others the clutch is what gives
way, and a third solve, the total pull beyond the limit minimised, names the connection that
must hold more than its studs can. A structure whose every block has each bottom unit on the table
or on another block stands without a solve (each unit's weight goes straight down; a pull only
adds forces that may go unused), so the program runs only where something overhangs.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rad_core.domain.grid import Grid
from rad_core.domain.support import convex_hull

MARGIN = 0.05
"""How far (cell units) inside a contact square's edges its corner forces act."""

TIPS = 'tips over the edge of what holds it'
FLOATS = 'rests on nothing'

_TOL = 1e-6
_TABLE, _NOTHING, _GROUND = -1, -2, -3        # what is under a unit, where it is not a piece
_PULL_COST = 1e-3                              # a pull within the limit costs a little: no idle pulls


@dataclass(frozen=True)
class Statics:
    """The verdict on a structure: whether it stands, and if not, the pieces (indices into what was
    asked) whose balance needs help that nothing gives."""

    stands: bool
    falling: tuple[int, ...] = ()
    why: tuple[str, ...] = ()
    """Aligned with `falling` (empty when not asked for): `FLOATS`, `TIPS`, or which stud connection
    pulls off, how much it must hold and how much its clutch gives (cell weights)."""

    def __bool__(self) -> bool:
        return self.stands

    def told(self, name, weight: float | None = None) -> list[tuple[int, str]]:
        """(falling piece, why) with the pieces named by `name(index)` and, given the `weight` (N) of a
        cell, forces in newtons rather than cell weights."""
        out = []
        for n, why in zip(self.falling, self.why or ('does not stand',) * len(self.falling)):
            why = re.sub(r'piece (\d+)', lambda m: name(int(m.group(1))), why)
            if weight is not None:
                why = re.sub(r"must hold ([\d.]+) times a cell's weight over (\d+) studs, the clutch gives ([\d.]+)",
                             lambda m: f'must hold {float(m.group(1)) * weight:.2f} N over {m.group(2)} studs, '
                                       f'the clutch gives {float(m.group(3)) * weight:.2f} N', why)
            out.append((n, why))
        return out


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


def structure_statics(grid: Grid, pieces: Sequence[Sequence[int]], ground=None, margin: float = MARGIN,
                      clutch: float | None = None, table_clutch: bool | None = None, explain: bool = True,
                      loads: Sequence[tuple[float, float, float] | None] | None = None) -> Statics:
    """Whether the pieces (grid cell ids each) stand together on the table (module docstring).
    loads: per piece, None or a push down on it besides its weight (the press that seats a brick on
    its studs): (how hard, in cell weights; where, x and y in cells as grid.centres[:, :2] / unit).
    ground: a mask of grid cells built before, taken as fixed as the table (None: none).
    clutch: the pull one stud connection holds, in cell weights (None: no studs, nothing pulls).
    table_clutch: whether the table's studs hold too (None: as the grid's scene says, a baseplate).
    explain: say why each falling piece falls (with clutch, one or two more solves, only when it does
    not stand)."""
    pieces = [np.asarray(p, dtype=int).ravel() for p in pieces]
    owner = _owner(grid, pieces, ground)
    if not any((_under(grid, owner, cells) == -2).any() for cells in pieces):
        return Statics(True)
    program = _Program(grid, pieces, owner, margin, clutch, _table_clutch(grid, table_clutch), loads)
    solved = program.solve()
    if solved is None:
        return Statics(False, tuple(range(len(pieces))),
                       ('the solver found no answer',) * len(pieces) if explain else ())
    stands, falling = solved
    if stands:
        return Statics(True)
    return Statics(False, falling, program.why(falling) if explain else ())


def _contacts(grid: Grid, owner: np.ndarray, pieces: Sequence[np.ndarray], margin: float,
              table_clutch: bool) -> tuple[dict, dict]:
    """(patches: (upper piece, lower piece or -1) -> the corner points of its squares,
    studs: (upper piece, lower piece, _GROUND or _TABLE) -> the centres of its squares that clutch)."""
    xy = grid.centres[:, :2] / grid.unit
    d = 0.5 - margin
    patches: dict[tuple[int, int], list] = {}
    studs: dict[tuple[int, int], list] = {}
    for n, cells in enumerate(pieces):
        for c, m in zip(cells, _under(grid, owner, cells)):
            if m == -2 or m == n:
                continue
            patches.setdefault((n, int(m)), []).extend(
                (xy[c, 0] + dx, xy[c, 1] + dy) for dx in (-d, d) for dy in (-d, d))
            held = _TABLE if grid.on_table[c] else (int(m) if m >= 0 else _GROUND)
            if held != _TABLE or table_clutch:
                studs.setdefault((n, held), []).append((xy[c, 0], xy[c, 1]))
    return patches, studs


class _Program:
    """The linear program of one structure: corner forces, stud pulls, and each piece's three
    balance equations with slack, the slack minimised (module docstring)."""

    def __init__(self, grid: Grid, pieces: Sequence[np.ndarray], owner: np.ndarray, margin: float,
                 clutch: float | None, table_clutch: bool,
                 loads: Sequence[tuple[float, float, float] | None] | None = None):
        from ortools.linear_solver import pywraplp
        self.lp = pywraplp
        self.solver = solver = pywraplp.Solver.CreateSolver('GLOP')
        self.clutch, self.inf = clutch, solver.infinity()
        self.scale = max(1.0, float(sum(len(p) for p in pieces)))
        xy = grid.centres[:, :2] / grid.unit
        self.com = [xy[p].mean(axis=0) for p in pieces]
        self.rows = []
        for n, cells in enumerate(pieces):
            push, x, y = (loads[n] if loads is not None and loads[n] is not None else (0.0, *self.com[n]))
            # A push down at (x, y) off the centre of mass: the forces from below balance its moment too.
            turn_x, turn_y = push * (y - self.com[n][1]), push * (x - self.com[n][0])
            down = float(len(cells)) + push
            self.rows.append([solver.Constraint(down, down), solver.Constraint(turn_x, turn_x),
                              solver.Constraint(turn_y, turn_y)])
        patches, studs = _contacts(grid, owner, pieces, margin, table_clutch)
        for (n, m), corners in patches.items():
            # Forces anywhere on a contact patch are forces at the corners of its convex hull.
            for x, y in convex_hull(np.asarray(corners)):
                self._force(n, m, x, y, 1.0, self.inf)
        self.studs: dict[tuple[int, int], list] = {}
        if clutch is not None:
            for (n, m), centres in studs.items():
                self.studs[n, m] = [self._force(n, m, x, y, -1.0, float(clutch)) for x, y in centres]
        self.held = {n for n, _ in patches} | {k for key in self.studs for k in key if k >= 0}
        self.slack = []
        for n, equations in enumerate(self.rows):
            for ct in equations:
                up, down = solver.NumVar(0.0, self.inf, ''), solver.NumVar(0.0, self.inf, '')
                ct.SetCoefficient(up, 1.0)
                ct.SetCoefficient(down, -1.0)
                self.slack.append((n, up, down))
        self.objective = solver.Objective()
        for _, up, down in self.slack:
            self.objective.SetCoefficient(up, 1.0)
            self.objective.SetCoefficient(down, 1.0)
        self.objective.SetMinimization()

    def _force(self, n: int, m: int, x: float, y: float, sign: float, most: float):
        """A force 0..most at (x, y): up on piece n and down on m for sign 1 (a push), the other
        way for -1 (a stud's pull); the table and ground (m < 0) take whatever they are given."""
        f = self.solver.NumVar(0.0, most, '')
        for k, s in ((n, sign), (m, -sign)):
            if k < 0:
                continue
            self.rows[k][0].SetCoefficient(f, s)
            self.rows[k][1].SetCoefficient(f, s * (y - self.com[k][1]))
            self.rows[k][2].SetCoefficient(f, s * (x - self.com[k][0]))
        return f

    def solve(self) -> tuple[bool, tuple[int, ...]] | None:
        """(whether it stands, the pieces whose balance needs slack), None where GLOP has no optimum."""
        if self.solver.Solve() != self.lp.Solver.OPTIMAL:
            return None
        if self.objective.Value() <= _TOL * self.scale:
            return True, ()
        tol = _TOL * self.scale
        return False, tuple(sorted({n for n, up, down in self.slack
                                    if up.solution_value() + down.solution_value() > tol}))

    def why(self, falling: tuple[int, ...]) -> tuple[str, ...]:
        """Why each falling piece falls (module docstring): solves again, the pull unlimited."""
        if self.clutch is None:
            return tuple(TIPS if n in self.held else FLOATS for n in falling)
        for pulls in self.studs.values():
            for t in pulls:
                t.SetUb(self.inf)
        solved = self.solve()
        tipping = set(solved[1]) if solved is not None else set(falling)
        said = {n: TIPS if n in self.held else FLOATS for n in falling if n in tipping}
        if len(said) < len(falling):
            said.update(self._pulled_off([n for n in falling if n not in tipping]))
        return tuple(said.get(n, TIPS) for n in falling)

    def _pulled_off(self, pieces: list[int]) -> dict[int, str]:
        """For pieces that stand with unlimited clutch: the connection, theirs where one is, that must
        hold the most beyond its studs' clutch, with the total pull beyond the limits minimised (the
        slack held at what unlimited clutch leaves)."""
        solver, tol = self.solver, _TOL * self.scale
        total = solver.Constraint(0.0, self.objective.Value() + tol)
        for _, up, down in self.slack:
            total.SetCoefficient(up, 1.0)
            total.SetCoefficient(down, 1.0)
        self.objective.Clear()
        beyond = {}
        for key, pulls in self.studs.items():
            beyond[key] = []
            for t in pulls:
                u = solver.NumVar(0.0, self.inf, '')
                limit = solver.Constraint(-self.inf, float(self.clutch))
                limit.SetCoefficient(t, 1.0)
                limit.SetCoefficient(u, -1.0)
                self.objective.SetCoefficient(u, 1.0)
                self.objective.SetCoefficient(t, _PULL_COST)
                beyond[key].append(u)
        self.objective.SetMinimization()
        if solver.Solve() != self.lp.Solver.OPTIMAL:
            return {}
        over = {key: sum(u.solution_value() for u in us) for key, us in beyond.items()}
        over = {key: v for key, v in over.items() if v > tol}
        if not over:
            return {}
        worst = max(over, key=over.get)
        out = {}
        for n in pieces:
            mine = [key for key in over if n in key]
            key = max(mine, key=over.get) if mine else worst
            out[n] = self._says(n, key)
        return out

    def _says(self, n: int, key: tuple[int, int]) -> str:
        """What the connection `key` (upper piece, lower piece or ground or table) asks, told to piece n."""
        pulls = self.studs[key]
        need = sum(t.solution_value() for t in pulls)
        k = len(pulls)
        studs = f'{k} stud' + ('s' if k > 1 else '')
        if n in key:
            other = key[1] if key[0] == n else key[0]
            head = 'pulls off its studs: its connection to'
        else:
            other, head = key[1], f'falls with piece {key[0]}, which pulls off its studs: its connection to'
        name = {_GROUND: 'the ground', _TABLE: 'the table'}.get(other, f'piece {other}')
        return (f"{head} {name} must hold {need:.2f} times a cell's weight over {studs}, "
                f'the clutch gives {k * self.clutch:.2f}')


def first_failure(grid: Grid, pieces: Sequence[Sequence[int]], ground=None, clutch: float | None = None,
                  margin: float = MARGIN, table_clutch: bool | None = None) -> tuple[int, Statics] | None:
    """The first step of building the pieces in the order given after which the structure does not
    stand: (the index of the piece just placed, the verdict on the structure then, which names the
    pieces that fall and why); None when it stands after every step. Only steps whose load reaches
    an overhang are solved (`order_statics`)."""
    walk = _Walk(grid, ground, margin, clutch, table_clutch, explain=True, press=False)
    for n, cells in enumerate(pieces):
        if not walk.add(np.asarray(cells, dtype=int).ravel())[0]:
            return n, walk.verdict
    return None


def _table_clutch(grid: Grid, table_clutch: bool | None) -> bool:
    """Whether the table's studs hold: as asked, else as the grid's scene says (``studs.baseplate``)."""
    return bool(getattr(grid, 'table_clutch', False)) if table_clutch is None else bool(table_clutch)


def press_load(grid: Grid, owner: np.ndarray, cells, clutch: float) -> tuple[float, float, float] | None:
    """The press that seats a studded piece on the pieces under it (`structure_statics`' loads): the
    clutch per stud it goes onto (seating a stud takes the pull it then holds), pushed down over those
    studs, where the hand presses (GAMP takes the grasp nearest them first). owner: per grid cell, a
    piece (>= 0), the ground (-1) or nothing (-2). None where it goes onto no stud (the table)."""
    cells = np.asarray(cells, dtype=int).ravel()
    below = grid.below_idx[cells]
    on = (below >= 0) & ~np.isin(below, cells) & (owner[np.maximum(below, 0)] >= -1) & ~grid.on_table[cells]
    if not on.any():
        return None
    x, y = (grid.centres[cells[on], :2] / grid.unit).mean(axis=0)
    return float(on.sum()) * float(clutch), float(x), float(y)


def order_statics(grid: Grid, pieces: Sequence[Sequence[int]], ground=None, margin: float = MARGIN,
                  clutch: float | None = None, table_clutch: bool | None = None,
                  press: bool = True) -> tuple[list[int], list[int]]:
    """(the order the pieces are placed in, the pieces that wait to the end), indices into `pieces`,
    of a walk that keeps the structure standing (clutch, table_clutch: `structure_statics`); with
    clutch, also under the press that seats each piece (`press_load`; `press` False: not).

    The pieces go on `ground` (cells built before, as fixed as the table) in the order given; one
    that would leave a structure that does not stand waits, and is tried again once a piece placed
    after it could hold it down: one on a piece its own load reaches, or under it. The walk does
    not ask whether a piece that waited can still be reached (GAMP does, step by step).

    A piece every unit of which rests on something, on pieces that each rest so all the way down,
    leaves a standing structure standing (its weight goes straight down, column by column), so
    the program is solved only for pieces whose load reaches an overhang."""
    walk_ = _Walk(grid, ground, margin, clutch, table_clutch, press=press)
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
    """A standing structure that pieces are added to, one at a time, each only if it still stands.
    `verdict`: the last verdict asked for (Statics(True) until one is)."""

    def __init__(self, grid: Grid, ground, margin: float, clutch: float | None = None,
                 table_clutch: bool | None = None, explain: bool = False, press: bool = True):
        self.grid, self.ground, self.margin = grid, ground, margin
        self.clutch, self.table_clutch, self.explain = clutch, _table_clutch(grid, table_clutch), explain
        self.press = press and clutch is not None
        self.owner = _owner(grid, [], ground)
        self.placed: list[np.ndarray] = []
        self.verdict = Statics(True)

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
        if heavy:
            self.verdict = structure_statics(self.grid, self.placed + [cells], self.ground, self.margin,
                                             self.clutch, self.table_clutch, self.explain)
            if not self.verdict:
                return False, heavy
            load = press_load(self.grid, self.owner, cells, self.clutch) if self.press else None
            if load is not None:
                self.verdict = structure_statics(self.grid, self.placed + [cells], self.ground, self.margin,
                                                 self.clutch, self.table_clutch, self.explain,
                                                 [None] * len(self.placed) + [load])
                if not self.verdict:
                    return False, heavy
        self.placed.append(cells)
        self.owner[cells] = n
        return True, heavy

"""Which blocks to lay out for a target, and where on the table: a scene rad can build.

A target from a file (`rad_core.domain.voxels`) comes without blocks. `choose_blocks` picks how
many of each type to lay out with CP-SAT over the very placements the allocation uses
(`allocation.placements.enumerate_candidates`), with its stability rule (`support='stable'`:
every block rests on the table, a chosen block or a filled cell when placed), lexicographically:

1. the allocation's objective c^T g (target cells covered less non-target cells used):
   an exact cover when one stands, else as much as can be covered;
2. target cells covered (a block half on a non-target cell may hold up a target cell,
   as in the allocation);
3. the fewest blocks (`fewest`) or the lowest total cost (`cheapest`, per-type costs).

With `SupplyParams.hand` (the default) the cover must also be one a top-down hand can build:
`allocation.order` looks for an order in which each chosen piece, when its turn comes, has
a way of being held that no piece placed before it is in the way of, rests on something, and
comes before every piece over its cells (the carried block comes down through their columns:
four stepped pieces in a pinwheel, each over the next, have no order), and leaves what is built
standing as a whole (`domain.statics`: plates stacked each further out tip the lowest once the top
one is on, though each rests on the one below). The pieces it cannot place
are ruled out and the model solved again, for at most `hand_rounds` rounds within the time limit;
the cover whose order places the most target cells is kept (ties: the earlier round, the better
by the levels above). Without this, a solid 2 x 2 tower becomes six 2 x 2 slabs standing back to
back, and the hand can take none of the second slabs of a pair (a flush slab on one side, 10 cm
across the other). The order is a guess that ignores the arm's
other links and the pick (`hand_order`); GAMP still checks every step.

An inventory caps how many blocks of each type there are; without one the count of each
type is free. So the allocation the planner solves later, over exactly these blocks, finds
a cover as good (this one is a feasible answer to it). The chosen pieces are checked with
`shapes.stable_order` too, a check that does not depend on the solver, and the structure as a
whole after each piece (`domain.statics`).

`lay_out_blocks` then puts them on the table as the hand-made shapes' scenes do
(`shapes.lay_out`: every unit 0.32..0.63 m from the base within 75 degrees of +x, 5 cm
between blocks for the open gripper's fingers, 7 cm clear of the target regions); where they do not
fit (`SupplyParams.start` 'auto'), or always ('feeder'), a feeder presents them at a station instead
(`feeder_blocks`). The scene keeps the cover as its design (`Scene.design`, `design_of`), which the
planner plans beside its own allocations: the allocation over exactly these blocks finds a cover as
good, but not always one the hand can build in some order, as this one is where the order model chose it.

A large target's model can outlast the time limit in presolve: `course_cover`, a cover laid course by
course from the bottom, is CP-SAT's first solution (a hint) and the answer where CP-SAT finds none.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from ortools.sat.python import cp_model

from rad_core.allocation.arm import HandBlocked
from rad_core.allocation.constraints import rests_now
from rad_core.allocation.cpsat import build_model, hand_unplaced, solve_rounds
from rad_core.allocation.order import candidate_poses, hand_order, solve_order
from rad_core.cell.panda import check_effector
from rad_core.gamp.planner import GampConfig
from rad_core.allocation.placements import Placement, enumerate_candidates
from rad_core.domain import shapes
from rad_core.domain.blocks import BlockType
from rad_core.domain.errors import RadError
from rad_core.domain.grid import Grid
from rad_core.domain.scene import MAX_BLOCKS, Block, Feeder, Scene, TargetRegion, feeder_of
from rad_core.domain.statics import order_statics
from rad_core.domain.voxels import MAX_UNIT

OBJECTIVES = ('fewest', 'cheapest')
SUPPLY_STARTS = ('auto', 'table', 'feeder')
# Costs are compared in thousandths, so CP-SAT's objective stays integral.
COST_SCALE = 1000
ORDERED_MAX_CELLS = 200
"""Targets of more cells skip the order model's cover (`_ordered_supply`): its model, every candidate
pose at every step, takes minutes to build beyond that, whatever the time limit. They are the large
targets, whose CP-SAT search starts from the course-by-course cover."""


def library(scene: Scene | None = None) -> dict[str, BlockType]:
    """Every block type a supply may name: the default set, the hand-made shapes' custom
    types, and the scene's own (which win on a name clash)."""
    return {**shapes.LIBRARY, **(dict(scene.block_types) if scene is not None else {})}


@dataclass(frozen=True)
class SupplyParams:
    """What to optimise and how long to search.

    objective: 'fewest' blocks, or 'cheapest' by `costs` (type -> cost; types left out cost 1).
    time_limit_s: CP-SAT's limit; on expiry the best supply found is used and reported FEASIBLE.
    seed: CP-SAT's seed and the layout's (yaws, places); one worker, so one answer per seed.
    """

    objective: str = 'fewest'
    costs: Mapping[str, float] = field(default_factory=dict)
    time_limit_s: float = 10.0
    seed: int = 0
    hand: bool = True
    """Keep to covers a top-down hand can place in some order (module docstring)."""
    hand_rounds: int = 8
    """At most this many solves, each ruling out the pieces the hand could not place."""
    effector: str = 'hand'
    """Whose placing `hand` asks about (`cell.panda.EFFECTORS`): the parallel hand or the vacuum gripper."""
    drop: bool | None = None
    """Whether the hand may let a block go over its place (`GampConfig.drop`); None: as GAMP by default."""
    start: str = 'auto'
    """Where the blocks start (`SUPPLY_STARTS`): on the 'table', in a 'feeder' presenting them at
    `station`, or 'auto': the table where they fit within reach, else the feeder (as `rad scene
    generate --supply auto`)."""
    station: tuple[float, float] = (0.42, -0.3)
    """The feeder's station (x, y), m: right of the target, within reach (the generator's)."""

    @property
    def gamp(self):
        """GAMP's settings the supply counts on (`GampConfig` with this effector and drop)."""
        if self.drop is None:
            return GampConfig(effector=self.effector)
        return GampConfig(effector=self.effector, drop=self.drop)

    def validate(self, types: Mapping[str, BlockType]) -> None:
        if self.objective not in OBJECTIVES:
            raise RadError(f'objective must be one of {", ".join(OBJECTIVES)}, got {self.objective!r}')
        if self.objective == 'fewest' and self.costs:
            raise RadError('costs apply to --objective cheapest; fewest counts blocks')
        if self.objective == 'cheapest' and not self.costs:
            raise RadError('--objective cheapest needs per-type costs (--cost I2=1,L3=1.5, or in the inventory)')
        for name, cost in self.costs.items():
            if name not in types:
                raise RadError(f'cost given for {name!r}, which is not among the types offered ({", ".join(types)})')
            if not (isinstance(cost, (int, float)) and math.isfinite(cost) and 0 <= cost <= 1e6):
                raise RadError(f'cost of {name} must be a number in 0..1e6, got {cost!r}')
        if not (isinstance(self.time_limit_s, (int, float)) and self.time_limit_s > 0):
            raise RadError(f'time limit must be a positive number of seconds, got {self.time_limit_s!r}')
        if not (isinstance(self.seed, int) and 0 <= self.seed < 2 ** 31):
            raise RadError(f'seed must be an integer in 0..2^31-1, got {self.seed!r}')
        check_effector(self.effector)
        if not (isinstance(self.hand_rounds, int) and self.hand_rounds >= 1):
            raise RadError(f'hand_rounds must be a positive integer, got {self.hand_rounds!r}')
        if self.start not in SUPPLY_STARTS:
            raise RadError(f'supply must be one of {", ".join(SUPPLY_STARTS)}, got {self.start!r}')


@dataclass(frozen=True)
class SupplyReport:
    """How well the chosen blocks cover the target, and what they are."""

    status: str
    target_cells: int
    covered: int
    filler_cells: int
    counts: Mapping[str, int]
    cost: float | None
    stands: bool
    solve_time_s: float
    hand_covered: int | None = None
    """Target cells of the cover a top-down hand can place in some order (`SupplyParams.hand`);
    None where it was not asked."""
    rounds: int = 1
    hand_left: tuple = ()
    """The pieces of the cover no order lets a top-down hand place, each {'type', 'target', 'cells'
    (the region's cells it fills), 'why'}: which cells, and what stands in the way."""
    ordered: bool = False
    """The cover is the order model's (`choose_blocks`: no cover the rounds found could be placed whole,
    and this one places more): it leaves out the cells no order lets the hand fill."""

    @property
    def exact(self) -> bool:
        """Every target cell covered and no other cell used."""
        return self.covered == self.target_cells and self.filler_cells == 0

    @property
    def coverage(self) -> float:
        return self.covered / self.target_cells if self.target_cells else 1.0

    def to_dict(self) -> dict:
        return {'status': self.status, 'target_cells': self.target_cells, 'covered': self.covered,
                'filler_cells': self.filler_cells, 'coverage': round(self.coverage, 4), 'exact': self.exact,
                'blocks': sum(self.counts.values()), 'counts': dict(self.counts), 'cost': self.cost,
                'stands': self.stands, 'hand_covered': self.hand_covered, 'rounds': self.rounds,
                'solve_time_s': round(self.solve_time_s, 3), 'hand_left': [dict(d) for d in self.hand_left],
                'ordered': self.ordered}

    def summary(self) -> str:
        counts = ', '.join(f'{n} {k}' for k, n in sorted(self.counts.items()) if n)
        text = f'{sum(self.counts.values())} blocks ({counts}) cover '
        text += f'all {self.target_cells} target cells exactly' if self.exact else \
            f'{self.covered} of {self.target_cells} target cells ({self.coverage:.2f})'
        if self.filler_cells:
            text += f', filling {self.filler_cells} cells off the target to hold blocks up'
        if self.cost is not None:
            text += f', cost {self.cost:g}'
        if not self.stands:
            text += ('; no order found in which every block rests when placed and what is built stands as a '
                     'whole')
        if self.ordered:
            text += ('; no cover of more cells could be placed whole by a top-down hand: these are the cells it '
                     'can place in some order')
        if self.hand_covered is not None and self.hand_covered < self.covered:
            text += (f'; a top-down hand can place {self.hand_covered} of the {self.covered} covered cells '
                     f'in some order')
            for d in self.hand_left[:3]:
                text += f"; {d['type']} on {d['target']} cells {_cells_text(d['cells'])}: {d['why']}"
            if len(self.hand_left) > 3:
                text += f'; {len(self.hand_left) - 3} more such pieces'
        return f'{text} [{self.status}]'


# ---- inventories ----------------------------------------------------------------

def read_inventory(path: str, types: Mapping[str, BlockType]) -> tuple[dict[str, int], dict[str, float]]:
    """An inventory file: a JSON object, type -> count or {"count": N, "cost": C}. Returns (counts, costs)."""
    try:
        doc = json.loads(Path(path).read_text())
    except OSError as e:
        raise RadError(f'cannot read inventory {path!r}: {e.strerror}') from None
    except (ValueError, UnicodeDecodeError) as e:
        raise RadError(f'inventory {path!r} is not JSON: {e}') from None
    return parse_inventory(doc, types, where=f'inventory {path}')


def parse_inventory(doc, types: Mapping[str, BlockType], where: str = 'inventory') -> tuple[dict[str, int],
                                                                                             dict[str, float]]:
    if not isinstance(doc, dict) or not doc:
        raise RadError(f'{where}: expected a JSON object of block type -> count, e.g. {{"I2": 4, "L3": 2}}')
    counts, costs = {}, {}
    for name, entry in doc.items():
        if name not in types:
            raise RadError(f'{where}: unknown block type {name!r} (known: {", ".join(sorted(types))})')
        if isinstance(entry, dict):
            unknown = sorted(set(entry) - {'count', 'cost'})
            if unknown or 'count' not in entry:
                raise RadError(f'{where}.{name}: expected {{"count": N}} with an optional "cost", got keys '
                               f'{sorted(entry)}')
            if 'cost' in entry:
                costs[name] = entry['cost']
            entry = entry['count']
        if not (isinstance(entry, int) and not isinstance(entry, bool) and 0 <= entry <= MAX_BLOCKS):
            raise RadError(f'{where}.{name}: count must be a whole number in 0..{MAX_BLOCKS}, got {entry!r}')
        counts[name] = entry
    return counts, costs


def parse_costs(text: str) -> dict[str, float]:
    """'I2=1,L3=1.5' -> {'I2': 1.0, 'L3': 1.5}."""
    out = {}
    for item in filter(None, (s.strip() for s in text.split(','))):
        name, sep, value = item.partition('=')
        try:
            out[name.strip()] = float(value)
        except ValueError:
            sep = ''
        if not sep or not name.strip():
            raise RadError(f'--cost takes TYPE=COST pairs separated by commas, e.g. I2=1,L3=1.5; got {item!r}')
    return out


def pick_types(names: str, types: Mapping[str, BlockType]) -> dict[str, BlockType]:
    """'I2,L3' -> those types of the library, in order."""
    wanted = [n.strip() for n in names.split(',') if n.strip()]
    if not wanted:
        raise RadError('--types names no block type, e.g. --types I2,L3,cube')
    unknown = [n for n in wanted if n not in types]
    if unknown:
        raise RadError(f'unknown block type {unknown[0]!r} (known: {", ".join(sorted(types))})')
    return {n: types[n] for n in dict.fromkeys(wanted)}


# ---- choosing blocks --------------------------------------------------------------

def choose_blocks(targets: Sequence[TargetRegion], unit: float, types: Mapping[str, BlockType],
                  inventory: Mapping[str, int] | None = None,
                  params: SupplyParams = SupplyParams(), clearance: float = 0.0) -> tuple[list, SupplyReport]:
    """The placements (allocation.Placement) of the blocks to lay out, and how well they cover.

    clearance: the scene's (`rad_core.domain.scene`), which gives the hand's fingers room between blocks."""


    params.validate(types)
    start = time.perf_counter()
    if not types:
        raise RadError('no block types offered')
    scene = Scene(unit, dict(types), (), tuple(targets), clearance)
    grid = Grid(scene)
    candidates = [c for c in enumerate_candidates(scene, grid, positive_only=False) if c.value >= 0]
    n_target = int(grid.is_target.sum())
    counts = {n: n_target for n in types} if inventory is None else {n: int(inventory.get(n, 0)) for n in types}
    occupied = np.zeros(grid.num_cells, dtype=bool)
    model, w, _ = build_model(candidates, counts, 'stable', grid, occupied)
    # The first cover, in well under a second at any size: where CP-SAT finds no answer in time (presolve
    # of a large model can take it all), it is the answer; on a large target CP-SAT also starts from it
    # (a hint; on a small one a hint would only steer which of equal covers CP-SAT returns).
    first = course_cover(grid, candidates, counts) if n_target > ORDERED_MAX_CELLS else None
    for n in set(first or ()):
        model.add_hint(w[n], True)
    # Lexicographic objective (module docstring): each level outweighs everything below it.
    unit_cost = [_cost(c.placement.type, params) for c in candidates]
    covered = [int(grid.is_target[list(c.cell_ids)].sum()) for c in candidates]
    cost_span = max(unit_cost, default=0) * grid.num_cells + 1
    cover_span = cost_span * (n_target + 1)
    model.maximize(cover_span * sum(c.value * w[n] for n, c in enumerate(candidates))
                   + cost_span * sum(k * w[n] for n, k in enumerate(covered) if k)
                   - sum(k * w[n] for n, k in enumerate(unit_cost) if k))
    best, rounds = None, 0
    for solver, status, chosen, unplaced in solve_rounds(model, w, candidates, scene,
                                                         params.hand_rounds if params.hand else 1,
                                                         params.time_limit_s, start, params.seed, gamp=params.gamp,
                                                         way_down=True):
        rounds += 1
        if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
            if best is None and first is None:
                first = course_cover(grid, candidates, counts)
            if best is None and first:
                # No answer in time: the course-by-course cover, judged by the same measure.
                unplaced = _hand_unplaced(scene, candidates, first, params) if params.hand else []
                hand_covered = _placeable_cells(grid, candidates, first, unplaced) if params.hand else None
                best = ((hand_covered or 0, -rounds), first, 'FEASIBLE (course by course)', hand_covered)
            if best is not None:
                break               # the rounds before found covers: keep the best of them
            raise RadError(f'the supply model found no answer in {params.time_limit_s:g} s '
                           f'({solver.status_name(status)}) and no block rests on the table in the target: '
                           f'give it a longer --time-limit or other block types')
        hand_covered = _placeable_cells(grid, candidates, chosen, unplaced) if params.hand and chosen else None
        score = (hand_covered if hand_covered is not None else 0, -rounds)
        if best is None or score > best[0]:
            best = (score, chosen, solver.status_name(status), hand_covered)
    _, chosen, status_name, hand_covered = best
    by_order = False
    if (params.hand and hand_covered is not None and hand_covered < _target_cells(grid, candidates, chosen)
            and n_target <= ORDERED_MAX_CELLS):
        left = params.time_limit_s - (time.perf_counter() - start)
        ordered = _ordered_supply(scene, grid, candidates, n_target, max(1.0, left / 3), params.gamp)
        if ordered is not None and ordered[1] > hand_covered:
            (chosen, hand_covered), by_order = ordered, True
            status_name = 'FEASIBLE'
    picked = [candidates[n] for n in chosen]
    placements = [c.placement for c in picked]
    cells = sorted({i for c in picked for i in c.cell_ids})
    n_covered = int(grid.is_target[cells].sum()) if cells else 0
    kinds = {n: 0 for n in types}
    for p in placements:
        kinds[p.type] += 1
    cost = None
    if params.objective == 'cheapest':
        cost = round(sum(_cost(p.type, params) for p in placements) / COST_SCALE, 6)
    left = hand_left(scene, grid, placements, params.gamp) if hand_covered is not None and hand_covered < n_covered \
        else ()
    report = SupplyReport(status_name, n_target, n_covered, len(cells) - n_covered,
                          {k: v for k, v in kinds.items() if v}, cost, stands(grid, placements, targets),
                          time.perf_counter() - start, hand_covered, rounds, left, by_order)
    return placements, report


def course_cover(grid: Grid, candidates, counts: Mapping[str, int]) -> list[int]:
    """A cover built course by course, as a mason would (indices into candidates): from the lowest
    course up, each pose whose cells are all target cells not yet covered and that rests on the table
    or on what is chosen below it (the 'stable' rule, `constraints.rests_now`), larger blocks first;
    then, where target cells are left, poses that use cells off the target to hold them up. Feasible
    for the supply model by construction (disjoint, within `counts`, each resting when placed in
    this order)."""
    occupied = np.zeros(grid.num_cells, dtype=bool)
    left = dict(counts)
    chosen: list[int] = []
    lowest = [int(grid.ijk[list(c.cell_ids), 2].min()) for c in candidates]
    on_target = [bool(grid.is_target[list(c.cell_ids)].all()) for c in candidates]
    for exact in (True, False):
        order = sorted((n for n, c in enumerate(candidates) if on_target[n] == exact and c.value > 0),
                       key=lambda n: (lowest[n], -candidates[n].value, -len(candidates[n].cell_ids), n))
        for n in order:
            cand = candidates[n]
            ids = list(cand.cell_ids)
            if left.get(cand.placement.type, 0) <= 0 or occupied[ids].any() or not rests_now(grid, ids, occupied):
                continue
            chosen.append(n)
            occupied[ids] = True
            left[cand.placement.type] -= 1
    return chosen


def _hand_unplaced(scene: Scene, candidates, chosen: list[int], params: SupplyParams) -> list[int]:
    return hand_unplaced(scene, [candidates[n].placement for n in chosen], params.gamp, way_down=True)


def hand_left(scene: Scene, grid: Grid, placements, gamp=None) -> tuple[dict, ...]:
    """The placements no order of `allocation.order.hand_order` places (supply's `SupplyReport.hand_left`),
    each with the cells it fills and why: its type has no top-down grasp, or every way of holding it
    (a grasp at a hand yaw) needs free a cell that another piece of the cover fills."""
    regions = [t.name for t in scene.targets]
    keys = [tuple(sorted(grid.index(regions.index(p.target), c) for c in p.cells)) for p in placements]
    left = set(hand_order(scene, placements, gamp=gamp, way_down=True).left_out(keys))
    hand = HandBlocked(scene, grid, gamp)
    owner = {}
    for p in placements:
        for c in p.cells:
            owner[grid.index(regions.index(p.target), c)] = p
    out = []
    for k, p in enumerate(placements):
        if k not in left:
            continue
        ids = [grid.index(regions.index(p.target), c) for c in p.cells]
        ways = [w for pair in hand.cells(p.type, p.yaw, ids) for w in pair]
        needed = sorted({int(c) for w in ways for c in w.tolist() if owner.get(int(c)) not in (None, p)})
        if not ways:
            why = 'its type has no top-down grasp at this unit'
        elif not needed:
            why = ('with it on, what is built would not stand (`domain.statics`: the load it adds tips what '
                   'holds it), in every order tried')
        else:
            why = (f'each of its {len(ways)} ways of being held (grasp and hand yaw) needs free a cell the cover '
                   f'fills ({_cells_text([tuple(int(v) for v in grid.ijk[c]) for c in needed[:6]])}'
                   f'{" ..." if len(needed) > 6 else ""}), and no order places it before all of them')
        out.append({'type': p.type, 'target': p.target, 'cells': [list(c) for c in p.cells], 'why': why})
    return tuple(out)


def _cells_text(cells) -> str:
    return ' '.join(f'({i},{j},{k})' for i, j, k in cells)


def _target_cells(grid, candidates, chosen: list[int]) -> int:
    return sum(int(grid.is_target[list(candidates[n].cell_ids)].sum()) for n in chosen)


def _ordered_supply(scene: Scene, grid, candidates, n_target: int, time_limit_s: float,
                    gamp=None) -> tuple[list[int], int] | None:
    """Where the rounds left cells the hand cannot place: the cover and its order at once
    (`allocation.order`'s model over every candidate pose, each type as many times as needed, the
    allocation's stability rule), so a dense target gets the cover whose order places most. (indices
    into candidates, target cells placed), or None where CP-SAT found none in `time_limit_s` of
    deterministic time (at most three times that of wall time)."""
    occupied = np.zeros(grid.num_cells, dtype=bool)
    counts = {name: n_target for name in scene.block_types}
    poses, items = candidate_poses(grid, HandBlocked(scene, grid, gamp), occupied, candidates, counts)
    found = solve_order(grid, occupied, poses, items, counts, time_limit_s, cover=True, way_down=True)
    if not found.order:
        return None
    index = {id(c.placement): n for n, c in enumerate(candidates)}
    chosen = [index[id(p)] for p in found.placements]
    return chosen, _target_cells(grid, candidates, chosen)


def _placeable_cells(grid, candidates, chosen: list[int], unplaced: list[int]) -> int:
    """Target cells of the chosen candidates but those the hand cannot place (indices into chosen)."""
    left_out = set(unplaced)
    return sum(int(grid.is_target[list(candidates[n].cell_ids)].sum()) for k, n in enumerate(chosen)
               if k not in left_out)


def _cost(type_name: str, params: SupplyParams) -> int:
    if params.objective == 'fewest':
        return 1
    return int(round(float(params.costs.get(type_name, 1.0)) * COST_SCALE))


def stands(grid: Grid, placements, targets: Sequence[TargetRegion]) -> bool:
    """Whether the pieces of every region can be placed in some order, each resting when placed
    (`shapes.stable_order`: its centre of mass over what holds it, with a margin), the structure
    standing as a whole after each (`domain.statics`: the load of the pieces on it included)."""
    names = [t.name for t in targets]
    for t in targets:
        mine = [p for p in placements if p.target == t.name]
        order = shapes.stable_order([p.cells for p in mine]) if mine else []
        if order is None:
            return False
        ids = [[grid.index(names.index(t.name), c) for c in mine[n].cells] for n in order]
        if order_statics(grid, ids, clutch=grid.clutch)[1]:
            return False
    return True


# ---- the table ------------------------------------------------------------------

def lay_out_blocks(kinds: Sequence[str], types: Mapping[str, BlockType], targets: Sequence[TargetRegion],
                   unit: float, seed: int = 0, config: shapes.LayoutConfig = shapes.LayoutConfig(),
                   course: float | None = None) -> list[Block]:
    """The blocks on the table within reach, apart and clear of the targets (`shapes.lay_out`),
    largest first (they are the hardest to fit); tighter on each retry, as `shapes.build_scene`."""
    order = sorted(kinds, key=lambda k: (-types[k].size, k))
    rng = np.random.default_rng(seed)
    for attempt in range(shapes.LAYOUT_ATTEMPTS):
        last = attempt == shapes.LAYOUT_ATTEMPTS - 1
        try:
            return shapes.lay_out(order, types, targets, rng, unit,
                                  replace(config, jitter=0.0 if last else config.jitter / 2 ** attempt), course)
        except RadError:
            if last:
                break
    units = sum(types[k].size for k in kinds)
    raise RadError(f'the {len(kinds)} blocks ({units} cubes) do not fit on the table within the arm\'s reach '
                   f'({config.reach[0]}..{config.reach[1]} m from the base, {config.gap} m apart, clear of the '
                   f'target): use a smaller target (--size) or larger block types')


def feeder_blocks(kinds: Sequence[str], types: Mapping[str, BlockType], targets: Sequence[TargetRegion],
                  unit: float, station: tuple[float, float], course: float | None = None) -> tuple[list[Block], Feeder]:
    """Every block in a feeder presenting them at `station` (the plan asks for any), as the generator's
    and the large shapes' scenes have them; RadError where the station's footprint, 5 cm round the
    largest block, would overlap a target region."""
    reach = max(float(np.ptp(types[k].offsets, axis=0)[:2].max()) + 1 for k in set(kinds)) * unit / 2 + 0.05
    for t in targets:
        lo, hi = t.bounds(unit)
        if lo[0] - reach < station[0] < hi[0] + reach and lo[1] - reach < station[1] < hi[1] + reach:
            raise RadError(f'the feeder\'s station {tuple(station)} lies within {reach:.2f} m of target region '
                           f'{t.name!r}: the blocks do not fit on the table and the feeder has no room')
    return feeder_of(kinds, types, station, unit, course=course)


def supply(targets: Sequence[TargetRegion], unit: float, types: Mapping[str, BlockType],
           inventory: Mapping[str, int] | None = None, params: SupplyParams = SupplyParams(),
           clearance: float = 0.0) -> tuple[Scene, SupplyReport]:
    """A complete scene for the targets: the chosen blocks laid out on the table; validated.

    RadError when no target cell can be covered by the types given (the report of a partial
    cover says how much can).
    """
    if not 0.01 <= unit <= MAX_UNIT:
        raise RadError(f'unit {unit} m is outside 0.01..{MAX_UNIT} m: the open hand takes cubes up to '
                       f'{MAX_UNIT} m wide')
    placements, report = choose_blocks(targets, unit, types, inventory, params, clearance)
    if report.covered == 0:
        offered = ', '.join(f'{k} x{inventory[k]}' for k in types if inventory and inventory.get(k)) \
            if inventory is not None else ', '.join(types)
        raise RadError(f'no target cell can be covered with the blocks offered ({offered or "none"}): offer more '
                       f'or other types, e.g. --types cube,I2,L3')
    kinds = [p.type for p in placements]
    blocks, feeder = None, None
    if params.start != 'feeder':
        try:
            blocks = lay_out_blocks(kinds, types, targets, unit, params.seed)
        except RadError:
            if params.start == 'table':
                raise
    if blocks is None:
        blocks, feeder = feeder_blocks(kinds, types, targets, unit, params.station)
    used = [n for n in types if n in set(kinds)]
    scene = Scene(unit, {n: types[n] for n in used}, tuple(blocks), tuple(targets), clearance, feeder=feeder,
                  design=design_of(placements, report.ordered))
    return Scene.from_dict(scene.to_dict()), report


def design_of(placements, ordered: bool) -> tuple[Placement, ...]:
    """The cover as the scene's design (`Scene.design`): in the order model's order where it chose the
    cover (`ordered`), else course by course from the bottom."""
    if not ordered:
        placements = sorted(placements, key=lambda p: min(c[2] for c in p.cells))
    return tuple(placements)


def target_only(targets: Sequence[TargetRegion], unit: float, types: Mapping[str, BlockType],
                clearance: float = 0.0) -> Scene:
    """A scene of the targets and the block types offered, with no block yet (for `rad scene supply`)."""
    return Scene.from_dict(Scene(unit, dict(types), (), tuple(targets), clearance).to_dict())

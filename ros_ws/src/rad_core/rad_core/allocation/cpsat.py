"""The allocation MILP of the paper's Sec. IV-A, solved with OR-Tools CP-SAT.

    maximize    c^T g,   g = sum_{i,k} w_{i,k} p_{i,k}
    subject to  g[j] <= 1                for every grid cell j
                sum_k w_{i,k} <= N_i     for every block type i
                w_{i,k} in {0, 1}

Since cells hold at most one unit, each pose is used at most once, so the
integer w of the paper is binary here without loss.

`support='stable'` (rad's option, not the paper's) adds what the paper leaves
to the sequencer, a static condition on every allocated block: it must stand
on what is under it when it is placed. For each pose p, the minimal sets S of
its bottom units whose convex footprint holds p's centre of mass
(`support.sufficient_supports`); p is admitted only if for one such S every
unit rests on the table, a placed block or a cell another chosen pose fills:

    z_{p,S} <= sum_{q fills the cell below u} w_q    for u in S
    w_p     <= sum_S z_{p,S}

(linear). Support only comes from the cell directly below, which with the
default blocks (at most two cubes tall, each in one plane) rules out two poses
holding each other up; scene-defined 3D types could interlock so, and physics
then has the last word. With it, poses
worth 0 (as many non-target as target cells) are admitted too, and among
allocations of equal c^T g the one covering more target cells wins (a
lexicographic second objective): a filler under an overhang costs nothing in
c^T g and makes the target cell above it buildable. The reported objective and
bound are c^T g's.

`prefer` (rad's, with 'stable' only) adds a third level: among allocations
equal in c^T g and coverage, 'fewer' takes the one with fewer poses (fewer
placements for the robot to get right, larger blocks), 'flat' the one whose
blocks span fewer levels (a top-down hand places a block beside lower or equal
neighbours, not beside taller ones: its palm passes 14 mm above the block's top).
Compared by `benchmarks/bench_reallocation.py` (its rows, under out/cache, name the preference).

`support='arm'` (rad's, stable as above) first rules out what the arm can never do,
whatever the order (`allocation.arm`): block types the open hand cannot take from above,
blocks on the table it cannot pick where they lie, poses whose every grasp is out of
reach; the result's `arm` says what and why.

`support='hand'` (rad's, arm as above) also asks for an order in which a top-down hand can
place the allocation (`allocation.order`: each pose, when its turn comes, has a way of
being held that no pose placed before it is in the way of): the poses it cannot place are ruled
out and the model solved again, at most `HAND_ROUNDS` times within the time limit, and the
allocation whose order places the most (c^T g of the poses it places) is kept (ties: the earlier
solve). Where GAMP drops blocks (`GampConfig.drop`), the rounds ask the hand that only sets blocks
down: counted on in the first allocation, the drops' many more orders led the sequencer to worse plans
where setting down placed everything (measured: generated g = 6 seeds 12 and 19, 0.93 and 0.90 where it
had 1.0); the cover stage asks for them where setting down leaves cells (`order.ordered_cover`). A pose the order cannot
place beside the others, GAMP refuses too in every order of that
allocation (`allocation.arm.HandBlocked` is sound for the hand, the fingers and panda_link7);
alone, or beside other poses, it may be fine, which is why it is ruled out only for this solve's
successors. What the order leaves out (the arm's other links, the carried block, the pick) GAMP
still checks.

`exclude` (no-goods) removes (block type, pose) pairs from the model: poses
the robot or physics already failed to build from the current state, when
sequencing stalled and the allocation is solved again over the cells still
free (`rad_core.sequencing.planning.reallocation`). Blocks already in target cells of
the scene are fixed: their cells are occupied and they are not available.
"""

from __future__ import annotations

import math
import time
from collections import defaultdict
from dataclasses import dataclass, replace

import numpy as np
from ortools.sat.python import cp_model

from rad_core.allocation.arm import arm_filter, finger_costs
from rad_core.cell.panda import check_effector
from rad_core.gamp.planner import GampConfig
from rad_core.allocation.constraints import cp_solver, support_options
from rad_core.allocation.order import hand_order
from rad_core.allocation.placements import Candidate, enumerate_candidates
from rad_core.allocation.result import AllocationResult
from rad_core.domain.errors import RadError
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Scene

SUPPORT_MODES = ('none', 'stable', 'arm', 'hand')
HAND_ROUNDS = 6
"""support='hand': at most this many solves."""
PREFER_MODES = ('none', 'fewer', 'flat', 'open')


@dataclass(frozen=True)
class AllocationParams:
    """Solver settings.

    time_limit_s: wall-clock limit; on expiry the best allocation found so far is
        returned with status FEASIBLE and the proven bound.
    seed: CP-SAT random seed; with num_workers=1 the result is deterministic.
    num_workers: CP-SAT search workers; more can be faster but not reproducible.
    """

    time_limit_s: float = 10.0
    seed: int = 0
    num_workers: int = 1
    support: str = 'none'
    """'none' (the paper's MILP), 'stable' (every allocated block can stand where it goes), 'arm'
    (stable, and nothing the arm can never do: `allocation.arm`) or 'hand' (arm, and an allocation
    a top-down hand can place in some order; module docstring)."""
    prefer: str = 'none'
    """Tie-break among equally good stable allocations: 'none', 'fewer' (fewer poses), 'flat'
    (blocks spanning fewer levels) or 'open' (poses a top-down hand can hold from free sides:
    `arm.finger_cost`)."""

    effector: str = 'hand'
    """What the arm carries (`cell.panda.EFFECTORS`): support 'arm' and 'hand' count on its grasps and
    the cells it needs free ('suction': the cup on a unit's top face, nothing beside the block)."""

    @property
    def gamp(self):
        """GAMP's settings the allocation counts on (`GampConfig` with this effector)."""
        return GampConfig(effector=self.effector)

    def validate(self) -> None:
        check_effector(self.effector)
        if self.support not in SUPPORT_MODES:
            raise RadError(f'support must be one of {", ".join(SUPPORT_MODES)}, got {self.support!r}')
        if self.prefer not in PREFER_MODES:
            raise RadError(f'prefer must be one of {", ".join(PREFER_MODES)}, got {self.prefer!r}')
        if self.prefer != 'none' and self.support == 'none':
            raise RadError(f"prefer={self.prefer!r} needs support='stable' or 'arm'")
        if not (isinstance(self.time_limit_s, (int, float)) and math.isfinite(self.time_limit_s)
                and self.time_limit_s > 0):
            raise RadError(f'time_limit_s must be a positive number of seconds, got {self.time_limit_s!r}')
        if not (isinstance(self.num_workers, int) and 1 <= self.num_workers <= 64):
            raise RadError(f'num_workers must be an integer in 1..64, got {self.num_workers!r}')
        if not isinstance(self.seed, int) or not (0 <= self.seed < 2**31):
            raise RadError(f'seed must be an integer in 0..2^31-1, got {self.seed!r}')


def available_counts(scene: Scene, grid: Grid) -> dict[str, int]:
    """N_i: blocks of each type still on the table (not yet on the grid)."""
    placed = blocks_on_grid(scene, grid)
    counts = {name: 0 for name in scene.block_types}
    for b, block in enumerate(scene.blocks):
        if b not in placed:
            counts[block.type] += 1
    return counts


def build_model(candidates: list[Candidate], counts: dict[str, int], support: str = 'none',
                grid: Grid | None = None, occupied=None, prefer: str = 'none', costs: list[int] | None = None):
    """CP-SAT model and its decision variables, one per candidate pose.

    support='stable' needs the grid and the cells already occupied (bool per cell).
    Returns (model, w, scale): the model's objective is scale * c^T g plus the
    lower levels (coverage, then the preference), each worth less than one unit
    of the level above (scale 1 without them)."""
    model = cp_model.CpModel()
    w = [model.new_bool_var(f'w{n}') for n in range(len(candidates))]
    by_cell, by_type = defaultdict(list), defaultdict(list)
    for n, cand in enumerate(candidates):
        by_type[cand.placement.type].append(w[n])
        for c in cand.cell_ids:
            by_cell[c].append(w[n])
    for vars_ in by_cell.values():
        if len(vars_) > 1:
            model.add_at_most_one(vars_)
    for name, vars_ in by_type.items():
        if counts.get(name, 0) < len(vars_):
            model.add(sum(vars_) <= counts.get(name, 0))
    primary = sum(cand.value * w[n] for n, cand in enumerate(candidates))
    if support == 'none':
        model.maximize(primary)
        return model, w, 1
    _add_support(model, candidates, w, by_cell, grid, occupied)
    covered = [int(grid.is_target[list(cand.cell_ids)].sum()) for cand in candidates]
    # The preference as a cost per pose, minimized below coverage: 'fewer' 1 per pose, 'flat'
    # the levels a pose spans above its lowest (a tall block next to a lower one blocks the palm).
    cost = costs if costs is not None else [_pose_cost(cand, grid, prefer) for cand in candidates]
    levels = sum(cost) + 1                       # the cost level spans 0..levels-1
    second = levels * sum(k * w[n] for n, k in enumerate(covered)) + (levels - 1) - sum(
        c * w[n] for n, c in enumerate(cost) if c)
    # The lower levels never outweigh one unit of c^T g (without a preference the scale is
    # the loose sum(covered) + 1 it always was, so allocations stay as they were).
    scale = levels * (int(grid.is_target.sum()) + 1) if prefer != 'none' else sum(covered) + 1
    model.maximize(scale * primary + second)
    return model, w, scale


def _pose_cost(cand: Candidate, grid: Grid, prefer: str) -> int:
    if prefer == 'fewer':
        return 1
    if prefer == 'flat':
        z = grid.ijk[list(cand.cell_ids)][:, 2]
        return int(z.max() - z.min())
    return 0


def _add_support(model, candidates, w, by_cell, grid: Grid, occupied) -> None:
    """The 'stable' constraints (see the module docstring)."""
    for n, cand in enumerate(candidates):
        sets = support_options(grid, list(cand.cell_ids), occupied, by_cell)
        if sets is None:
            continue                                   # stands whatever else is chosen
        options = []
        for unders in sets:
            z = model.new_bool_var(f'z{n}_{len(options)}')
            for u in unders:
                model.add(z <= sum(u))
            options.append(z)
        model.add(sum(options) >= w[n])


def greedy(candidates: list[Candidate], counts: dict[str, int]) -> list[int]:
    """A quick feasible allocation: best-value poses first, largest blocks on ties."""
    order = sorted(range(len(candidates)),
                   key=lambda n: (-candidates[n].value, -len(candidates[n].cell_ids), n))
    used, left, chosen = set(), dict(counts), []
    for n in order:
        cand = candidates[n]
        if left.get(cand.placement.type, 0) > 0 and used.isdisjoint(cand.cell_ids):
            chosen.append(n)
            used.update(cand.cell_ids)
            left[cand.placement.type] -= 1
    return chosen


def pose_key(type_name: str, target: str, cells) -> tuple:
    """What identifies a (block type, pose) pair: type, region and the set of its cells."""
    return type_name, target, frozenset(tuple(int(v) for v in c) for c in cells)


def solve(scene: Scene, params: AllocationParams = AllocationParams(), exclude=()) -> AllocationResult:
    """Build and solve the allocation for a scene; never raises on solver trouble.

    exclude: Placements that must not be chosen (no-goods; their yaw is ignored, the
    type and cells name the pose). Blocks already in the scene's target cells are fixed.

    Anytime: the greedy allocation is the solver's hint, and if the time limit
    ends the search before CP-SAT reports a solution (it can, during presolve of a
    big model), the greedy one is returned as FEASIBLE with the best known bound.
    """
    params.validate()
    start = time.perf_counter()
    grid = Grid(scene)
    if params.support == 'none':
        candidates = enumerate_candidates(scene, grid)
    else:   # fillers worth 0 may hold up target cells
        candidates = [c for c in enumerate_candidates(scene, grid, positive_only=False) if c.value >= 0]
    names = {t.name for t in scene.targets}
    for p in exclude:
        if p.target not in names:
            raise RadError(f'exclude names target region {p.target!r}, which the scene does not have')
    banned = {pose_key(p.type, p.target, p.cells) for p in exclude}
    if banned:
        candidates = [c for c in candidates
                      if pose_key(c.placement.type, c.placement.target, c.placement.cells) not in banned]
    counts = available_counts(scene, grid)
    arm = None
    if params.support in ('arm', 'hand'):
        candidates, counts, arm = arm_filter(scene, grid, candidates, params.gamp)
    occupied = None
    if params.support != 'none':
        occupied = np.zeros(grid.num_cells, dtype=bool)
        for cells in blocks_on_grid(scene, grid).values():
            occupied[cells] = True
    costs = None
    if params.prefer == 'open':
        costs = finger_costs(scene, grid, candidates, params.gamp)
    model, w, scale = build_model(candidates, counts, params.support, grid, occupied, params.prefer, costs)
    incumbent = set(greedy(candidates, counts)) if params.support == 'none' else set()
    for n, var in enumerate(w):
        model.add_hint(var, n in incumbent)
    rounds = HAND_ROUNDS if params.support == 'hand' else 1
    gamp = params.gamp
    drops = params.support == 'hand' and gamp.drop and gamp.effector == 'hand' and scene.studs is None
    best = None
    # Where GAMP drops, the rounds ask the hand that only sets blocks down (module docstring).
    for solver, status, picked, unplaced in solve_rounds(model, w, candidates, scene, rounds, params.time_limit_s,
                                                          start, params.seed, params.num_workers,
                                                          replace(gamp, drop=False) if drops else gamp):
        if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
            if best is not None:
                break               # keep what the solves before found
            return _unsolved(scene, grid, solver, status, candidates, incumbent, start, arm)
        left_out = set(unplaced)
        placed_value = sum(candidates[n].value for k, n in enumerate(picked) if k not in left_out)
        if best is None:        # the first solve's bound is the whole model's
            objective_bound = float(solver.best_objective_bound)
        if best is None or placed_value > best[0]:
            best = (placed_value, picked, solver.status_name(status))
    _, picked, name = best
    elapsed = time.perf_counter() - start
    # c^T g can never exceed the number of free target cells.
    free_targets = float(grid.is_target.sum() - _filled_targets(scene, grid))
    chosen = tuple(candidates[n].placement for n in picked)
    value = float(sum(candidates[n].value for n in picked))
    # scale * c^T g + coverage <= bound with 0 <= coverage < scale: c^T g <= bound / scale.
    bound = math.floor(objective_bound / scale + 1e-9) if scale > 1 else objective_bound
    return AllocationResult(name, value, min(float(bound), free_targets), elapsed, chosen, arm=arm)


def _unsolved(scene: Scene, grid: Grid, solver, status, candidates, incumbent, start: float, arm) -> AllocationResult:
    """What `solve` answers when CP-SAT found no allocation: the greedy one where the time limit
    cut the search short, else nothing."""
    name = solver.status_name(status)
    elapsed = time.perf_counter() - start
    free_targets = float(grid.is_target.sum() - _filled_targets(scene, grid))
    if status == cp_model.UNKNOWN and incumbent:
        # CP-SAT's bound means nothing without a status; only the cell count is proven.
        value = float(sum(candidates[n].value for n in incumbent))
        chosen = tuple(candidates[n].placement for n in sorted(incumbent))
        return AllocationResult('OPTIMAL' if value >= free_targets else 'FEASIBLE', value, free_targets, elapsed,
                                chosen, arm=arm)
    return AllocationResult(name, 0.0, 0.0, elapsed, arm=arm)


def solve_rounds(model, w, candidates: list[Candidate], scene: Scene, rounds: int, time_limit_s: float,
                 start: float, seed: int = 0, num_workers: int = 1, gamp=None, way_down: bool = False):
    """Solve `model` (one bool `w[n]` per candidate), then again without the picked poses the hand
    cannot place beside the others (`hand_unplaced`), at most `rounds` solves, the first with the
    whole `time_limit_s`, the others with what is left of it since `start` (none with 50 ms or
    less). Yields (solver, status, picked candidate indices, indices into picked the hand cannot
    place) per solve; ends after a solve with no answer (picked empty), or with nothing to rule
    out. One round: the plain solve, the hand not asked. The support rule 'hand' and
    `rad_core.allocation.supply` choose among the answers, each by its own measure. way_down: the
    order's (`allocation.order.order_model`)."""
    for round_ in range(rounds):
        left = time_limit_s - (time.perf_counter() - start)
        if round_ and left <= 0.05:
            return
        solver = cp_solver(time_limit_s if not round_ else left, num_workers, seed)
        status = solver.solve(model)
        if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
            yield solver, status, [], []
            return
        picked = [n for n in range(len(candidates)) if solver.boolean_value(w[n])]
        unplaced = []
        if rounds > 1 and picked:
            unplaced = hand_unplaced(scene, [candidates[n].placement for n in picked], gamp, way_down)
        yield solver, status, picked, unplaced
        if not unplaced:
            return
        for k in unplaced:
            model.add(w[picked[k]] == 0)


def hand_unplaced(scene: Scene, placements, gamp=None, way_down: bool = False) -> list[int]:
    """The indices of the `placements` (allocation.Placement, of the scene's free cells) that no
    order `allocation.order` finds places beside the others (the support rule 'hand' and
    `rad_core.allocation.supply` rule them out and solve again; `HandOrder.left_out`: poses that
    would tip what holds them count only where nothing else is left out)."""
    placements = list(placements)
    grid = Grid(scene)
    regions = [t.name for t in scene.targets]
    keys = [tuple(sorted(grid.index(regions.index(p.target), c) for c in p.cells)) for p in placements]
    return hand_order(scene, placements, gamp=gamp, way_down=way_down).left_out(keys)


def _filled_targets(scene: Scene, grid: Grid) -> int:
    return sum(int(grid.is_target[cells].sum()) for cells in blocks_on_grid(scene, grid).values())


def coverage_bound(scene: Scene, time_limit_s: float = 2.0, occupied=None, counts=None) -> float:
    """An upper bound on the target coverage any continuation from the scene state can
    reach, whatever the allocation and order: the most target cells disjoint poses of the
    blocks still on the table can cover (no stability, non-target cells free), plus what is
    already filled, over all target cells. Proven by CP-SAT (its bound if the time limit
    cuts the search). occupied / counts: the state's cells and blocks, when the scene's
    blocks do not show them (default: from the scene)."""
    grid = Grid(scene)
    if occupied is None:
        occupied = np.zeros(grid.num_cells, dtype=bool)
        for cells in blocks_on_grid(scene, grid).values():
            occupied[cells] = True
    counts = counts if counts is not None else available_counts(scene, grid)
    candidates = [c for c in enumerate_candidates(scene, grid, positive_only=False)
                  if not occupied[list(c.cell_ids)].any()]
    return max_coverage(grid, occupied, candidates, counts, time_limit_s)


def max_coverage(grid: Grid, occupied, candidates: list[Candidate], counts: dict[str, int],
                 time_limit_s: float = 2.0) -> float:
    """What `coverage_bound` proves, over given free candidate poses and blocks per type: the
    cells filled (occupied) plus the most target cells disjoint poses cover, over all target cells."""
    total = int(grid.is_target.sum())
    filled = int((grid.is_target & occupied).sum())
    scored = []
    for c in candidates:
        k = int(grid.is_target[list(c.cell_ids)].sum())
        if k:
            scored.append(Candidate(c.placement, c.cell_ids, k))
    if not scored or total == 0:
        return filled / total if total else 1.0
    model, _, _ = build_model(scored, counts)
    solver = cp_solver(time_limit_s)
    status = solver.solve(model)
    best = float(solver.best_objective_bound) if status in (cp_model.OPTIMAL, cp_model.FEASIBLE) \
        else float(total - filled)
    return min(1.0, (filled + math.floor(best + 1e-9)) / total)

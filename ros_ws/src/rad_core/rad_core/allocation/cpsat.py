"""The allocation MILP of the paper's Sec. IV-A, solved with OR-Tools CP-SAT.

    maximize    c^T g,   g = sum_{i,k} w_{i,k} p_{i,k}
    subject to  g[j] <= 1                for every grid cell j
                sum_k w_{i,k} <= N_i     for every block type i
                w_{i,k} in {0, 1}

Since cells hold at most one unit, each pose is used at most once, so the
integer w of the paper is binary here without loss.
"""

from __future__ import annotations

import math
import time
from collections import defaultdict
from dataclasses import dataclass

from ortools.sat.python import cp_model

from rad_core.allocation.placements import Candidate, enumerate_candidates
from rad_core.allocation.result import AllocationResult
from rad_core.errors import RadError
from rad_core.grid import Grid, blocks_on_grid
from rad_core.scene import Scene


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

    def validate(self) -> None:
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


def build_model(candidates: list[Candidate], counts: dict[str, int]):
    """CP-SAT model and its decision variables, one per candidate pose."""
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
    model.maximize(sum(cand.value * w[n] for n, cand in enumerate(candidates)))
    return model, w


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


def solve(scene: Scene, params: AllocationParams = AllocationParams()) -> AllocationResult:
    """Build and solve the allocation for a scene; never raises on solver trouble.

    Anytime: the greedy allocation is the solver's hint, and if the time limit
    ends the search before CP-SAT reports a solution (it can, during presolve of a
    big model), the greedy one is returned as FEASIBLE with the best known bound.
    """
    params.validate()
    start = time.perf_counter()
    grid = Grid(scene)
    candidates = enumerate_candidates(scene, grid)
    counts = available_counts(scene, grid)
    model, w = build_model(candidates, counts)
    incumbent = set(greedy(candidates, counts))
    for n, var in enumerate(w):
        model.add_hint(var, n in incumbent)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = float(params.time_limit_s)
    solver.parameters.num_workers = params.num_workers
    solver.parameters.random_seed = params.seed
    # CP-SAT would install its own SIGINT handler for the solve and leave SIGINT at
    # the default action afterwards: a node then dies by the signal instead of
    # shutting down. Signals belong to the process owner, not to a library call.
    solver.parameters.catch_sigint_signal = False
    status = solver.solve(model)
    name = solver.status_name(status)
    elapsed = time.perf_counter() - start
    # c^T g can never exceed the number of free target cells.
    free_targets = float(grid.is_target.sum() - _filled_targets(scene, grid))
    if status in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        chosen = tuple(c.placement for n, c in enumerate(candidates) if solver.boolean_value(w[n]))
        return AllocationResult(name, float(solver.objective_value),
                                min(float(solver.best_objective_bound), free_targets), elapsed, chosen)
    if status == cp_model.UNKNOWN:
        # CP-SAT's bound means nothing without a status; only the cell count is proven.
        value = float(sum(candidates[n].value for n in incumbent))
        chosen = tuple(candidates[n].placement for n in sorted(incumbent))
        return AllocationResult('OPTIMAL' if value >= free_targets else 'FEASIBLE', value, free_targets, elapsed,
                                chosen)
    return AllocationResult(name, 0.0, 0.0, elapsed)


def _filled_targets(scene: Scene, grid: Grid) -> int:
    return sum(int(grid.is_target[cells].sum()) for cells in blocks_on_grid(scene, grid).values())

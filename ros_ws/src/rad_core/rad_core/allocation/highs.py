"""An independent MILP solve of the same allocation with SciPy's HiGHS.

Used to cross-check CP-SAT (tests) and to compare solvers (benchmarks). It uses
the full formulation, poses of non-positive value included.
"""

from __future__ import annotations

import time

import numpy as np

from rad_core.allocation.cpsat import available_counts
from rad_core.allocation.placements import enumerate_candidates
from rad_core.allocation.result import AllocationResult
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Scene


def solve_highs(scene: Scene, time_limit_s: float = 60.0) -> AllocationResult:
    from scipy.optimize import Bounds, LinearConstraint, milp  # scipy: only the HiGHS cross-check pays for its import
    from scipy.sparse import lil_matrix  # scipy: only the HiGHS cross-check pays for its import

    start = time.perf_counter()
    grid = Grid(scene)
    cands = enumerate_candidates(scene, grid, positive_only=False)
    counts = available_counts(scene, grid)
    types = sorted(scene.block_types)
    n = len(cands)
    if n == 0:
        return AllocationResult('OPTIMAL', 0.0, 0.0, time.perf_counter() - start, solver='highs')
    a = lil_matrix((grid.num_cells + len(types), n))
    for k, cand in enumerate(cands):
        for c in cand.cell_ids:
            a[c, k] = 1
        a[grid.num_cells + types.index(cand.placement.type), k] = 1
    ub = np.concatenate([np.ones(grid.num_cells), [counts[t] for t in types]])
    c = -np.array([cand.value for cand in cands], dtype=float)
    res = milp(c, constraints=LinearConstraint(a.tocsr(), -np.inf, ub), integrality=np.ones(n),
               bounds=Bounds(0, 1), options={'time_limit': time_limit_s})
    elapsed = time.perf_counter() - start
    if res.x is None:
        return AllocationResult('UNKNOWN', 0.0, 0.0, elapsed, solver='highs')
    status = 'OPTIMAL' if res.status == 0 else 'FEASIBLE'
    chosen = tuple(cand.placement for k, cand in enumerate(cands) if res.x[k] > 0.5)
    bound = -getattr(res, 'mip_dual_bound', res.fun)
    return AllocationResult(status, float(-res.fun), float(bound), elapsed, chosen, solver='highs')

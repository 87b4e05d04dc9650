"""CP-SAT vs HiGHS on generated two-sided scenes, same scenes, same run.

    python benchmarks/bench_allocation.py [--scenes 50] [--grids 3 4 5 6]

Prints per grid size: solve time median / p95 (ms, including model building)
for both solvers, the fraction proven optimal, whether the optima agree, and
the ratio of median times.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from rad_core.allocation import AllocationParams, solve, validate_allocation
from rad_core.allocation.highs import solve_highs
from rad_core.domain.generator import GeneratorConfig, generate_scene


def run(grids, n_scenes, seed):
    rows = []
    for g in grids:
        cp_t, hi_t, cp_opt, agree, cells = [], [], 0, 0, []
        for s in range(n_scenes):
            scene = generate_scene(GeneratorConfig(grid=g, sides=2), seed + s)
            a = solve(scene, AllocationParams(time_limit_s=30, seed=0))
            b = solve_highs(scene, time_limit_s=30)
            assert not validate_allocation(scene, a), validate_allocation(scene, a)
            cp_t.append(a.solve_time_s * 1e3)
            hi_t.append(b.solve_time_s * 1e3)
            cp_opt += a.status == 'OPTIMAL'
            agree += abs(a.objective - b.objective) < 1e-6
            cells.append(scene.num_target_cells)
        row = {'grid': g, 'scenes': n_scenes, 'target_cells_mean': float(np.mean(cells)),
               'cpsat_ms_median': float(np.median(cp_t)), 'cpsat_ms_p95': float(np.percentile(cp_t, 95)),
               'highs_ms_median': float(np.median(hi_t)), 'highs_ms_p95': float(np.percentile(hi_t, 95)),
               'cpsat_optimal': cp_opt / n_scenes, 'objectives_agree': agree / n_scenes,
               'highs_over_cpsat_median': float(np.median(hi_t) / np.median(cp_t))}
        rows.append(row)
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=50)
    p.add_argument('--grids', type=int, nargs='+', default=[3, 4, 5, 6])
    p.add_argument('--seed', type=int, default=1000)
    p.add_argument('--json', help='also write the rows to this file')
    args = p.parse_args()
    rows = run(args.grids, args.scenes, args.seed)
    print(f'{"g":>2} {"cells":>6} | {"CP-SAT ms med":>13} {"p95":>7} {"optimal":>7} | '
          f'{"HiGHS ms med":>12} {"p95":>7} | {"agree":>5} {"HiGHS/CP-SAT":>12}')
    for r in rows:
        print(f'{r["grid"]:>2} {r["target_cells_mean"]:>6.1f} | {r["cpsat_ms_median"]:>13.2f} '
              f'{r["cpsat_ms_p95"]:>7.2f} {r["cpsat_optimal"]:>7.0%} | {r["highs_ms_median"]:>12.2f} '
              f'{r["highs_ms_p95"]:>7.2f} | {r["objectives_agree"]:>5.0%} {r["highs_over_cpsat_median"]:>12.2f}')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(rows, f, indent=1)


if __name__ == '__main__':
    main()

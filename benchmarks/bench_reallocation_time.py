"""What re-allocation on stall costs /plan_assembly, and what it gains.

    python benchmarks/bench_reallocation_time.py [--scenes 20] [--grids 4 5] [--policy milp-dqn-lookahead]

Plans generated two-sided scenes (seeds 100..) in-process with the code behind
/plan_assembly (`sequencing.planning.plan.plan_assembly`, the stable allocation as the
assembly node's default, GAMP in-process, the sequencer's `rank`), once without and
once with re-allocation, and prints per grid size the median and p95 planning
time of each, the ratio of the medians (issue 9's target: re-allocation adds under
20 %), the share of time spent re-allocating, and the predicted coverage of both.
Over DDS each plan also pays the service round trips (bench_plan_assembly.py), so
in-process the relative cost of re-allocation is the larger one.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rad_core.allocation import AllocationParams, solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.gamp.action import MotionPlanner
from rad_core.sequencing.decide.sequencer import POLICIES, Sequencer, SequencerConfig
from rad_core.sequencing.planning.plan import local_motion_planner, plan_assembly
from rad_core.sequencing.planning.reallocation import local_allocate


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=20)
    p.add_argument('--grids', type=int, nargs='+', default=[4, 5])
    p.add_argument('--seed', type=int, default=100)
    p.add_argument('--policy', choices=POLICIES, default='milp-dqn-lookahead')
    args = p.parse_args()
    stable = AllocationParams(support='stable')
    planner = MotionPlanner()
    sequencer = Sequencer(SequencerConfig(policy=args.policy))
    local = local_motion_planner(planner)
    print(f'policy {args.policy}, {args.scenes} scenes per grid, in-process, times in ms (median / p95)')
    for g in args.grids:
        times = {False: [], True: []}
        coverage = {False: [], True: []}
        realloc_s, events = [], []
        for s in range(args.seed, args.seed + args.scenes):
            scene = generate_scene(GeneratorConfig(grid=g), s)
            for on in (False, True):
                sequencer.forget()   # milp-dqn-dfs would otherwise answer the second run from its kept line
                t0 = time.perf_counter()
                plan = plan_assembly(scene, lambda sc: solve(sc, stable), local, sequencer.rank, seed=0,
                                     reallocate=local_allocate(stable) if on else None)
                times[on].append(time.perf_counter() - t0)
                coverage[on].append(plan.predicted_coverage)
                if on:
                    realloc_s.append(plan.timings.get('reallocation', 0.0))
                    events.append(len(plan.reallocations))
        med = {k: float(np.median(v)) for k, v in times.items()}
        print(f'g={g}: without {med[False] * 1e3:8.0f} / {np.percentile(times[False], 95) * 1e3:8.0f}   '
              f'with {med[True] * 1e3:8.0f} / {np.percentile(times[True], 95) * 1e3:8.0f}   '
              f'median ratio {med[True] / med[False]:.2f}   '
              f'mean ratio {np.mean(times[True]) / np.mean(times[False]):.2f}')
        print(f'      re-allocating: {sum(realloc_s) / sum(times[True]):.0%} of the time with it, '
              f'{np.mean(events):.1f} re-allocations per plan, {sum(1 for e in events if e)} of {len(events)} '
              f'plans re-allocated')
        print(f'      predicted coverage: without {np.mean(coverage[False]):.3f}, with {np.mean(coverage[True]):.3f}')
    planner.close()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

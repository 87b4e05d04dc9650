"""Evaluation throughput serial and over Dask workers (`rad eval --workers N`).

    python benchmarks/bench_distributed.py [--scenes 20] [--grid 4] [--agent heur-verified] [--verify]
                                           [--workers 1 2] [--seed 0]

Runs the same generated two-sided scenes with `evaluation.evaluate` (the serial path) and
with `distributed.evaluate_distributed` on a LocalCluster of N single-threaded worker
processes on 127.0.0.1 (what `rad eval --workers N` starts), and prints for each the
scenes per second, the speed-up over serial (the issue's target: at least 1.7x with 2
workers on a 2-core machine), the cluster's start-up time (counted apart: it is paid once
per run, not per scene), and whether the rows and metrics equal the serial run's.

The workers' first scenes include their cold start (imports, the policy, the robot's
world), as in a real run and as the serial run's first scene does. Worker processes run
torch on one thread each (Dask's OMP_NUM_THREADS=1); the serial run uses torch's default.

Not yet measured on an idle machine; a 4-scene smoke run only shows the script works.
"""

from __future__ import annotations

import argparse
import time

from rad_core.distributed import AgentArgs, dask_client, evaluate_distributed
from rad_core.evaluation import evaluate, generated_scenes, uses_robot


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=20)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--agent', default='heur-verified', help='an agent of rad eval, e.g. milp-dqn-mixed-lookahead')
    p.add_argument('--verify', action='store_true', help="the agent's --verify variant")
    p.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    args = p.parse_args()

    agent_args = AgentArgs(args.agent, verify=args.verify)
    agent = agent_args.build()
    robot = uses_robot(agent, True)
    scenes = list(generated_scenes(args.grid, 2, args.scenes, args.seed))
    print(f'{agent.name}, {"robot (teleport)" if robot else "no robot"}, {args.scenes} g={args.grid} two-sided '
          f'scenes (seeds {args.seed}..{args.seed + args.scenes - 1})')

    t0 = time.perf_counter()
    serial = evaluate(agent, scenes, robot, args.seed)
    serial_s = time.perf_counter() - t0
    print(f'{"run":<10} {"start-up s":>10} {"run s":>8} {"scenes/s":>9} {"speed-up":>9} {"with start-up":>14}  rows')
    print(f'{"serial":<10} {"-":>10} {serial_s:8.2f} {args.scenes / serial_s:9.3f} {1.0:9.2f} {1.0:14.2f}  -')

    for n in args.workers:
        t0 = time.perf_counter()
        with dask_client(workers=n) as client:
            startup_s = time.perf_counter() - t0
            t1 = time.perf_counter()
            result = evaluate_distributed(agent_args, scenes, robot, args.seed, client=client)
            run_s = time.perf_counter() - t1
        same = 'identical' if result == serial else 'DIFFER'
        print(f'{f"{n} worker" + "s" * (n > 1):<10} {startup_s:10.2f} {run_s:8.2f} {args.scenes / run_s:9.3f} '
              f'{serial_s / run_s:9.2f} {serial_s / (run_s + startup_s):14.2f}  {same}')
    return 0


if __name__ == '__main__':   # the workers are spawned processes that import this module
    raise SystemExit(main())

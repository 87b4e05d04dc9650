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

Measured on this 2-core machine, nothing else running (2026-12-02, `--scenes 20 --grid 4 --agent
milp-dqn-mixed-lookahead --verify`): serial 0.687 scenes/s, 1 worker 0.614 (0.89x), 2 workers
1.074 (1.56x; 1.47x with the 1.2 s start-up): below the 1.7x target; rows identical. With
`--scenes 40`: serial 0.709, 1 worker 0.768 (1.08x), 2 workers 1.400 (1.97x; 1.90x with the 1.1 s
start-up), rows identical: each worker's cold start (network, PyBullet world) weighs less.

    python benchmarks/bench_distributed.py --train [--train-steps 400] [--actors 1 2] [--dataset FILE]

Training (`rad train --actors N`): environment steps per second of a short run of the serial
trainer (for reference) and of the learner fed by 1 and 2 actors (cluster start-up counted
apart), with the gradient steps taken, on a small network and a dataset of 24 g=3 scenes built
on the fly unless --dataset is given. Measured (same day, idle, `--train --train-steps 400`):
serial 50.1 env steps/s (151 gradient steps), 1 actor 76.6 (1.53x, 137), 2 actors 69.5 (1.39x,
85): the learner falls behind the actors in so short a run.
"""

from __future__ import annotations

import argparse
import time

from rad_core.distributed import AgentArgs, dask_client, evaluate_distributed
from rad_core.evaluation import evaluate, uses_robot
from rad_core.scene_sources import generated_scenes


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=20)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--agent', default='heur-verified', help='an agent of rad eval, e.g. milp-dqn-mixed-lookahead')
    p.add_argument('--verify', action='store_true', help="the agent's --verify variant")
    p.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    p.add_argument('--train', action='store_true', help='benchmark training (--actors) instead of evaluation')
    p.add_argument('--train-steps', type=int, default=400, help='with --train: environment steps per run')
    p.add_argument('--actors', type=int, nargs='+', default=[1, 2], help='with --train: actor counts')
    p.add_argument('--dataset', help='with --train: training scenes (default: 24 g=3 scenes built now)')
    args = p.parse_args()
    if args.train:
        return bench_train(args)

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


def bench_train(args) -> int:
    import tempfile
    from pathlib import Path

    from rad_core.learning.actors import ActorConfig, train_with_actors
    from rad_core.learning.dataset import build
    from rad_core.learning.dqn import TrainConfig, train

    with tempfile.TemporaryDirectory() as tmp:
        dataset = args.dataset
        if dataset is None:
            dataset = str(Path(tmp) / 'tiny.jsonl.gz')
            build(dataset, [3], 24)
        n = args.train_steps
        cfg = dict(dataset=dataset, total_steps=n, learning_starts=min(100, n // 4), train_every=2,
                   target_update=100, batch_size=16, buffer_size=5000, eval_every=10 * n, eval_scenes=1,
                   checkpoint_every_s=1e9, dim=32, heads=4, rounds=2, ff=64, readout=32, seed=args.seed)
        print(f'training: {n} environment steps, small network, train_every 2 (evaluation: 1 scene at the end)')
        print(f'{"run":<10} {"start-up s":>10} {"run s":>8} {"env steps/s":>12} {"grad steps":>11} {"speed-up":>9}')
        t0 = time.perf_counter()
        r = train(TrainConfig(**cfg), Path(tmp) / 'serial')
        serial_rate = r['env_steps'] / (time.perf_counter() - t0)
        print(f'{"serial":<10} {"-":>10} {time.perf_counter() - t0:8.2f} {serial_rate:12.1f} {r["grad_steps"]:11d} '
              f'{1.0:9.2f}')
        for k in args.actors:
            t0 = time.perf_counter()
            with dask_client(workers=k) as client:
                startup_s = time.perf_counter() - t0
                t1 = time.perf_counter()
                r = train_with_actors(TrainConfig(**cfg), Path(tmp) / f'actors-{k}', ActorConfig(actors=k),
                                      client=client)
                run_s = time.perf_counter() - t1
            rate = r['env_steps'] / run_s
            print(f'{f"{k} actor" + "s" * (k > 1):<10} {startup_s:10.2f} {run_s:8.2f} {rate:12.1f} '
                  f'{r["grad_steps"]:11d} {rate / serial_rate:9.2f}')
    return 0


if __name__ == '__main__':   # the workers are spawned processes that import this module
    raise SystemExit(main())

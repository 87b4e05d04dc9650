"""Speed and memory of the learned sequencer (issue figures; a benchmark, not a test).

    python benchmarks/bench_sequencer.py                      # all figures
    python benchmarks/bench_sequencer.py --decisions 300 --train-steps 3000

Prints, each measured in this process on this machine:
- decision latency: one QPolicy.scores call (graph + network forward) on states
  of g = 5 scenes, median and p95, against the 5 ms target;
- training throughput: environment steps/s and gradient steps/s of a short
  MILP-DQN training (the default TrainConfig, one torch thread), and where a
  training step's time goes (environment incl. physics, graph building,
  acting forward, learning);
- peak resident memory of the training process.
Nothing else should run meanwhile: the figures are wall-clock.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from rad_core.allocation import solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.learning.graph import Observer
from rad_core.learning.policy import QPolicy
from rad_core.sequencing.decide.actions import action_space
from rad_core.training import dqn
from rad_core.training.dataset import build

ROOT = Path(__file__).resolve().parents[1]


def decision_latency(policy: QPolicy, n: int, grid: int) -> dict:
    times, sizes = [], []
    rng = np.random.default_rng(0)
    seed = 0
    while len(times) < n:
        scene = generate_scene(GeneratorConfig(grid=grid), seed)
        seed += 1
        env = AssemblyEnv(scene, EnvConfig(stability='none'))
        space = action_space('milp', env, solve(scene).placements)
        while not env.state.done and len(times) < n:
            actions = space(env)
            if not actions:
                break
            t0 = time.perf_counter()
            scores = policy.scores(env, actions, rng)
            times.append(time.perf_counter() - t0)
            sizes.append((len(Observer(env)(env, actions).kind), len(actions)))
            env.step(actions[int(np.argmax(scores[:-1]))])
    ms = 1e3 * np.array(times)
    nodes = np.array(sizes)
    return {'median_ms': float(np.median(ms)), 'p95_ms': float(np.percentile(ms, 95)),
            'nodes_mean': float(nodes[:, 0].mean()), 'candidates_mean': float(nodes[:, 1].mean())}


def training_throughput(steps: int, dataset: Path) -> dict:
    with tempfile.TemporaryDirectory() as out:
        # Epsilon fixed at its final value, so acting is mostly greedy as in most of a run.
        cfg = dqn.TrainConfig(dataset=str(dataset), total_steps=10**9, eval_every=10**9, eps_start=0.05)
        trainer = dqn.Trainer(cfg, out)
        shares = {'learn': 0.0, 'act': 0.0}
        learn, greedy = trainer.learn, trainer.greedy

        def timed(fn, key):
            def wrapper(*a, **k):
                t0 = time.perf_counter()
                r = fn(*a, **k)
                shares[key] += time.perf_counter() - t0
                return r
            return wrapper

        trainer.learn, trainer.greedy = timed(learn, 'learn'), timed(greedy, 'act')
        while trainer.pos['env_steps'] < cfg.learning_starts:   # fill the replay first
            trainer.episode()
        shares.update(learn=0.0, act=0.0)
        s0, g0, t0 = trainer.pos['env_steps'], trainer.pos['grad_steps'], time.perf_counter()
        while trainer.pos['env_steps'] - s0 < steps:
            trainer.episode()
        dt = time.perf_counter() - t0
        n, g = trainer.pos['env_steps'] - s0, trainer.pos['grad_steps'] - g0
        return {'env_steps_per_s': n / dt, 'grad_steps_per_s': g / dt, 'seconds': dt,
                'share_learning': shares['learn'] / dt, 'share_acting_forward': shares['act'] / dt,
                'share_environment_and_graphs': 1 - (shares['learn'] + shares['act']) / dt,
                'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--decisions', type=int, default=500)
    p.add_argument('--grid', type=int, default=5)
    p.add_argument('--train-steps', type=int, default=3000)
    p.add_argument('--checkpoint', default='milp-dqn', help='shipped agent name or model file')
    args = p.parse_args()
    torch.set_num_threads(1)
    lat = decision_latency(QPolicy.load(args.checkpoint), args.decisions, args.grid)
    print(f'decision latency at g = {args.grid} ({args.decisions} decisions, {lat["nodes_mean"]:.0f} nodes and '
          f'{lat["candidates_mean"]:.0f} candidates on average): median {lat["median_ms"]:.2f} ms, '
          f'p95 {lat["p95_ms"]:.2f} ms; target 5 ms: p95 is {5 / lat["p95_ms"]:.1f}x under it')
    dataset = ROOT / 'data' / 'train-g3.jsonl.gz'
    if not dataset.exists():
        dataset = Path(tempfile.mkdtemp()) / 'bench.jsonl.gz'
        build(dataset, [3], 500)
    tr = training_throughput(args.train_steps, dataset)
    print(f'training (MILP-DQN, g = 3, default config, 1 thread): {tr["env_steps_per_s"]:.1f} env steps/s, '
          f'{tr["grad_steps_per_s"]:.1f} gradient steps/s over {tr["seconds"]:.0f} s; time: learning '
          f'{100 * tr["share_learning"]:.0f} %, acting forward {100 * tr["share_acting_forward"]:.0f} %, '
          f'environment + physics + graphs {100 * tr["share_environment_and_graphs"]:.0f} %; '
          f'peak RSS {tr["peak_rss_mb"]:.0f} MB')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

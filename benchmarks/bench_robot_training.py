"""Where a robot-in-the-loop training step's time goes, and how fast it runs.

    python benchmarks/bench_robot_training.py profile [--steps 50] [--grid 4]
    python benchmarks/bench_robot_training.py bench   [--steps 150] [--grid 4]
    python benchmarks/bench_robot_training.py settle  [--scenes 40] [--grid 4]

profile: cProfile over `--steps` training-like steps (epsilon-greedy on the
shipped no-robot network, epsilon 0.3, stable allocations of g = 4 scenes, the
robot env in teleport execution); prints the share of each part (GAMP: IK,
collision probes; physics settling; judging; the network; observations; world
set-up; the allocation).
bench: the same steps with each speed-up turned on in turn (same seeds, same
actions asked), env steps/s and the ratio to the baseline; also checks that
every configuration gives the same outcomes as the baseline on the same actions.
settle: for how many simulated seconds of settling the judgement of a placement
stays what 0.5 s (the default) says, over many exploratory placements.

    python benchmarks/bench_robot_training.py eval --model runs/milp-dqn-robot/model.pt [--grids 4,5]

eval: `rad_core.experiment.evaluation.evaluate` with the robot (its default execution and
settling, a fresh world per scene, no markov, no cache: the evaluation's own
setting, not the training's) for the model and the no-robot network it started
from, on evaluation scenes 0.. with the stable allocation; --rows (default
out/cache/robot_training/rows.jsonl, '' for none) gets one compact line per (run, grid):
its figures and its scenes' rows.

A benchmark, not a test: figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import numpy as np
import torch
from common import CACHE, write_rows
from rad_core.allocation import AllocationParams, solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import TERMINATE
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
from rad_core.learning.policy import QPolicy
from rad_core.sequencing.decide.actions import action_space

SCENE_SEED = 2_000_000   # neither evaluation (0..), validation (500000..) nor training (1e6..) seeds


def scenes(grid: int, n: int):
    config = GeneratorConfig(grid=grid)
    out = []
    for i in range(n):
        s = generate_scene(config, SCENE_SEED + i)
        out.append((s, solve(s, AllocationParams(support='stable')).placements))
    return out


def rollout(config: RobotEnvConfig, steps: int, grid: int, eps: float = 0.3, seed: int = 0,
            policy: QPolicy | None = None, reuse_world: bool = False, log: list | None = None,
            passes: int = 1) -> dict:
    """`steps` epsilon-greedy robot env steps over g-scenes (each scene once per pass,
    `passes` passes over the same scenes, as validation does); time per part."""
    policy = policy or QPolicy.load('milp-dqn-mixed')
    rng = np.random.default_rng(seed)
    data = scenes(grid, max(4, steps // (3 * passes)))
    n, k, t0 = 0, 0, time.perf_counter()
    renv = None
    try:
        while n < steps:
            scene, placements = data[k % len(data)]
            k += 1
            if reuse_world and renv is not None:
                renv.load(scene)
            else:
                if renv is not None:
                    renv.close()
                renv = RobotAssemblyEnv(scene, config)
            renv.reset()
            env = renv.env
            space = action_space('milp', env, placements)
            while not env.state.done and n < steps:
                actions = space(env)
                if rng.random() < eps:
                    j = int(rng.integers(len(actions) + 1)) - 1
                else:
                    s = policy.scores(env, actions)
                    j = int(np.argmax(s))
                    j = j if j < len(actions) else -1
                a = actions[j] if j >= 0 else TERMINATE
                r = renv.step(a)
                if log is not None:
                    log.append((k, env.state.steps, a, r.outcome.value))
                n += 1
        hit_rate = None
        if renv.cache is not None:
            hit_rate = renv.cache.hits / max(1, renv.cache.hits + renv.cache.misses)
    finally:
        if renv is not None:
            renv.close()
    dt = time.perf_counter() - t0
    return {'steps': n, 'seconds': dt, 'steps_per_s': n / dt, 'hit_rate': hit_rate}


PARTS = [  # (label, function name as cProfile shows it, file fragment)
    ('GAMP plan_action (all)', 'plan_action', 'gamp/planner.py'),
    ('  IK (solve_top_down)', 'solve_top_down', 'gamp/ik.py'),
    ('  collision probes (every probe)', 'collision', 'gamp/collision.py'),
    ('  time parameterization', 'time_parameterize', 'gamp/trajectory.py'),
    ('physics settle (twin.settle)', 'settle', 'sim/twin.py'),
    ('judge (poses after settling)', '_judge', 'robot_env.py'),
    ('snap placed blocks back', '_snap_placed', 'robot_env.py'),
    ('network: observation + forward (QPolicy.scores)', 'scores', 'learning/policy.py'),
    ('  observation (Observer)', '__call__', 'learning/graph.py'),
    ('allowed actions (AllocationGuide)', 'allowed_actions', 'allocation/guide.py'),
    ('world set-up (World.__init__)', '__init__', 'sim/world.py'),
    ('scene load (World.load_scene)', 'load_scene', 'sim/world.py'),
    ('support check (any_support)', 'any_support', 'support.py'),
    ('MDP bookkeeping (AssemblyEnv.step)', 'step', 'rad_core/env/mdp.py'),
    ('allocation solve (CP-SAT, per scene)', 'solve', 'allocation/__init__.py'),
]


def cmd_profile(args) -> None:
    config = RobotEnvConfig(execution='teleport')
    policy = QPolicy.load('milp-dqn-mixed')
    prof = cProfile.Profile()
    prof.enable()
    r = rollout(config, args.steps, args.grid, policy=policy)
    prof.disable()
    stats = pstats.Stats(prof)
    total = r['seconds']
    print(f'{r["steps"]} robot env steps (g = {args.grid}, teleport, eps 0.3 on milp-dqn-mixed) in {total:.1f} s: '
          f'{r["steps_per_s"]:.2f} steps/s, {1e3 * total / r["steps"]:.0f} ms/step (under cProfile)')
    print(f'{"part":44s} {"s":>7s} {"share":>6s} {"calls":>7s}')
    for label, name, frag in PARTS:
        cum, calls = 0.0, 0
        for (file, _, fn), (cc, nc, tt, ct, callers) in stats.stats.items():
            if fn == name and frag in file.replace('\\', '/'):
                cum += ct
                calls += nc
        print(f'{label:44s} {cum:7.2f} {100 * cum / total:5.1f}% {calls:7d}')
    if args.top:
        stats.sort_stats('tottime').print_stats(args.top)


def cmd_bench(args) -> None:
    from dataclasses import replace
    base = RobotEnvConfig(execution='teleport')
    policy = QPolicy.load('milp-dqn-mixed')
    markov = replace(base, markov=True)
    cached = replace(markov, cache=True)
    variants = [('baseline: teleport, settle 0.5 s, new World per scene', base, False),
                ('+ one World for all scenes (load_scene)', base, True),
                ('+ markov (arm HOME, unplaced blocks back)', markov, True),
                ('+ step cache', cached, True)]
    if args.settle > 0:
        variants.append((f'+ settle {args.settle} s', replace(cached, settle_s=args.settle), True))
    print(f'training-like steps: eps 0.3 on milp-dqn-mixed, g = {args.grid}, {args.steps} steps, '
          f'each scene once per pass, {args.passes} pass(es)')
    ref_log, first = None, None
    for label, cfg, reuse in variants:
        log = []
        r = rollout(cfg, args.steps, args.grid, policy=policy, reuse_world=reuse, log=log, seed=args.seed,
                    passes=args.passes)
        first = first or r['steps_per_s']
        same = ''
        if ref_log is None:
            ref_log = log
        else:
            agree = sum(a == b for a, b in zip(ref_log, log))
            same = f'  same outcomes as the baseline: {agree}/{len(ref_log)}'
        hits = f'  cache hits {r["hit_rate"]:.2f}' if r.get('hit_rate') is not None else ''
        print(f'{label:50s} {r["steps_per_s"]:6.2f} steps/s  x{r["steps_per_s"] / first:4.2f}{hits}{same}',
              flush=True)


def cmd_settle(args) -> None:
    """Judge the same exploratory placements after settle_s of 0.5 s and shorter:
    before each step of a random walk the env is snapshot, each shorter settle
    tried from it and undone (`RobotAssemblyEnv.restore`), then the walk goes on
    with 0.5 s."""
    from dataclasses import replace

    from rad_core.env.robot_env import outcome_class
    lengths = [0.3, 0.2, 0.15, 0.1, 0.05]
    rng = np.random.default_rng(args.seed)
    data = scenes(args.grid, args.scenes)
    agree = {t: 0 for t in lengths}
    judged, unstable = 0, 0
    base = RobotEnvConfig(execution='teleport', markov=True)
    renv = RobotAssemblyEnv(data[0][0], base)
    try:
        for scene, placements in data:
            renv.load(scene)
            renv.reset()
            space = action_space('milp', renv.env, placements)
            while not renv.env.state.done:
                actions = space(renv.env)
                a = actions[int(rng.integers(len(actions)))] if actions else TERMINATE
                snap = renv.snapshot()
                outs = {}
                for t in lengths:
                    renv.config = replace(base, settle_s=t)
                    outs[t] = renv.step(a).outcome
                    renv.restore(snap)
                renv.config = base
                ref = renv.step(a).outcome
                if a is TERMINATE:
                    continue
                judged += 1
                unstable += outcome_class(ref) == 'unstable'
                for t in lengths:
                    agree[t] += outs[t] == ref
    finally:
        renv.close()
    print(f'{judged} random allocation placements (g = {args.grid}, {args.scenes} scenes; {unstable} judged '
          f'unstable at 0.5 s): verdict equal to settle 0.5 s')
    for t in lengths:
        print(f'  settle {t:4.2f} s: {agree[t]}/{judged} ({100 * agree[t] / max(judged, 1):.1f} %)')


def cmd_eval(args) -> None:
    from rad_core.domain.scene_sources import generated_scenes
    from rad_core.experiment.evaluation import evaluate, get_agent
    out = []
    runs = [('trained with the robot', args.model, False), ('start (no robot)', args.baseline, False)]
    if args.verify:
        runs.append(('trained, + verify (GAMP)', args.model, True))
    for label, model, verify in runs:
        agent = get_agent('milp-dqn-mixed', checkpoint=model)   # milp actions, stable allocation
        if verify:
            from dataclasses import replace
            agent = replace(agent, name=agent.name + '+verify', verified=True)
        for g in (int(v) for v in args.grids.split(',')):
            t0 = time.perf_counter()
            r = evaluate(agent, generated_scenes(g, 2, args.scenes, 0), robot=True, seed=0)
            out.append({'run': label, 'grid': g, 'model': model, 'allocation': 'stable', **r})
            print(f'{label:24s} g = {g}: R {r["R"]:.2f}  coverage {r["coverage"]:.3f}  rel {r["coverage_rel"]:.3f}  '
                  f'f {r["f"]:.2f} (f_g {r["f_g"]:.2f}, f_p {r["f_p"]:.2f})  d {r["d"]:.2f}  e {r["e"]:.2f}  '
                  f'n {r["n"]}  ({time.perf_counter() - t0:.0f} s)', flush=True)
    if args.rows:
        print(f'wrote {write_rows(Path(args.rows), out)}')


def main(argv=None) -> int:
    torch.set_num_threads(1)   # as training runs (TrainConfig.threads)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest='cmd', required=True)
    p = sub.add_parser('profile')
    p.add_argument('--steps', type=int, default=50)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--top', type=int, default=0, help='also print the top N functions by own time')
    p.set_defaults(func=cmd_profile)
    p = sub.add_parser('bench')
    p.add_argument('--steps', type=int, default=150)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--settle', type=float, default=0.0, help='also try this shorter settle (s)')
    p.add_argument('--passes', type=int, default=1, help='passes over the same scenes (validation: many)')
    p.set_defaults(func=cmd_bench)
    p = sub.add_parser('settle')
    p.add_argument('--scenes', type=int, default=40)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--seed', type=int, default=0)
    p.set_defaults(func=cmd_settle)
    p = sub.add_parser('eval')
    p.add_argument('--model', required=True)
    p.add_argument('--baseline', default='milp-dqn-mixed')
    p.add_argument('--grids', default='4,5')
    p.add_argument('--scenes', type=int, default=30)
    p.add_argument('--rows', default=str(CACHE / 'robot_training' / 'rows.jsonl'),
                   help="one line per (run, grid): figures and per-scene rows ('' for none)")
    p.add_argument('--verify', action='store_true', help='also the model taking the best GAMP-feasible action')
    p.set_defaults(func=cmd_eval)
    args = ap.parse_args(argv)
    args.func(args)
    return 0


if __name__ == '__main__':
    sys.exit(main())

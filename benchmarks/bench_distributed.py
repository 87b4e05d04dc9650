"""Evaluation throughput serial and over Dask workers (`rad eval --workers N`), start-up included.

    python benchmarks/bench_distributed.py [--scenes 40] [--grid 4] [--agent default] [--verify]
                                           [--workers 1 2] [--seed 0] [--start-method fork|spawn|forkserver]
                                           [--serial-threads N] [--cold] [--rounds 1] [--results DIR] [--rows FILE]
    python benchmarks/bench_distributed.py --from-rows docs/results/distributed.rows.jsonl   # the page again

Runs the same generated two-sided scenes with `evaluation.evaluate` (the serial path, in this
process, as `rad eval` runs it: the agent built first, the planner inside the run) and with
`distributed.evaluate_distributed` on a LocalCluster of N single-threaded worker processes on
127.0.0.1 (what `rad eval --workers N` starts), and prints for each: the start-up (the cluster,
then `warm_up`: every worker builds the agent, its network and the planner's worlds), the run,
the cluster's shut-down, the scenes per second over all of it and the speed-up over serial with
and without start-up (the issue's target: at least 1.8x with 2 workers on 40 g = 4 scenes,
start-up included, on this 2-core machine), and whether the rows equal the serial run's
(wall-clock fields, `reallocation_s` and the re-allocations' `solve_time_s`, left out). The
machine is shared, so each run also prints the load average (1 min) before and after it and
`others`: the cores the other processes kept busy on average during it (the machine's busy
time from /proc/stat less this process's and its workers'); --wait-quiet S waits up to S
seconds before each run for the others to go quiet (< 0.1 core).
--cold: first, a fresh process's cold start, step by step (what a spawned worker pays).
--rounds R: serial and then each worker count, R times over. Writes <results>/distributed.md (one
row per run on workers: its round's serial time, its own with start-up, the speed-up, CPU seconds)
and distributed.rows.jsonl (one line per run: times, loads, command, date); --results DIR (default
docs/results); --rows FILE also appends those lines to FILE; --from-rows FILE rebuilds the page.

The serial run uses torch's default thread count (as `rad eval` does: the cores), the workers
one thread each; a network's scores can differ in the last bits between the two, enough to
flip a near tie, so with a learned agent a few rows can differ from a serial run on more
threads (`--serial-threads 1` gives the workers' rows exactly). Results: docs/results/distributed.md.

    python benchmarks/bench_distributed.py --train [--train-steps 400] [--actors 1 2] [--dataset FILE]

Training (`rad train --actors N`): environment steps per second of a short run of the serial
trainer (for reference) and of the learner fed by 1 and 2 actors (cluster start-up counted
apart), with the gradient steps taken, on a small network and a dataset of 24 g=3 scenes built
on the fly unless --dataset is given. Measured (2026-12-02, idle, `--train --train-steps 400`):
serial 50.1 env steps/s (151 gradient steps), 1 actor 76.6 (1.53x, 137), 2 actors 69.5 (1.39x,
85): the learner falls behind the actors in so short a run.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from common import RESULTS, command_line, page_meta, read_rows, write_page

WALL_CLOCK = ('reallocation_s', 'solve_time_s')


def main() -> int:
    # rad (and with it torch, Dask) imported below, not above: --cold-child times those imports.
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=40)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--agent', default='default', help='an agent of rad eval, e.g. default, heur-verified')
    p.add_argument('--verify', action='store_true', help="the agent's --verify variant")
    p.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    p.add_argument('--start-method', choices=['fork', 'spawn', 'forkserver'],
                   help='how the workers start (default: distributed.START_METHOD, what rad eval --workers uses)')
    p.add_argument('--serial-threads', type=int, help="torch threads of the serial run (default: torch's own)")
    p.add_argument('--cold', action='store_true', help="first, a fresh process's cold start step by step")
    p.add_argument('--cold-child', action='store_true', help=argparse.SUPPRESS)
    p.add_argument('--rounds', type=int, default=1, help='serial and then each worker count, this many times')
    p.add_argument('--results', type=Path, default=RESULTS, help='folder of distributed.md and its rows')
    p.add_argument('--from-rows', type=Path,
                   help="rebuild the page from this rows file, running nothing (the page's command, commit, date stay)")
    p.add_argument('--rows', metavar='FILE', help='also append one JSON line per run to FILE')
    p.add_argument('--wait-quiet', type=float, default=0, metavar='S',
                   help='before each run, wait up to S seconds until other processes use < 0.1 core')
    p.add_argument('--train', action='store_true', help='benchmark training (--actors) instead of evaluation')
    p.add_argument('--train-steps', type=int, default=400, help='with --train: environment steps per run')
    p.add_argument('--actors', type=int, nargs='+', default=[1, 2], help='with --train: actor counts')
    p.add_argument('--dataset', help='with --train: training scenes (default: 24 g=3 scenes built now)')
    args = p.parse_args()
    if args.train:
        return bench_train(args)
    if args.from_rows:
        return write(read_rows(args.from_rows), args.results, page_meta(args.results / 'distributed.md'))
    if args.cold_child:
        return cold_child(args)
    if args.cold:
        subprocess.run([sys.executable, __file__, '--cold-child', '--agent', args.agent, '--grid', str(args.grid),
                        '--seed', str(args.seed)] + ['--verify'] * args.verify, check=True)

    from rad_core.domain.scene_sources import generated_scenes
    from rad_core.experiment.distributed import (
        START_METHOD,
        AgentArgs,
        dask_client,
        evaluate_distributed,
        scene_cost,
        warm_up,
    )
    from rad_core.experiment.evaluation import evaluate, uses_robot
    args.start_method = args.start_method or START_METHOD
    agent_args = AgentArgs(args.agent, verify=args.verify)
    agent = agent_args.build()
    robot = uses_robot(agent, True)
    scenes = list(generated_scenes(args.grid, 2, args.scenes, args.seed))
    import torch
    if args.serial_threads:
        torch.set_num_threads(args.serial_threads)
    print(f'{agent.name}, {"robot (teleport)" if robot else "no robot"}, {args.scenes} g={args.grid} two-sided '
          f'scenes (seeds {args.seed}..{args.seed + args.scenes - 1}); serial: torch on {torch.get_num_threads()} '
          f'thread(s); workers: {args.start_method}ed, torch on 1 thread', flush=True)
    meta = dict(date=datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
                command=command_line(), agent=agent.name, robot=robot, scenes=args.scenes, grid=args.grid,
                seed=args.seed, cores=os.cpu_count())

    durations, runs = [], []
    last = [0.0]

    def lap(_row):
        now = time.perf_counter()
        durations.append(now - last[0])
        last[0] = now

    def record(doc):
        runs.append(doc)
        _append(args.rows, doc)

    for _ in range(args.rounds):
        durations.clear()
        waited = wait_until_quiet(args.wait_quiet) if args.wait_quiet else 0.0
        load0 = os.getloadavg()[0]
        with Others() as others:
            t0 = last[0] = time.perf_counter()
            serial = evaluate(agent, scenes, robot, args.seed, progress=lap)
            serial_s = time.perf_counter() - t0
        print(f'{"run":<10} {"start-up s":>10} {"(warm s)":>8} {"run s":>8} {"close s":>7} {"total s":>8} '
              f'{"scenes/s":>9} {"speed-up":>8} {"with start-up":>13} {"load":>9} {"others":>6}  rows')
        print(f'{"serial":<10} {"-":>10} {"-":>8} {serial_s:8.2f} {"-":>7} {serial_s:8.2f} '
              f'{args.scenes / serial_s:9.3f} {1.0:8.2f} {1.0:13.2f} {load0:4.2f}>{others.load:4.2f} '
              f'{others.cores:6.2f}  -', flush=True)
        record({**meta, 'run': 'serial', 'torch_threads': torch.get_num_threads(), 'total_s': serial_s,
                'load_before': load0, 'load_after': others.load, 'others_cores': others.cores,
                'cpu_s': others.own_s, 'waited_s': waited, 'scene_s': [round(d, 3) for d in durations]})

        for n in args.workers:
            waited = wait_until_quiet(args.wait_quiet) if args.wait_quiet else 0.0
            load0 = os.getloadavg()[0]
            with Others() as others:
                t0 = time.perf_counter()
                with dask_client(workers=n, start_method=args.start_method) as client:
                    cluster_s = time.perf_counter() - t0
                    warm_up(client, agent_args, robot)
                    startup_s = time.perf_counter() - t0
                    t1 = time.perf_counter()
                    result = evaluate_distributed(agent_args, scenes, robot, args.seed, client=client)
                    run_s = time.perf_counter() - t1
                    worker_cpu = sorted(client.run(time.process_time).values())   # each since its fork
                    t2 = time.perf_counter()
                close_s = time.perf_counter() - t2
                total_s = time.perf_counter() - t0
            differ = different_rows(serial, result)
            same = 'identical' if not differ else f'{len(differ)} differ: {", ".join(differ)}'
            print(f'{f"{n} worker" + "s" * (n > 1):<10} {startup_s:10.2f} {startup_s - cluster_s:8.2f} {run_s:8.2f} '
                  f'{close_s:7.2f} {total_s:8.2f} {args.scenes / total_s:9.3f} {serial_s / run_s:8.2f} '
                  f'{serial_s / total_s:13.2f} {load0:4.2f}>{others.load:4.2f} {others.cores:6.2f}  {same}; '
                  f'CPU s per worker {" ".join(f"{c:.1f}" for c in worker_cpu)}', flush=True)
            record({**meta, 'run': f'{n} workers', 'start_method': args.start_method, 'cluster_s': cluster_s,
                    'startup_s': startup_s, 'run_s': run_s, 'close_s': close_s, 'total_s': total_s,
                    'speedup': serial_s / run_s, 'speedup_with_startup': serial_s / total_s,
                    'load_before': load0, 'load_after': others.load, 'others_cores': others.cores,
                    'cpu_s': others.own_s, 'worker_cpu_s': worker_cpu, 'waited_s': waited,
                    'rows_differ': differ})
    if 2 in args.workers:
        costs = [scene_cost(s) for _, s in scenes]
        print(f'2 workers, from the serial scene times ({sum(durations):.1f} s of scenes): ideal makespan '
              f'{max(sum(durations) / 2, max(durations)):.1f} s; scheduled in scene order '
              f'{makespan(durations, range(len(scenes))):.1f} s, by scene_cost '
              f'{makespan(durations, sorted(range(len(scenes)), key=lambda i: -costs[i])):.1f} s, '
              f'by the true times {makespan(durations, sorted(range(len(scenes)), key=lambda i: -durations[i])):.1f} s')
    write(runs, args.results)
    return 0


def table(runs: list[dict]) -> tuple[list[str], list[list]]:
    """The page's headers and rows: one row per run on workers, with the serial run of its round
    (the serial run before it)."""
    labels = sorted({r['run'] for r in runs if r['run'] != 'serial'})
    one = labels[0] if len(labels) == 1 else 'workers'
    threads = next((r['torch_threads'] for r in runs if r['run'] == 'serial'), '?')
    headers = ['run', f'serial s (torch {threads} threads)', f'{one} s, start-up included', 'speed-up',
               'CPU s serial', 'CPU s workers (each)']
    out, serial, n = [], None, 0
    for r in runs:
        if r['run'] == 'serial':
            serial, n = r, n + 1
            continue
        out.append([n if len(labels) == 1 else f'{n} ({r["run"]})', f'{serial["total_s"]:.2f}', f'{r["total_s"]:.2f}',
                    f'{r["speedup_with_startup"]:.2f}x', f'{serial["cpu_s"]:.1f}',
                    ', '.join(f'{c:.1f}' for c in r['worker_cpu_s'])])
    return headers, out


def write(runs: list[dict], results: Path, meta: dict | None = None) -> int:
    """<results>/distributed.md and distributed.rows.jsonl from the runs' rows."""
    workers = [r for r in runs if r['run'] != 'serial']
    if not workers:
        print('no run on workers: no page written')
        return 0
    first = runs[0]
    counts = ' and '.join(sorted({r['run'].split()[0] for r in workers}, key=int))
    identical = sum(not r['rows_differ'] for r in workers)
    startup = [r['startup_s'] for r in workers]
    rounds = sum(r['run'] == 'serial' for r in runs)
    note = (f"{rounds} round{'s' * (rounds != 1)} of `{first['agent']}` "
            f"{'with the robot (teleporting execution)' if first['robot'] else 'without the robot'} on "
            f"{first['scenes']} g = {first['grid']} two-sided scenes (seeds from {first['seed']}), on a "
            f"{first['cores']}-core machine where other processes kept at most "
            f"{max(r['others_cores'] for r in runs):.2f} cores busy; the workers' rows are identical to the serial "
            f"run's in {identical} of {len(workers)}. Start-up (the cluster and every worker's warm-up) is "
            f"{min(startup):.2f}-{max(startup):.2f} s of the time. `bash benchmarks/bench_process_pair.sh` times two "
            'plain processes side by side for comparison.')
    headers, rows = table(runs)
    page = write_page('distributed', f'rad eval --workers: {first["scenes"]} scenes on {counts} local workers',
                      headers, rows, note, runs, results=results, **(meta or {}))
    print(f'wrote {page}')
    return 0


def machine_busy_s() -> float:
    """CPU seconds all cores have spent busy since boot (/proc/stat)."""
    with open('/proc/stat') as f:
        ticks = [int(v) for v in f.readline().split()[1:9]]
    return (sum(ticks) - ticks[3] - ticks[4]) / os.sysconf('SC_CLK_TCK')


def own_cpu_s() -> float:
    """CPU seconds of this process and of its children reaped so far (the workers, once closed)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


class Others:
    """How busy everything else kept the machine during a run: the cores' busy time less this
    process's own and its workers' (the machine is shared)."""

    def __enter__(self):
        self.t, self.busy, self.own = time.perf_counter(), machine_busy_s(), own_cpu_s()
        return self

    def __exit__(self, *exc):
        wall = time.perf_counter() - self.t
        self.own_s = own_cpu_s() - self.own   # this run's CPU seconds, its workers' included
        self.cores = max(0.0, (machine_busy_s() - self.busy) - self.own_s) / max(wall, 1e-9)
        self.load = os.getloadavg()[0]


def wait_until_quiet(max_s: float, others_max: float = 0.1) -> float:
    """Wait (at most max_s) until the other processes use less than others_max of a core over
    3 s; return the seconds waited."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < max_s:
        with Others() as o:
            time.sleep(3)
        if o.cores < others_max:
            break
    return time.perf_counter() - t0


def makespan(durations, order, workers: int = 2) -> float:
    """When the last of `workers` finishes, each taking the next scene in `order` when free."""
    free = [0.0] * workers
    for i in order:
        k = free.index(min(free))
        free[k] += durations[i]
    return max(free)


def _strip(value):
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if k not in WALL_CLOCK}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def different_rows(serial: dict, result: dict) -> list[str]:
    """Names of the scenes whose rows differ (wall-clock fields left out); ['metrics'] if only those do."""
    names = [a['name'] for a, b in zip(serial['scenes'], result['scenes']) if _strip(a) != _strip(b)]
    if len(serial['scenes']) != len(result['scenes']):
        names.append('count')
    if not names and _strip(serial) != _strip(result):
        names.append('metrics')
    return names


def _append(path, doc) -> None:
    if path:
        with open(path, 'a') as f:
            f.write(json.dumps(doc) + '\n')


def cold_child(args) -> int:
    """A fresh process's cold start, step by step (what a spawned worker pays before its first row)."""
    t = [time.perf_counter()]
    t_start = t[0]

    def step(what: str) -> None:
        now = time.perf_counter()
        print(f'  {what:<44} {now - t[0]:6.2f} s', flush=True)
        t[0] = now
    print(f'cold start of a fresh process (load {os.getloadavg()[0]:.2f}):')
    import numpy  # noqa: F401
    step('import numpy')
    import torch  # noqa: F401
    step('import torch')
    import ortools.sat.python.cp_model  # noqa: F401
    step('import ortools (CP-SAT)')
    import pybullet  # noqa: F401
    step('import pybullet')
    import distributed  # noqa: F401
    step('import distributed')
    from rad_core.domain.scene_sources import generated_scenes
    from rad_core.experiment.distributed import AgentArgs, scene_cost, warm
    from rad_core.experiment.evaluation import robot_planner, scene_episode, uses_robot  # noqa: F401
    step('import rad_core (evaluation, distributed)')
    agent_args = AgentArgs(args.agent, verify=args.verify)
    agent = agent_args.build()
    step('the agent and its network')
    robot = uses_robot(agent, True)
    warm(agent_args, robot)
    step('the planner (GAMP world, planning twin)' if robot else 'the stability check')
    from rad_core.experiment.distributed import _agent_and_policy, _planner, _stability
    planner = _planner(agent_args, None, None) if robot else None
    stability = None if robot else _stability()
    scenes = list(generated_scenes(args.grid, 2, 3, args.seed))
    for i, (name, scene) in enumerate(scenes):
        scene_episode(agent, scene, robot, args.seed + i, policy=_agent_and_policy(agent_args)[1], planner=planner,
                      stability=stability)
        step(f'scene {name} ({len(scene.blocks)} blocks, cost {scene_cost(scene)})')
    print(f'  {"total":<44} {time.perf_counter() - t_start:6.2f} s', flush=True)
    return 0


def bench_train(args) -> int:
    import tempfile
    from pathlib import Path

    from rad_core.experiment.distributed import dask_client
    from rad_core.training.actors import ActorConfig, train_with_actors
    from rad_core.training.dataset import build
    from rad_core.training.dqn import TrainConfig, train

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

"""/plan_assembly end to end over DDS on the live node graph: latency and predicted coverage.

    python benchmarks/bench_plan_assembly.py [--scenes 20] [--grid 5] [--seed 9000] [--agent default]
                                             [--improve-time-s 2.0] [--torch-threads 1] [--time-limits 0,2]

Starts the allocation, gamp, sequencer and assembly nodes (real processes, loopback DDS, the
agent given to both the sequencer and the assembly node), calls /plan_assembly on generated
two-sided scenes the project never trained or tuned on (seeds from --seed on), and prints and
writes (docs/results/plan_assembly.md and .rows.jsonl, `common.write_page`) the end-to-end time (median, p95, max),
the time to the anytime planner's first complete plan, the predicted coverage and how often a
later plan (order repair's, a search's) replaced the first. Plans start at home; no robot runs.
Each scene is asked once per request time limit in --time-limits (0: the node's default,
the first complete plan, improved until `anytime_deadline_s`, 2.25 s); the answer should come within
the limit (or that deadline) plus 10 %.
"""

from __future__ import annotations

import argparse
import subprocess
import time

import numpy as np
import rclpy
from common import RESULTS, write_page
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_planner.assembly_node import ANYTIME_DEADLINE_S
from rad_planner.graph import executable

HOME9 = [0.0, -0.215, 0.0, -2.57, 0.0, 2.356, 2.356, 0.04, 0.04]


def main():
    from rad_msgs.srv import PlanAssembly, Sequence
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=20)
    p.add_argument('--grid', type=int, default=5)
    p.add_argument('--seed', type=int, default=9000, help='first scene seed (unseen: training draws its own)')
    p.add_argument('--agent', default='default')
    p.add_argument('--improve-time-s', type=float, default=2.0, help="the assembly node's improve_time_s")
    p.add_argument('--torch-threads', type=int, default=1, help="the sequencer node's torch_threads")
    p.add_argument('--time-limits', default='0,2',
                   help="the requests' time_limit_s, comma-separated, each over every scene (0: the node default)")
    p.add_argument('--results', default=str(RESULTS))
    args = p.parse_args()
    params = {'sequencer_node': {'agent': args.agent, 'torch_threads': args.torch_threads},
              'assembly_node': {'agent': args.agent, 'improve_time_s': args.improve_time_s}}
    procs = []
    for pkg, exe in (('rad_planner', 'allocation_node'), ('rad_gamp', 'gamp_node'),
                     ('rad_planner', 'sequencer_node'), ('rad_planner', 'assembly_node')):
        ros_args = [a for k, v in params.get(exe, {}).items() for a in ('-p', f'{k}:={v}')]
        procs.append(subprocess.Popen([str(executable(pkg, exe)), *(['--ros-args', *ros_args] if ros_args else [])],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    rclpy.init()
    node = rclpy.create_node('bench_plan_assembly')
    rows = []
    try:
        client = node.create_client(PlanAssembly, 'plan_assembly')
        assert client.wait_for_service(timeout_sec=60.0), 'the assembly node did not come up'
        assert node.create_client(Sequence, 'sequence').wait_for_service(timeout_sec=60.0), 'no sequencer node'
        config = GeneratorConfig(grid=args.grid, sides=2)
        for limit, k in ((float(x), k) for x in args.time_limits.split(',') for k in range(args.scenes)):
            seed = args.seed + k
            scene = generate_scene(config, seed)
            t0 = time.perf_counter()
            future = client.call_async(PlanAssembly.Request(scene_json=scene.dumps(), start_positions=HOME9,
                                                            time_limit_s=limit))
            rclpy.spin_until_future_complete(node, future, timeout_sec=300.0)
            seconds = time.perf_counter() - t0
            r = future.result()
            assert r is not None, f'no answer for seed {seed}'
            timing = {t.stage: t.seconds for t in r.timings}
            first = r.anytime_times_s[0] if r.anytime_times_s else timing.get('total', seconds)
            rows.append({'seed': seed, 'time_limit_s': limit, 'seconds': seconds, 'first_plan_s': first,
                         'coverage': r.predicted_coverage, 'success': r.success, 'steps': len(r.steps),
                         'blocks': len(scene.blocks), 'plans': list(r.anytime_plans),
                         'anytime_coverages': list(r.anytime_coverages),
                         'stages': timing})
            print(f'limit {limit:g} s, seed {seed}: {seconds:6.2f} s, coverage {r.predicted_coverage:.3f}, '
                  f'{len(r.steps)} steps, plans {list(r.anytime_plans)}', flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for proc in procs:
            proc.terminate()
            proc.wait()
    write(rows, args)


def stage_lines(rows) -> list[str]:
    """Where a request's time goes, summed over the scenes: the planner's stages (GAMP's motion as the
    assembly node waits for it, the sequencer as it reports its own time and as the assembly node waits
    for the answer, GAMP as the gamp node reports its own time, the allocation, re-allocation, whose GAMP
    calls count in motion too), what the assembly node spends outside the allocation, motion and the
    sequencer's calls (its stability checks, re-allocation's solves, building states, the response)
    and what the client waits beyond the node's total. With anytime planning the stages are those of
    every plan made for a request."""
    total = sum(r['seconds'] for r in rows)
    sums = {}
    for r in rows:
        for stage, seconds in r['stages'].items():
            sums[stage] = sums.get(stage, 0.0) + seconds
    node = sums.get('total', 0.0)
    waited = sum(sums.get(s, 0.0) for s in ('allocation', 'motion', 'registration'))
    waited += sums.get('sequencer_call', sums.get('sequencing', 0.0))
    parts = [(s, sums[s]) for s in ('allocation', 'sequencer_call', 'sequencing', 'motion', 'gamp', 'reallocation')
             if s in sums]
    parts += [('in the assembly node besides', node - waited), ('client beyond the node', total - node)]
    return [f'| time, all {len(rows)} requests (s) | {total:.2f} | | |',
            *(f'| {name} | {seconds:.2f} | {100 * seconds / total:.0f} % | |' for name, seconds in parts)]


def table(rows) -> list[list]:
    """One line per request time limit: end-to-end seconds (median, p95, max), the share answered within
    the limit plus 10 %, the first plan's median, the predicted coverage."""
    out = []
    for limit in dict.fromkeys(r['time_limit_s'] for r in rows):
        mine = [r for r in rows if r['time_limit_s'] == limit]
        t = np.array([r['seconds'] for r in mine])
        first = np.array([r['first_plan_s'] for r in mine])
        cov = np.array([r['coverage'] for r in mine])
        deadline = limit or ANYTIME_DEADLINE_S
        within = f'{int((t <= 1.1 * deadline).sum())} of {len(mine)}'
        out.append([f'{limit:g}' if limit else f'0 (anytime, {ANYTIME_DEADLINE_S:g})', f'{np.median(t):.2f}',
                    f'{np.percentile(t, 95):.2f}', f'{t.max():.2f}', within, f'{np.median(first):.2f}',
                    f'{cov.mean():.3f}', f'{int((cov >= 1 - 1e-4).sum())} of {len(mine)}'])
    return out


def write(rows, args) -> None:
    for line in stage_lines(rows):
        print(line)
    note = (f'The allocation, gamp, sequencer and assembly nodes as real processes on loopback DDS, agent '
            f'`{args.agent}`, improve_time_s {args.improve_time_s:g}; {args.scenes} generated two-sided '
            f'g = {args.grid} scenes, seeds {args.seed}..{args.seed + args.scenes - 1} (never used in training); '
            'the client\'s wall clock. Where each request\'s time went is in its row (`stages`).')
    headers = ['time_limit_s', 'median (s)', 'p95 (s)', 'max (s)', 'within limit + 10 %', 'first plan, median (s)',
               'mean predicted coverage', 'complete']
    page = write_page('plan_assembly', f'/plan_assembly over DDS, g = {args.grid}', headers, table(rows), note, rows,
                      results=args.results)
    print(f'wrote {page}')


if __name__ == '__main__':
    main()

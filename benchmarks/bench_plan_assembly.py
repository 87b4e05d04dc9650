"""/plan_assembly latency per stage and end to end, over DDS and in-process.

    python benchmarks/bench_plan_assembly.py [--scenes 20] [--grids 3 4 5 6] [--policy milp-dqn-mcts]

Starts the allocation, gamp, sequencer and assembly nodes (real processes, loopback
DDS), calls /plan_assembly on generated two-sided scenes, then computes the same
plans in-process (the same core functions and sequencer, no DDS) and prints median /
p95 per stage and the DDS overhead as a ratio of end-to-end medians.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import rclpy

from rad_core.allocation import solve
from rad_core.gamp.action import MotionPlanner
from rad_core.generator import GeneratorConfig, generate_scene
from rad_core.sequencing.plan import local_motion_planner, plan_assembly
from rad_core.sequencing.sequencer import POLICIES, Sequencer, SequencerConfig
from rad_planner.graph import executable

HOME9 = [0.0, -0.215, 0.0, -2.57, 0.0, 2.356, 2.356, 0.04, 0.04]   # no robot runs: plans start at home

NODES = (('rad_planner', 'allocation_node'), ('rad_gamp', 'gamp_node'), ('rad_planner', 'sequencer_node'),
         ('rad_planner', 'assembly_node'))


def stats(values) -> str:
    return f'{np.median(values) * 1e3:7.1f} / {np.percentile(values, 95) * 1e3:7.1f}'


def main():
    import subprocess
    from rad_msgs.srv import PlanAssembly, Sequence
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=20)
    p.add_argument('--grids', type=int, nargs='+', default=[3, 4, 5, 6])
    p.add_argument('--seed', type=int, default=100)
    p.add_argument('--policy', choices=POLICIES, default='milp-dqn-mcts')
    args = p.parse_args()
    extra = {'sequencer_node': ['--ros-args', '-p', f'policy:={args.policy}']}
    procs = [subprocess.Popen([str(executable(pkg, exe)), *extra.get(exe, [])], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) for pkg, exe in NODES]
    rclpy.init()
    node = rclpy.create_node('bench_plan_assembly')
    client = node.create_client(PlanAssembly, 'plan_assembly')
    assert client.wait_for_service(timeout_sec=30.0), 'the assembly node did not come up'
    assert node.create_client(Sequence, 'sequence').wait_for_service(timeout_sec=60.0), 'no sequencer node'
    local = local_motion_planner(MotionPlanner())
    sequencer = Sequencer(SequencerConfig(policy=args.policy))
    print(f'policy {args.policy}')
    print(f'{"g":>2} | {"end to end ms (median / p95)":>30} | {"allocation":>17} {"motion":>17} '
          f'| {"in-process":>17} | DDS overhead | steps')
    try:
        for g in args.grids:
            scenes = [generate_scene(GeneratorConfig(grid=g), args.seed + s) for s in range(args.scenes)]
            dds, stages, inproc, steps = [], {'allocation': [], 'motion': []}, [], []
            for scene in scenes:
                t0 = time.perf_counter()
                future = client.call_async(PlanAssembly.Request(scene_json=scene.dumps(), start_positions=HOME9))
                rclpy.spin_until_future_complete(node, future, timeout_sec=120.0)
                dds.append(time.perf_counter() - t0)
                r = future.result()
                timing = {t.stage: t.seconds for t in r.timings}
                for k in stages:
                    stages[k].append(timing.get(k, 0.0))
                steps.append(len(r.steps))
                t0 = time.perf_counter()
                plan_assembly(scene, solve, local, sequencer.rank, seed=0)
                inproc.append(time.perf_counter() - t0)
            ratio = np.median(dds) / np.median(inproc)
            print(f'{g:>2} | {stats(dds):>30} | {stats(stages["allocation"]):>17} {stats(stages["motion"]):>17} '
                  f'| {stats(inproc):>17} | {ratio:11.2f}x | {np.mean(steps):.1f}')
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for proc in procs:
            proc.terminate()
            proc.wait()


if __name__ == '__main__':
    main()

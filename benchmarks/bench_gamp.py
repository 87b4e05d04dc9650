"""IK accuracy and GAMP cost on generated scenes.

IK: random top-down grasp-target poses in the workspace in front of the robot
(x 0.3..0.7 m, y -0.4..0.4 m, z 0.02..0.35 m, any closing yaw).
GAMP: for each generated scene (grid 4 and 5, two-sided), the allocation is
solved and its poses are built bottom-up, each by the first unplaced block of
the pose's type: GAMP plans the action from the current world; on success the
block is teleported to its pose (as if executed), else the pose is skipped.
Outcomes are counted as success / f_g / f_p.

    PYTHONPATH=ros_ws/src/rad_core python benchmarks/bench_gamp.py [--targets 300] [--scenes 10]
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter

import numpy as np
from rad_core.allocation import AllocationParams, solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.gamp import GampConfig, allocated_pose, plan_action, solve_top_down
from rad_core.sim.world import World


def bench_ik(world: World, n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n):
        pos = np.array([rng.uniform(0.3, 0.7), rng.uniform(-0.4, 0.4), rng.uniform(0.02, 0.35)])
        r = solve_top_down(world, pos, rng.uniform(-math.pi, math.pi), rng=rng)
        rows.append((r.ok, r.position_error, r.orientation_error_deg, r.calls, r.seconds))
    a = np.array(rows)
    ok = a[:, 0] == 1
    pe, oe = a[ok, 1] * 1000, a[ok, 2]
    print(f'IK: {n} random top-down targets, success {ok.mean() * 100:.1f} %')
    print(f'  position error mm: median {np.median(pe):.4f}  p95 {np.percentile(pe, 95):.4f}  '
          f'max {pe.max():.3f}')
    print(f'  orientation error deg: median {np.median(oe):.4f}  p95 {np.percentile(oe, 95):.4f}  '
          f'max {oe.max():.3f}')
    print(f'  per solve: median {np.median(a[:, 4]) * 1000:.2f} ms, p95 {np.percentile(a[:, 4], 95) * 1000:.2f} ms; '
          f'pybullet calls median {np.median(a[:, 3]):.0f}, p95 {np.percentile(a[:, 3], 95):.0f}; '
          f'per call {a[:, 4].sum() / a[:, 3].sum() * 1000:.2f} ms')


def bench_gamp(grid: int, scenes: int, config: GampConfig) -> list[dict]:
    rows = []
    world = World()
    for seed in range(scenes):
        scene = generate_scene(GeneratorConfig(grid=grid), seed)
        alloc = solve(scene, AllocationParams(time_limit_s=5.0))
        world.load_scene(scene)
        poses = sorted(alloc.placements, key=lambda p: (min(c[2] for c in p.cells), p.target,
                                                        min(c[0] for c in p.cells)))
        used = set()
        for placement in poses:
            block = next((b for b in scene.blocks if b.type == placement.type and b.id not in used), None)
            if block is None:
                continue
            position, yaw = allocated_pose(scene, placement)
            r = plan_action(world, block.id, position, yaw, config=config)
            rows.append({'outcome': 'success' if r.success else r.failure, **r.timings,
                         'ik_calls': r.ik_calls, 'reason': r.reason})
            if r.success:
                used.add(block.id)
                world.set_block_pose(block.id, position, [0, 0, math.sin(math.radians(yaw) / 2),
                                                          math.cos(math.radians(yaw) / 2)])
    world.close()
    return rows


def report(grid: int, rows: list[dict]) -> None:
    counts = Counter(r['outcome'] for r in rows)
    n = len(rows)
    print(f'GAMP grid {grid}: {n} actions: ' + ', '.join(f'{k} {v} ({v / n * 100:.0f} %)'
                                                        for k, v in sorted(counts.items())))
    for label, sel in (('all', rows), ('success', [r for r in rows if r['outcome'] == 'success']),
                       ('failed', [r for r in rows if r['outcome'] != 'success'])):
        if not sel:
            continue
        tot = np.array([r['total_s'] for r in sel]) * 1000
        ik = np.array([r['ik_s'] for r in sel]) * 1000
        col = np.array([r['collision_s'] for r in sel]) * 1000
        print(f'  {label:8s} total ms median {np.median(tot):6.1f} p95 {np.percentile(tot, 95):6.1f} | '
              f'IK median {np.median(ik):5.1f} | collision median {np.median(col):5.1f} | '
              f'other median {np.median(tot - ik - col):5.1f}')
    reasons = Counter(r['reason'].split(':')[0] + ': ' + _first_cause(r['reason']) for r in rows if r['reason'])
    for reason, k in reasons.most_common(6):
        print(f'    {k:3d} x {reason}')


def _first_cause(reason: str) -> str:
    """'grasp: all 3 grasps blocked: unit 2 yaw 0: at the grasp: left finger hits block b5; ...'
    -> 'at the grasp: left finger hits ...' without the block id."""
    parts = reason.split('; ')[0].split(': ')
    text = ': '.join(parts[3:]) if len(parts) > 3 else parts[-1]
    return ' '.join(w for w in text.split() if not (w.startswith('b') and w[1:].isdigit()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--targets', type=int, default=300)
    ap.add_argument('--scenes', type=int, default=10)
    ap.add_argument('--seed', type=int, default=0)
    args = ap.parse_args()
    with World() as world:
        bench_ik(world, args.targets, args.seed)
    for grid in (4, 5):
        t = time.perf_counter()
        rows = bench_gamp(grid, args.scenes, GampConfig())
        report(grid, rows)
        print(f'  ({time.perf_counter() - t:.1f} s wall incl. scene generation and allocation)')


if __name__ == '__main__':
    main()

"""Real-time factor of the twin executing a trajectory with N blocks in the world.

The trajectory (6 s) swings the arm over the table and back, closing and opening
the fingers on the way, as a pick and place would; the blocks lie in rows on the
table (random library types and yaws) and stay at rest. Two ways of running it
are timed:

- execute: one call, as tests, benchmarks and the MDP use it;
- node-like: advance(1/50 s) slices, reading joint states and every block's
  motion-capture pose after each slice, as the rad_sim node does at 50 Hz.

    PYTHONPATH=ros_ws/src/rad_core python benchmarks/bench_twin.py [--blocks 0 10 20 40] [--repeats 3]

Prints, per N, the real-time factor (simulated s per wall s; 1 = real time)
and the cost of one physics step with its control and grasp checks.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rad_core.cell import panda
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.scene import Block, Scene, TargetRegion
from rad_core.sim.twin import Twin
from rad_core.sim.world import World

UNIT = 0.05


def scene_with(n: int, seed: int) -> Scene:
    """n random blocks in rows on the robot's right (y < -0.12), one small target region."""
    rng = np.random.default_rng(seed)
    blocks, x, y = [], 0.3, -0.15
    for i in range(n):
        name = sorted(DEFAULT_LIBRARY)[rng.integers(len(DEFAULT_LIBRARY))]
        yaw = int(rng.choice([0, 90, 180, 270]))
        offs = DEFAULT_LIBRARY[name].rotated(yaw)
        lo, hi = offs.min(axis=0), offs.max(axis=0)
        if x + UNIT * (hi[0] - lo[0] + 1) > 0.75:
            x, y = 0.3, y - 0.2
        pos = (x - lo[0] * UNIT, y - lo[1] * UNIT, UNIT / 2 - lo[2] * UNIT)
        blocks.append(Block(f'b{i}', name, tuple(round(float(v), 6) for v in pos), yaw))
        x += UNIT * (hi[0] - lo[0] + 1) + 0.04
    used = {b.type for b in blocks} or {'cube'}
    target = TargetRegion('t', (0.45, 0.1, UNIT / 2), (3, 1, 3), ((0, 0, 0),))
    return Scene.from_dict(Scene(UNIT, {t: DEFAULT_LIBRARY[t] for t in used}, tuple(blocks), (target,)).to_dict())


def sweep() -> dict:
    """6 s: out over the blocks, fingers close and open, back home; cubic with velocities."""
    home = panda.HOME.copy()
    out = home.copy()
    out[[0, 1, 3]] += [-0.6, 0.5, 0.6]
    closed = out.copy()
    closed[7:] = 0.0
    points = [(1.5, out), (2.5, closed), (3.5, out), (4.5, home + [0.4, 0, 0, 0, 0, 0, 0, 0, 0]), (6.0, home)]
    return {'joint_names': list(panda.JOINT_NAMES),
            'points': [{'positions': list(q), 'velocities': [0.0] * 9, 'time_from_start': t} for t, q in points]}


def run(n: int, repeats: int) -> dict:
    scene = scene_with(n, seed=n)
    rtf_exec, rtf_node, step_ms = [], [], []
    with World() as world:
        twin = Twin(world)
        for _ in range(repeats):
            twin.load_scene(scene)
            report = twin.execute(sweep())
            rtf_exec.append(report.compute_factor)
            step_ms.append(report.compute_time / report.steps * 1e3)

            twin.load_scene(scene)
            twin.start(sweep())
            t0, sim, done = time.perf_counter(), 0.0, None
            while done is None:
                done = twin.advance(1 / 50)
                sim += 1 / 50
                twin.joint_state()
                twin.bodies()
            rtf_node.append(sim / (time.perf_counter() - t0))
        moved = max((np.linalg.norm(twin.world.block_pose(b.id)[0] - b.position) for b in scene.blocks), default=0.0)
    return {'blocks': n, 'rtf_execute': float(np.median(rtf_exec)), 'rtf_node': float(np.median(rtf_node)),
            'step_ms': float(np.median(step_ms)), 'final_error': report.final_error,
            'max_tracking_error': report.max_tracking_error, 'block_drift_mm': moved * 1e3}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--blocks', type=int, nargs='+', default=[0, 10, 20, 40])
    ap.add_argument('--repeats', type=int, default=3)
    args = ap.parse_args()
    print(f'{"blocks":>6} {"RTF execute":>12} {"RTF node 50Hz":>14} {"ms/step":>8} '
          f'{"final err":>10} {"max track":>10} {"drift mm":>9}')
    for n in args.blocks:
        r = run(n, args.repeats)
        print(f'{r["blocks"]:>6} {r["rtf_execute"]:>12.1f} {r["rtf_node"]:>14.1f} {r["step_ms"]:>8.3f} '
              f'{r["final_error"]:>10.2e} {r["max_tracking_error"]:>10.2e} {r["block_drift_mm"]:>9.3f}')


if __name__ == '__main__':
    main()

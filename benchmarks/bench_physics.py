"""Time the PyBullet stability check on random small structures.

Structures grow the way an MDP episode does: a random library block at a random
pose in a 6 x 6 x 5 box, kept when physics says it stands, until the structure
has --max-blocks blocks or a number of tries fail. Only poses the MDP would ask
physics about are timed (on the grid, no overlap, at least one unit resting on
the table or a placed block).

    PYTHONPATH=ros_ws/src/rad_core python benchmarks/bench_physics.py [--episodes 60]

Prints median and p95 per check in ms, by verdict and by structure size, and
the cost of the setup a kept client avoids (resetSimulation per check).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.sim.physics import PhysicsConfig, PhysicsStability

UNIT = 0.05
BOX = np.array([6, 6, 5])
ORIGIN = np.array([0.4, -0.15, UNIT / 2])


def candidate(rng: np.random.Generator, occupied: set) -> np.ndarray | None:
    """Integer cells of a random block pose the MDP would hand to physics, or None."""
    btype = list(DEFAULT_LIBRARY.values())[rng.integers(len(DEFAULT_LIBRARY))]
    offsets = btype.rotated(int(rng.choice([0, 90, 180, 270])))
    cells = offsets + rng.integers(0, BOX)
    if (cells < 0).any() or (cells >= BOX).any():
        return None
    as_set = {tuple(c) for c in cells.tolist()}
    if as_set & occupied:
        return None
    if not any(z == 0 or (x, y, z - 1) in occupied for x, y, z in as_set):
        return None
    return cells


def run(episodes: int, max_blocks: int, seed: int, config: PhysicsConfig) -> list[tuple[int, bool, str, float]]:
    rng = np.random.default_rng(seed)
    rows = []
    with PhysicsStability(config) as check:
        check(UNIT, [], ORIGIN[None, :])                  # connect outside the timings
        for _ in range(episodes):
            placed, occupied, failures = [], set(), 0
            while len(placed) < max_blocks and failures < 8:
                cells = candidate(rng, occupied)
                if cells is None:
                    continue
                new = ORIGIN + UNIT * cells
                t0 = time.perf_counter()
                ok, reason = check(UNIT, placed, new)
                rows.append((len(placed) + 1, ok, reason, (time.perf_counter() - t0) * 1e3))
                if ok:
                    placed.append(new)
                    occupied |= {tuple(c) for c in cells.tolist()}
                else:
                    failures += 1
    return rows


def reset_baseline(repeats: int = 20) -> float:
    """Median ms of resetSimulation plus rebuilding a table and ten one-cube bodies."""
    import pybullet as p
    cid = p.connect(p.DIRECT)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        p.resetSimulation(physicsClientId=cid)
        box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[UNIT / 2] * 3, physicsClientId=cid)
        for k in range(10):
            p.createMultiBody(0.1, box, basePosition=[0, 0, UNIT * (k + 0.5)], physicsClientId=cid)
        times.append((time.perf_counter() - t0) * 1e3)
    p.disconnect(physicsClientId=cid)
    return float(np.median(times))


def summary(label: str, ms: list[float]) -> str:
    if not ms:
        return f'{label:28s} {0:5d} checks'
    return (f'{label:28s} {len(ms):5d} checks  median {np.median(ms):6.2f} ms  '
            f'p95 {np.percentile(ms, 95):6.2f} ms  max {max(ms):6.2f} ms')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--episodes', type=int, default=60)
    ap.add_argument('--max-blocks', type=int, default=10)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--solver-iterations', type=int, default=PhysicsConfig().solver_iterations)
    ap.add_argument('--explain-steps', type=int, default=PhysicsConfig().explain_steps)
    args = ap.parse_args()
    config = PhysicsConfig(solver_iterations=args.solver_iterations, explain_steps=args.explain_steps)

    t0 = time.perf_counter()
    rows = run(args.episodes, args.max_blocks, args.seed, config)
    wall = time.perf_counter() - t0
    ms = [r[3] for r in rows]
    print(f'{len(rows)} checks on {args.episodes} random structures of up to {args.max_blocks} blocks '
          f'(seed {args.seed}, {config.solver_iterations} solver iterations, explain_steps '
          f'{config.explain_steps}), {wall:.1f} s')
    print(summary('all', ms))
    print(summary('stands', [r[3] for r in rows if r[1]]))
    print(summary('falls', [r[3] for r in rows if not r[1]]))
    for lo, hi in ((1, 3), (4, 6), (7, 10), (11, 10 ** 6)):
        sel = [r[3] for r in rows if lo <= r[0] <= hi]
        if sel:
            print(summary(f'{lo}-{hi} blocks' if hi < 10 ** 6 else f'>{lo - 1} blocks', sel))
    print(f'stood: {sum(r[1] for r in rows)}, fell: {sum(not r[1] for r in rows)}')
    base = reset_baseline()
    print(f'for comparison, resetSimulation + table + ten cubes (the per-call setup a kept client '
          f'avoids): {base:.2f} ms, {base / np.median(ms):.2f}x the median check')


if __name__ == '__main__':
    main()

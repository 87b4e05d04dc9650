"""Steps per second of the no-robot assembly MDP, with and without physics.

    python benchmarks/bench_env.py [--grid 4] [--episodes 100]

Episodes follow a random policy over the allocation's actions (only those that
pass the geometric support rule, as the paper's HEUR does), so most steps are
successful placements that reach the stability check. Allocation time is not
counted, nor is the policy's own time (printed apart). 'support' is the geometric rule
alone; 'physics' asks PyBullet (with its
cache of identical structures cleared per episode, so every check is real).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import TERMINATE, AssemblyEnv, EnvConfig
from rad_core.sequencing import supported_actions


def run(mode: str, grid: int, episodes: int, seed: int) -> dict:
    steps, elapsed, policy_s, invalid = 0, 0.0, 0.0, 0
    stability = None
    for e in range(episodes):
        scene = generate_scene(GeneratorConfig(grid=grid), seed + e)
        alloc = solve(scene)
        env = AssemblyEnv(scene, EnvConfig(stability=mode), stability=stability)
        stability = env.stability  # one physics client for the whole run
        guide = AllocationGuide(scene, alloc.placements)
        rng = np.random.default_rng(e)
        while True:
            t0 = time.perf_counter()
            actions = supported_actions(env, guide.allowed_actions(env.state))
            action = actions[int(rng.integers(len(actions)))] if actions else TERMINATE
            t1 = time.perf_counter()
            result = env.step(action)
            elapsed += time.perf_counter() - t1
            policy_s += t1 - t0
            steps += 1
            invalid += result.outcome.is_invalid
            if result.done:
                break
    return {'mode': mode, 'steps': steps, 'seconds': elapsed, 'steps_per_s': steps / elapsed,
            'invalid': invalid, 'policy_ms_per_step': 1e3 * policy_s / steps}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--episodes', type=int, default=100)
    p.add_argument('--seed', type=int, default=0)
    args = p.parse_args()
    rows = [run(m, args.grid, args.episodes, args.seed) for m in ('none', 'support', 'physics')]
    for r in rows:
        print(f'{r["mode"]:>8}: {r["steps_per_s"]:9.1f} env steps/s  ({r["steps"]} steps in {r["seconds"]:.3f} s, '
              f'{r["invalid"]} invalid; the HEUR policy itself took {r["policy_ms_per_step"]:.2f} ms/step)')
    print(f'physics costs {rows[1]["steps_per_s"] / rows[2]["steps_per_s"]:.1f}x the support rule')


if __name__ == '__main__':
    main()

"""Steps per second of the MDP with the robot in the loop.

    python benchmarks/bench_robot_env.py [--grid 4] [--scenes 20]

Runs the paper's HEUR policy (random allocation action whose block would rest
fully supported; no feasibility pre-check) on generated scenes, once with the
whole arm motion simulated by the twin and once in 'teleport' mode (GAMP still
decides feasibility; only the settling is simulated). Prints steps/s of
`RobotAssemblyEnv.step`, the share of time in GAMP, and the outcome classes.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import TERMINATE
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig, outcome_class
from rad_core.sequencing import supported_actions


def run(execution: str, grid: int, scenes: int, seed: int) -> dict:
    steps, step_s, gamp_s, classes = 0, 0.0, 0.0, Counter()
    for s in range(scenes):
        scene = generate_scene(GeneratorConfig(grid=grid), seed + s)
        with RobotAssemblyEnv(scene, RobotEnvConfig(execution=execution)) as renv:
            env = renv.env
            guide = AllocationGuide(scene, solve(scene).placements)
            rng = np.random.default_rng(seed + s)
            while not env.state.done:
                acts = supported_actions(env, guide.allowed_actions(env.state))
                action = acts[int(rng.integers(len(acts)))] if acts else TERMINATE
                renv.last_plan = None
                t0 = time.perf_counter()
                result = renv.step(action)
                step_s += time.perf_counter() - t0
                if renv.last_plan is not None:
                    gamp_s += renv.last_plan.timings['total_s']
                steps += 1
                classes[outcome_class(result.outcome) if result.outcome.is_invalid else result.outcome.value] += 1
    return {'execution': execution, 'steps': steps, 'steps_per_s': steps / step_s,
            'gamp_share': gamp_s / step_s, 'classes': dict(classes)}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--grid', type=int, default=4)
    p.add_argument('--scenes', type=int, default=20)
    p.add_argument('--seed', type=int, default=0)
    args = p.parse_args()
    for execution in ('simulate', 'teleport'):
        r = run(execution, args.grid, args.scenes, args.seed)
        print(f'{execution:>8}: {r["steps_per_s"]:6.2f} steps/s over {r["steps"]} steps, '
              f'GAMP {r["gamp_share"]:.0%} of the time; outcomes {r["classes"]}')


if __name__ == '__main__':
    main()

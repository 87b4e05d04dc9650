"""Flush blocks against blocks with a clearance (the predecessor's robot geometry), with the robot.

The same generated scenes, once flush (clearance 0, rad's default) and once with
each --clearance (a fraction of the unit: 0.2 is 1 cm between neighbouring 5 cm
cells), evaluated by HEUR and verified HEUR with GAMP and the twin
(`rad_core.experiment.evaluation.evaluate`, robot=True). Prints one row per agent and
geometry: completion d, failures f (grasp f_g, placement f_p), coverage a-bar
and corrected coverage, and the wall time.

    PYTHONPATH=ros_ws/src/rad_core python benchmarks/bench_clearance.py [--grid 4] [--scenes 10]
"""

from __future__ import annotations

import argparse
import time

from rad_core.domain.scene_sources import generated_scenes
from rad_core.experiment.evaluation import evaluate

AGENTS = ('heur', 'heur-verified')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--grid', type=int, default=4)
    parser.add_argument('--sides', type=int, default=2)
    parser.add_argument('--scenes', type=int, default=10)
    parser.add_argument('--seed', type=int, default=0, help='first generator seed; the policy seed too')
    parser.add_argument('--clearance', type=float, nargs='+', default=[0.2])
    args = parser.parse_args()

    print(f'g={args.grid}, sides={args.sides}, {args.scenes} scenes from seed {args.seed}, robot=True')
    print(f'{"agent":14s} {"clearance":>9s} {"d":>5s} {"f":>5s} {"f_g":>5s} {"f_p":>5s} '
          f'{"a-bar":>6s} {"a-rel":>6s} {"s":>6s}')
    for agent in AGENTS:
        for clearance in [0.0, *args.clearance]:
            scenes = [(name, s.with_clearance(clearance) if clearance else s)
                      for name, s in generated_scenes(args.grid, args.sides, args.scenes, args.seed)]
            t0 = time.perf_counter()
            r = evaluate(agent, scenes, robot=True, seed=args.seed)
            wall = time.perf_counter() - t0
            print(f'{agent:14s} {clearance:9.3g} {r["d"]:5.2f} {r["f"]:5.2f} {r["f_g"]:5.2f} {r["f_p"]:5.2f} '
                  f'{r["coverage"]:6.3f} {r["coverage_rel"]:6.3f} {wall:6.1f}', flush=True)


if __name__ == '__main__':
    main()

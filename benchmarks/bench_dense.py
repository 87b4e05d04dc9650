"""Dense targets with the parallel hand and the vacuum gripper: solid boxes, two-deep walls, brick models.

    python benchmarks/bench_dense.py [--unit 0.03] [--clearances 0,0.1] [--effectors hand,suction]
                                     [--agent default] [--sets boxes,walls,bricks] [--execution simulate]
                                     [--results docs/results]

Each design of `rad_core.domain.dense_shapes` becomes a scene as a user's voxel file does
(`rad scene from-voxels`: the region in front of the robot, the blocks the supply chooses laid out on
the table), boxes and walls from rad's own block set, brick models from the two-wide plates (B22,
B24) with I2s and cubes, each flush (clearance 0) and with the scene's clearance set (0.1: 3 mm
between neighbours at a 3 cm unit), for each effector: Franka's hand (wide grasps on, as by
default) and the vacuum gripper in its place (the supply then chooses for the cup, too). The agent
plans each with the robot in the loop and the plan is built in a fresh twin. Writes
docs/results/dense.md (per effector, clearance and set: designs, coverage, the designs built whole,
those the supply's order model finds a whole order for and how many of them were built whole,
failures) and one row per design. Run it on a quiet machine: planning stages have time budgets.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from common import RESULTS, write_page
from rad_core.domain.blocks import BRICK_TYPES, DEFAULT_LIBRARY
from rad_core.domain.dense_shapes import designs
from rad_core.experiment.evaluation import evaluate, get_agent

SET_TYPES = {
    'boxes': dict(DEFAULT_LIBRARY),
    'walls': dict(DEFAULT_LIBRARY),
    'bricks': {**BRICK_TYPES, 'I2': DEFAULT_LIBRARY['I2'], 'cube': DEFAULT_LIBRARY['cube']},
}


def dense_scene(name: str, cells, unit: float, types, seed: int = 0, clearance: float = 0.0,
                effector: str = 'hand'):
    """(scene, supply report) of a design, as `rad scene from-voxels` makes it for this effector."""
    from rad_core.allocation.supply import SupplyParams, supply
    from rad_core.domain.voxels import Model, place_regions

    targets = place_regions([Model(name, '', cells)], unit)
    return supply(targets, unit, types, params=SupplyParams(time_limit_s=60.0, seed=seed, effector=effector),
                  clearance=clearance)


def run_set(set_name: str, named_cells: dict, unit: float, clearance: float, effector: str, agent,
            execution: str) -> tuple[list[dict], list[str]]:
    rows, scenes = [], []
    for name, cells in named_cells.items():
        scene, report = dense_scene(name, cells, unit, SET_TYPES[set_name], clearance=clearance, effector=effector)
        scenes.append((name, scene))
        hand = report.hand_covered if report.hand_covered is not None else report.covered
        rows.append({'effector': effector, 'set': set_name, 'clearance': clearance, 'name': name,
                     'cells': int(cells.sum()),
                     'blocks': len(scene.blocks), 'supply_covered': report.covered, 'supply_hand': hand})
    t0 = time.perf_counter()
    result = evaluate(agent, scenes, True, 0, execution=execution, effector=effector)
    seconds = time.perf_counter() - t0
    for row, got in zip(rows, result['scenes']):
        row.update(coverage=got['coverage'], outcome=got['outcome'], steps=got['steps'],
                   failed=got['outcome'].startswith('invalid'), reason=got['reason'] or got['stop_reason'])
    whole = [r for r in rows if r['coverage'] >= 1.0 - 1e-9]
    orderable = [r for r in rows if r['supply_hand'] == r['cells']]
    line = [effector, set_name, f'{clearance:g}', str(len(rows)), f"{result['coverage']:.3f}",
            f'{len(whole)}/{len(rows)}',
            f"{sum(r in whole for r in orderable)}/{len(orderable)}", f"{result['f']:g}", f'{seconds:.0f}']
    print(' | '.join(line), flush=True)
    return rows, line


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--unit', type=float, default=0.03, help='cell edge, m (default 0.03)')
    p.add_argument('--clearances', default='0,0.1', help='scene clearances, fractions of the unit')
    p.add_argument('--effectors', default='hand,suction', help='end effectors: hand, suction')
    p.add_argument('--agent', default='default')
    p.add_argument('--sets', default='boxes,walls,bricks')
    p.add_argument('--execution', choices=('teleport', 'simulate'), default='simulate')
    p.add_argument('--results', type=Path, default=RESULTS)
    args = p.parse_args()
    agent = get_agent(args.agent)
    every = designs()
    rows, table = [], []
    for effector in args.effectors.split(','):
        for clearance in (float(c) for c in args.clearances.split(',')):
            for set_name in args.sets.split(','):
                got, line = run_set(set_name, every[set_name], args.unit, clearance, effector, agent, args.execution)
                rows += got
                table.append(line)
    note = (f'`{args.agent}` (`{agent.name}`) with the robot in the loop, {args.execution} execution, at a '
            f'{args.unit * 100:g} cm unit. Designs: `rad_core.domain.dense_shapes` (boxes and walls from '
            'rad\'s own block set, brick models of 2-12 two-wide bricks from B22/B24 plates, I2s and cubes). '
            'effector: Franka\'s hand (wide grasps included) or the vacuum gripper (`--effector suction`). '
            'clearance: the scene\'s, a fraction of the unit (0: flush). coverage: what the twin finds built, '
            'mean over designs; whole: designs built to the last cell; orderable built whole: of the designs '
            'whose supply the effector\'s order model can place whole in some order, those built whole; '
            'f: episodes that ended on a failed action; seconds: planning and building the set.')
    page = write_page('dense', 'Dense targets with the parallel hand and the vacuum gripper',
                      ['effector', 'set', 'clearance', 'designs', 'coverage', 'whole', 'orderable built whole', 'f',
                       'seconds'],
                      table, note,
                      rows=rows, results=args.results)
    print(f'wrote {page}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

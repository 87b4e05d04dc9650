"""Your own shapes, built: the supply that asks the hand against the one that does not.

    python benchmarks/bench_supply.py [--agent default] [--city 12] [--seed 2026] [--rows FILE]

`rad scene from-mesh` / `from-voxels` choose the blocks for a target (`rad_core.allocation.supply`). Since
2026-12-04 the cover must be one a top-down hand can place in some order (`SupplyParams.hand`);
`--any-order` gives the cover chosen before. Here every shape is made into a scene both ways
and planned and built by the agent with the robot in the loop (`rad_core.experiment.evaluation.evaluate`,
the code of `rad eval --robot`, teleporting execution).

The shapes, none from the generator and none used in training:
- the gallery's meshes (`data/meshes/meshes.json`) at 5 cm, flush and with the paper's 1 cm
  between blocks (clearance 0.2), as `bench_gallery.py` makes them;
- ten voxel shapes drawn here (`DRAWN`: a chimney on a slab, a ring, stairs, a goalpost, a cross
  stack, a low wall, a closed box, a pyramid, a solid 2 x 2 tower, a frame), at 5 and 4 cm;
- `--city` random "city blocks" (footprints 2..4 x 2..3, every column 0..3 cells high, drawn
  from `--seed`), at 5 and 4 cm.

Printed: per set, the mean coverage of both supplies and every scene whose coverage differs;
with `--rows`, one row per scene (supply counts, the cells the hand's order places, coverage).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from common import ROOT, command_line, write_rows

MESHES = ROOT / 'data' / 'meshes'


def _drawn() -> dict[str, np.ndarray]:
    out = {}
    v = np.zeros((3, 3, 4), bool)
    v[:, :, 0] = True
    v[1, 1, :] = True
    out['chimney_on_slab'] = v
    v = np.ones((4, 4, 1), bool)
    v[1:3, 1:3, 0] = False
    out['ring'] = v
    v = np.zeros((4, 2, 4), bool)
    for k in range(4):
        v[:4 - k, :, k] = True
    out['stairs_back'] = v
    v = np.zeros((5, 1, 3), bool)
    v[0, 0, :] = v[4, 0, :] = v[:, 0, 2] = True
    out['goalpost'] = v
    v = np.zeros((3, 3, 3), bool)
    v[:, :, 0] = True
    v[1, :, 1] = True
    v[:, 1, 2] = True
    out['cross_stack'] = v
    v = np.zeros((6, 1, 2), bool)
    v[:, 0, 0] = True
    v[1:5, 0, 1] = True
    out['long_low_wall'] = v
    v = np.ones((4, 4, 3), bool)
    v[1:3, 1:3, 1] = False
    out['closed_box'] = v
    v = np.zeros((5, 5, 3), bool)
    for k in range(3):
        v[k:5 - k, k:5 - k, k] = True
    out['pyramid5'] = v
    out['tower2x2x6'] = np.ones((2, 2, 6), bool)
    v = np.zeros((7, 1, 3), bool)
    v[:, 0, 0] = v[0, 0, :] = v[6, 0, :] = v[:, 0, 2] = True
    v[3, 0, 1] = True
    out['frame7'] = v
    return out


DRAWN = _drawn()


def city(n: int, seed: int) -> dict[str, np.ndarray]:
    """n random height maps: footprints 2..4 x 2..3, columns 0..3 cells high (at least one cell)."""
    rng = np.random.default_rng(seed)
    out = {}
    for i in range(n):
        nx, ny = rng.integers(2, 5), rng.integers(2, 4)
        h = rng.integers(0, 4, size=(nx, ny))
        v = np.zeros((nx, ny, 4), bool)
        for x in range(nx):
            for y in range(ny):
                v[x, y, :h[x, y]] = True
        if not v.any():
            v[0, 0, 0] = True
        out[f'city{i:02d}'] = v
    return out


def make(models, unit: float, clearance: float, hand: bool):
    from rad_core.allocation.supply import SupplyParams, supply
    from rad_core.domain.blocks import DEFAULT_LIBRARY
    from rad_core.domain.voxels import place_regions
    return supply(place_regions(models, unit), unit, dict(DEFAULT_LIBRARY), params=SupplyParams(hand=hand),
                  clearance=clearance)


def shape_sets(args) -> dict[str, list[tuple[str, list, float, float]]]:
    """Set name -> [(scene name, voxels.Model list, unit, clearance)]."""
    from rad_core.domain.voxels import Model, crop, mesh_models
    meshes = json.loads((MESHES / 'meshes.json').read_text())
    sets = {'gallery meshes': [], 'drawn voxels': [], 'city voxels': []}
    for name, entry in meshes.items():
        models = mesh_models([(name, str(MESHES / entry['file']))], 0.05, size=entry['size'], up=entry['up'])
        for c in (0.0, 0.2):
            sets['gallery meshes'].append((f'{name}-c{c:g}', models, 0.05, c))
    for label, shapes in (('drawn voxels', DRAWN), ('city voxels', city(args.city, args.seed))):
        for name, grid in shapes.items():
            for unit in (0.05, 0.04):
                sets[label].append((f'{name}-u{unit * 100:g}', [Model(name, '', crop(grid))], unit, 0.0))
    return sets


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--agent', default='default', help='the agent (rad_core.sequencing.decide.agents)')
    p.add_argument('--city', type=int, default=12, help='random city-block shapes')
    p.add_argument('--seed', type=int, default=2026, help='seed of the city-block shapes')
    p.add_argument('--rows', type=Path, help='write one row per scene here')
    args = p.parse_args()

    from rad_core.experiment.evaluation import evaluate
    rows, t0 = [], time.perf_counter()
    print(command_line())
    for label, entries in shape_sets(args).items():
        scenes = {True: [], False: []}
        reports = {}
        for name, models, unit, clearance in entries:
            for hand in (True, False):
                scene, report = make(models, unit, clearance, hand)
                scenes[hand].append((name, scene))
                reports[name, hand] = report
        results = {hand: {r['name']: r for r in evaluate(args.agent, scenes[hand], True, 0)['scenes']}
                   for hand in (True, False)}
        cov = {hand: [results[hand][n]['coverage'] for n, *_ in entries] for hand in (True, False)}
        pairs = list(zip(cov[False], cov[True]))
        same = sum(reports[n, True].counts == reports[n, False].counts for n, *_ in entries)
        print(f'{label}: {len(entries)} scenes, coverage {np.mean(cov[False]):.3f} (any order) -> '
              f'{np.mean(cov[True]):.3f} (the hand asked); better on {sum(b > a + 1e-9 for a, b in pairs)}, '
              f'worse on {sum(b < a - 1e-9 for a, b in pairs)}, the same blocks on {same}')
        for (name, *_), a, b in zip(entries, cov[False], cov[True]):
            r = reports[name, True]
            if abs(a - b) > 1e-9:
                print(f'  {name}: {a:.3f} -> {b:.3f} (the hand places {r.hand_covered} of {r.covered} cells; '
                      f'{dict(reports[name, False].counts)} -> {dict(r.counts)})')
            for hand in (True, False):
                rep = reports[name, hand]
                rows.append({'set': label, 'scene': name, 'hand': hand, 'counts': dict(rep.counts),
                             'covered': rep.covered, 'target_cells': rep.target_cells,
                             'hand_covered': rep.hand_covered, 'rounds': rep.rounds,
                             'coverage': results[hand][name]['coverage'], 'steps': results[hand][name]['steps']})
    print(f'{time.perf_counter() - t0:.0f} s')
    if args.rows:
        write_rows(args.rows, rows)
        print(f'{len(rows)} rows -> {args.rows}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

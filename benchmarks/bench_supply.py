"""Your own shapes, built: the supply that asks the hand against the one that does not.

    python benchmarks/bench_supply.py [--agent default] [--city 12] [--seed 2026] [--results DIR]
    python benchmarks/bench_supply.py --from-rows docs/results/supply.rows.jsonl   # the page again, running nothing

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

Writes <results>/supply.md (per set: the mean coverage of both supplies, the scenes better, worse
and given the same blocks) and supply.rows.jsonl (one row per scene and supply: supply counts, the
cells the hand's order places, coverage); prints every scene whose coverage differs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from common import RESULTS, ROOT, page_meta, read_rows, write_page

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


# What each set's row of the table says it holds; {shapes}: scenes / 2, {seed}: --seed.
SET_TEXT = {'gallery meshes': "the gallery's {shapes} meshes, flush and at clearance 0.2",
            'drawn voxels': '{shapes} voxel shapes drawn in the benchmark, 5 and 4 cm',
            'city voxels': '{shapes} random "city blocks" (seed {seed}), 5 and 4 cm'}
HEADERS = ['shapes', 'scenes', 'coverage, any order', 'coverage, the hand asked', 'better', 'worse',
           'the same blocks']
TITLE = 'Your own shapes: blocks the hand can place'


def measure(args) -> list[dict]:
    """Every scene made both ways, planned and built: one row per scene and supply."""
    from rad_core.experiment.evaluation import evaluate
    rows = []
    for label, entries in shape_sets(args).items():
        scenes, reports = {True: [], False: []}, {}
        for name, models, unit, clearance in entries:
            for hand in (True, False):
                scene, report = make(models, unit, clearance, hand)
                scenes[hand].append((name, scene))
                reports[name, hand] = report
        results = {hand: {r['name']: r for r in evaluate(args.agent, scenes[hand], True, 0)['scenes']}
                   for hand in (True, False)}
        for name, *_ in entries:
            for hand in (True, False):
                rep = reports[name, hand]
                rows.append({'set': label, 'scene': name, 'hand': hand, 'counts': dict(rep.counts),
                             'covered': rep.covered, 'target_cells': rep.target_cells,
                             'hand_covered': rep.hand_covered, 'rounds': rep.rounds,
                             'coverage': results[hand][name]['coverage'], 'steps': results[hand][name]['steps']})
        print(f'{label}: {len(entries)} scenes', flush=True)
    return rows


def pairs(rows: list[dict]) -> dict[str, list[tuple[str, dict, dict]]]:
    """Set -> [(scene, its row with any order, its row with the hand asked)], in the rows' order."""
    by = {(r['set'], r['scene'], r['hand']): r for r in rows}
    out = {}
    for r in rows:
        if r['hand']:
            out.setdefault(r['set'], []).append((r['scene'], by[r['set'], r['scene'], False], r))
    return out


def table(rows: list[dict], seed: int) -> list[list]:
    out = []
    for label, scenes in pairs(rows).items():
        a = [x['coverage'] for _, x, _ in scenes]
        b = [y['coverage'] for _, _, y in scenes]
        text = SET_TEXT.get(label, label).format(shapes=len(scenes) // 2, seed=seed)
        out.append([text, len(scenes), f'{np.mean(a):.3f}', f'{np.mean(b):.3f}',
                    sum(y > x + 1e-9 for x, y in zip(a, b)), sum(y < x - 1e-9 for x, y in zip(a, b)),
                    sum(x['counts'] == y['counts'] for _, x, y in scenes)])
    return out


def note(rows: list[dict], agent: str) -> str:
    worse = [f'{name} {x["coverage"]:.3f} -> {y["coverage"]:.3f}' for scenes in pairs(rows).values()
             for name, x, y in scenes if y['coverage'] < x['coverage'] - 1e-9]
    last = f'Worse with the hand asked: {", ".join(worse)}.' if worse else 'No scene is worse with the hand asked.'
    return ('Every shape made into a scene both ways (`rad scene from-mesh`, `from-voxels`, `supply`; `--any-order` '
            'keeps the cover with the fewest blocks, by default the cover must be one a top-down hand can place in '
            f'some order), planned and built by `{agent}` with the robot in the loop (teleporting execution). None '
            f'of the shapes comes from the generator or is used in training. {last}')


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--agent', default='default', help='the agent (rad_core.sequencing.decide.agents)')
    p.add_argument('--city', type=int, default=12, help='random city-block shapes')
    p.add_argument('--seed', type=int, default=2026, help='seed of the city-block shapes')
    p.add_argument('--results', type=Path, default=RESULTS, help='folder of supply.md and supply.rows.jsonl')
    p.add_argument('--from-rows', type=Path,
                   help="rebuild the page from this rows file, running nothing (the page's command, commit, date stay)")
    args = p.parse_args()

    meta = {}
    if args.from_rows:
        rows = read_rows(args.from_rows)
        meta = page_meta(args.results / 'supply.md')
    else:
        t0 = time.perf_counter()
        rows = measure(args)
        print(f'{time.perf_counter() - t0:.0f} s')
    for scenes in pairs(rows).values():
        for name, x, y in scenes:
            if abs(x['coverage'] - y['coverage']) > 1e-9:
                print(f'  {name}: {x["coverage"]:.3f} -> {y["coverage"]:.3f} (the hand places {y["hand_covered"]} '
                      f'of {y["covered"]} cells; {x["counts"]} -> {y["counts"]})')
    page = write_page('supply', TITLE, HEADERS, table(rows, args.seed), note(rows, args.agent), rows,
                      results=args.results, **meta)
    print(f'wrote {page}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

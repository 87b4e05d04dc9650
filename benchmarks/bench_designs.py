"""Large voxel designs made into scenes: the time to a scene and how much of the target its blocks cover.

    python benchmarks/bench_designs.py [--unit 0.02] [--time-limit 10] [--results docs/results]

Furniture and vehicles drawn as voxel grids the way text-to-brick designs come (a 20-stud grid at a 2 cm
unit, 300-1,000 cells) and one 2,100-cell solid, each through the code of `rad scene from-voxels`
(`voxels.voxel_models`, `place_regions`, `supply.supply` with the default block set, the hand's order
asked, --supply auto): the yaw and place chosen, the seconds to a scene (this process's wall clock, one
design at a time, nothing else running), the cells covered, the blocks and where they start. The
designs are this file's own, not a public corpus: they measure size, not variety (bench_meshes has the
corpus). Writes <results>/designs.md and designs.rows.jsonl.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import RESULTS, write_page

TITLE = 'Large voxel designs: time to a scene'
HEADERS = ['design', 'cells', 'blocks', 'covered', 'share', 'stands', 'hand places', 'start', 'fit', 'seconds']


def _box(g, lo, hi):
    g[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True


def _corners(g, xs, ys, size, height):
    """Four posts (legs, wheels) of `size` (x, y) cells, from the ground to `height`, at each x in xs and y in ys."""
    for x in xs:
        for y in ys:
            _box(g, (x, y, 0), (x + size[0], y + size[1], height))


def designs() -> dict[str, np.ndarray]:
    """name -> occupancy [x, y, z], z up."""
    out = {}
    g = np.zeros((16, 12, 9), dtype=bool)                       # table: a top on four legs
    _box(g, (0, 0, 8), (16, 12, 9))
    _corners(g, (0, 14), (0, 10), (2, 2), 8)
    out['table'] = g
    g = np.zeros((12, 12, 16), dtype=bool)                      # chair: seat, back, legs
    _box(g, (0, 0, 6), (12, 12, 8))
    _box(g, (0, 10, 8), (12, 12, 16))
    _corners(g, (0, 10), (0, 10), (2, 2), 6)
    out['chair'] = g
    g = np.zeros((18, 10, 9), dtype=bool)                       # sofa: base, back, arms
    _box(g, (0, 0, 0), (18, 8, 4))
    _box(g, (0, 8, 0), (18, 10, 9))
    _box(g, (0, 0, 4), (2, 8, 7))
    _box(g, (16, 0, 4), (18, 8, 7))
    out['sofa'] = g
    g = np.zeros((18, 10, 8), dtype=bool)                       # car: wheels, body, cabin
    _corners(g, (2, 13), (0, 8), (3, 2), 2)
    _box(g, (0, 0, 2), (18, 10, 5))
    _box(g, (5, 1, 5), (14, 9, 8))
    out['car'] = g
    g = np.zeros((20, 8, 10), dtype=bool)                       # train: engine with a chimney, two wagons
    for x0, x1 in ((0, 7), (8, 13), (14, 20)):
        _box(g, (x0, 0, 0), (x1, 8, 5))
    _box(g, (0, 1, 5), (4, 7, 8))
    _box(g, (5, 3, 5), (7, 5, 10))
    out['train'] = g
    out['solid 20 x 15 x 7'] = np.ones((20, 15, 7), dtype=bool)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--unit', type=float, default=0.02)
    parser.add_argument('--time-limit', type=float, default=10.0, help="supply's CP-SAT time limit, s")
    parser.add_argument('--only', nargs='*', help='design names')
    parser.add_argument('--results', type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    from rad_core.allocation.supply import SupplyParams, supply
    from rad_core.domain.blocks import DEFAULT_LIBRARY
    from rad_core.domain.errors import RadError
    from rad_core.domain.voxels import place_regions, placement, voxel_models
    rows, table = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, grid in designs().items():
            if args.only and name not in args.only:
                continue
            path = Path(tmp) / f'{name.split()[0]}.npy'
            np.save(path, grid)
            t0 = time.perf_counter()
            row = {'design': name, 'cells': int(grid.sum())}
            try:
                models = voxel_models([(name.split()[0], str(path))], args.unit)
                chosen = placement(models, args.unit)
                fit = f'x {chosen.x:g} m, yaw {chosen.yaw}'
                scene, report = supply(place_regions(models, args.unit), args.unit, dict(DEFAULT_LIBRARY),
                                       params=SupplyParams(time_limit_s=args.time_limit))
                row.update(blocks=len(scene.blocks), covered=report.covered, share=report.coverage,
                           stands=report.stands, hand=report.hand_covered, status=report.status,
                           start='feeder' if scene.feeder is not None else 'table', fit=fit)
            except RadError as e:
                row.update(error=str(e))
            row['seconds'] = time.perf_counter() - t0
            rows.append(row)
            if 'error' in row:
                line = [name, row['cells'], '-', '-', '-', '-', '-', '-', row['error'][:60], f'{row["seconds"]:.1f}']
            else:
                line = [name, row['cells'], row['blocks'], row['covered'], f'{row["share"]:.2f}',
                        'yes' if row['stands'] else 'no', row['hand'], row['start'], row['fit'],
                        f'{row["seconds"]:.1f}']
            table.append(line)
            print(' | '.join(str(v) for v in line), flush=True)
    note = (f'Each design through `rad scene from-voxels`\'s code at a {args.unit:g} m unit, the default block set, '
            f'supply\'s --time-limit {args.time_limit:g} s, the hand\'s order asked, --supply auto; seconds: '
            f'the whole of it (fit, supply model, hand order, layout), one design at a time on this machine. '
            f'covered: target cells the chosen blocks cover (blocks only rest: a seat or table top over '
            f'legs overhangs, and what overhangs is left out); hand places: covered cells a top-down hand '
            f'places in some order; stands: the order found keeps what is built standing as a whole.')
    page = write_page('designs', TITLE, HEADERS, table, note, rows, results=args.results)
    print(f'wrote {page}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

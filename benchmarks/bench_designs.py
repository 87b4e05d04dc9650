"""Large voxel designs made into scenes: the time to a scene and how much of the target its blocks cover.

    python benchmarks/bench_designs.py [--unit 0.02] [--time-limit 10] [--results docs/results]

Furniture and vehicles drawn as voxel grids the way text-to-brick designs come (a 20-stud grid at a 2 cm
unit, 300-1,000 cells) and one 2,100-cell solid, each through the code of `rad scene from-voxels`
(`voxels.voxel_models`, `place_regions`, `supply.supply` with the default block set, the hand's order
asked, --supply auto): the yaw and place chosen, the seconds to a scene (this process's wall clock, one
design at a time, nothing else running), the cells covered, the blocks and where they start. The
designs are this file's own, not a public corpus: they measure size, not variety (bench_meshes has the
corpus). Writes <results>/designs.md and designs.rows.jsonl. `designs` and `design_scene` (one design to a
scene) are also what `bench_large.py --designs` plans and builds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from common import RESULTS, design_scene, designs, write_page

TITLE = 'Large voxel designs: time to a scene'
HEADERS = ['design', 'cells', 'blocks', 'covered', 'share', 'stands', 'hand places', 'start', 'fit', 'seconds']


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--unit', type=float, default=0.02)
    parser.add_argument('--time-limit', type=float, default=10.0, help="supply's CP-SAT time limit, s")
    parser.add_argument('--only', nargs='*', help='design names')
    parser.add_argument('--results', type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    from rad_core.domain.errors import RadError
    rows, table = [], []
    for name, grid in designs().items():
        if args.only and name not in args.only:
            continue
        t0 = time.perf_counter()
        row = {'design': name, 'cells': int(grid.sum())}
        try:
            scene, report, fit = design_scene(name, grid, args.unit, args.time_limit)
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

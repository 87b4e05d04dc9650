"""Meshes from outside: how many give a solid target through `rad scene from-mesh`.

    python benchmarks/bench_meshes.py [--size 8] [--unit 0.03] [--random 50] [--results DIR]

The corpus is every mesh pybullet_data ships (installed with pybullet; none made on this project),
chosen by a fixed rule, not by what works: every file in a format `rad scene from-mesh` reads
outside random_urdfs/, in sorted path order, then the first `--random` of random_urdfs/*/*.obj
in sorted order. Every fifth mesh of that order (the 5th, 10th, ...) is held out: it was not
looked at while the voxelization was tuned, and it is reported on its own line.

Each mesh goes through `rad_core.domain.voxels.mesh_models`, the code of `rad scene from-mesh`,
with its longest side `--size` cells of `--unit` m, z up. A solid target is a model with at least
one cell and no error. Writes <results>/meshes.md (per split: meshes, solid targets, the share,
the methods used, the median and longest time) and meshes.rows.jsonl (one row per mesh: the
file, the split, the method, cells, the filled share of its box, seconds, the error).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from common import RESULTS, write_page

TITLE = 'Meshes from outside: solid targets'
METHODS = ('contains', 'bodies', 'flood fill', 'surface', 'closed gaps')    # `voxels.MeshReport.method`
HEADERS = ['meshes', 'count', 'targets', 'share', *METHODS, 'median s', 'longest s']


def corpus(n_random: int) -> list[tuple[str, Path]]:
    """(name relative to pybullet_data, path) by the fixed rule of the module docstring."""
    import pybullet_data
    from rad_core.domain.voxels import MESH_FORMATS
    root = Path(pybullet_data.getDataPath())
    files = sorted(p for p in root.rglob('*') if p.is_file() and p.suffix.lower() in MESH_FORMATS
                   and 'random_urdfs' not in p.relative_to(root).parts)
    files += sorted(root.glob('random_urdfs/*/*.obj'))[:n_random]
    return [(str(p.relative_to(root)), p) for p in files]


def measure(name: str, path: Path, unit: float, size: int) -> dict:
    from rad_core.domain.errors import RadError
    from rad_core.domain.voxels import mesh_models
    t0 = time.perf_counter()
    row = {'mesh': name}
    try:
        model = mesh_models([('m', str(path))], unit, size=size)[0]
    except RadError as e:
        row.update(solid=False, method=None, cells=0, fill=None, error=str(e).replace(str(path), name))
    else:
        cells = int(model.cells.sum())
        row.update(solid=cells > 0, method=model.report.method, cells=cells, shape=list(model.cells.shape),
                   fill=cells / model.cells.size, bodies=model.report.bodies, open_edges=model.report.open_edges,
                   open_after=model.report.open_after, repairs=list(model.report.repairs), error=None)
    row['seconds'] = time.perf_counter() - t0
    return row


def summary(label: str, rows: list[dict]) -> list:
    solid = sum(r['solid'] for r in rows)
    methods = [sum(r['method'] == m for r in rows) for m in METHODS]
    seconds = [r['seconds'] for r in rows]
    return [label, len(rows), solid, f'{solid / max(1, len(rows)):.2f}', *methods,
            f'{np.median(seconds):.2f}', f'{max(seconds):.2f}']


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--size', type=int, default=8, help='longest side of each mesh, in cells')
    ap.add_argument('--unit', type=float, default=0.03, help='cell edge in metres (the arm\'s limits bound the cells)')
    ap.add_argument('--random', type=int, default=50, help='how many of random_urdfs/*/*.obj, in sorted order')
    ap.add_argument('--results', default=str(RESULTS))
    args = ap.parse_args(argv)
    rows = []
    for i, (name, path) in enumerate(corpus(args.random)):
        row = measure(name, path, args.unit, args.size)
        row['split'] = 'held out' if i % 5 == 4 else 'tuning'
        rows.append(row)
        print(f'{i:4d} {row["split"]:8s} {name:60s} {row["method"] or "-":10s} {row["cells"]:5d} '
              f'{row["seconds"]:6.2f}s {row["error"] or ""}', flush=True)
    table = [summary('all', rows), summary('tuning', [r for r in rows if r['split'] == 'tuning']),
             summary('held out', [r for r in rows if r['split'] == 'held out'])]
    print()
    for line in table:
        print(' | '.join(str(v) for v in line))
    failed = [r for r in rows if not r['solid']]
    thin = sorted((r for r in rows if r['solid']), key=lambda r: r['fill'])[:5]
    note = (f'Every mesh file pybullet_data ships outside random_urdfs/ and the first {args.random} of '
            f'random_urdfs/*/*.obj, in sorted order; every fifth held out. `rad scene from-mesh` at --size '
            f'{args.size}, --unit {args.unit:g}, z up (the code of the command, `voxels.mesh_models`). Methods: '
            f'contains = one closed shell, cell centres inside; bodies = several closed shells, united; flood fill '
            f'= anything else, holes capped and the outside flood-filled on a finer grid; surface = closed '
            f'walls thinner than a cell (shells that share edges or touch, cracks narrower than a sub-cell '
            f'included), the cells their surface passes through; closed gaps = anything else left open (gaps '
            f'between parts, open edges that form no loop), its gaps up to about two cells wide closed on the '
            f'flood fill\'s grid by thickening the surface and thinning the solid back. No target ('
            f'{len(failed)}): ' + '; '.join(f'{r["mesh"]} ({_reason(r["error"])})' for r in failed)
            + '. The thinnest targets (filled share of their box): '
            + ', '.join(f'{r["mesh"]} {r["fill"]:.2f}' for r in thin) + '.')
    page = write_page('meshes', TITLE, HEADERS, table, note, rows, results=args.results)
    print(f'wrote {page}', file=sys.stderr)
    return 0


def _reason(error: str | None) -> str:
    """The error's reason, without the file name and the advice."""
    if not error:
        return 'no cell'
    text = error.split(': ', 1)[-1]
    return text.split(':')[0].split(';')[0]


if __name__ == '__main__':
    sys.exit(main())

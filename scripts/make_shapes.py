"""Write scenes/shapes/<name>.json, the hand-designed shapes of rad_core.domain.shapes (seed 0).

    .venv/bin/python scripts/make_shapes.py [--out DIR] [--check] [--time-limit S]

The committed files are what evaluations (`rad eval --scene-dir scenes/shapes`)
and people read; the module is what they come from, so this script is the only
writer and tests/core/test_shapes.py fails when the two drift apart. --check
compares instead of writing (exit 1 on a difference). Each shape's allocation
(CP-SAT, default settings) is solved and summarised: target cells, blocks,
objective, target coverage, and whether the allocated placements can be built
in an order where every block rests fully supported (HEUR's rule) and where
every block at least rests stably (centre of mass over its support).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
try:
    import rad_core  # noqa: F401
except ImportError:   # run without scripts/env.sh: the core is pure Python
    sys.path.insert(0, str(ROOT / 'ros_ws' / 'src' / 'rad_core'))

from rad_core.allocation import AllocationParams, solve, validate_allocation  # noqa: E402
from rad_core.domain import shapes  # noqa: E402
from rad_core.domain.coverage import placements_coverage  # noqa: E402


def fully_supported_order(pieces) -> bool:
    """Whether some order places every piece with each unit on the table, on a
    placed piece or on its own unit (support.fully_supported, on cells)."""
    left, occupied = list(range(len(pieces))), set()
    while left:
        for n in left:
            own = set(pieces[n])
            if all(c[2] == 0 or (c[0], c[1], c[2] - 1) in occupied | own for c in pieces[n]):
                break
        else:
            return False
        left.remove(n)
        occupied.update(pieces[n])
    return True


def summary(name, scene, params):
    result = solve(scene, params)
    problems = validate_allocation(scene, result)
    by_region = {}
    for p in result.placements:
        by_region.setdefault(p.target, []).append(tuple(tuple(c) for c in p.cells))
    heur = all(fully_supported_order(v) for v in by_region.values())
    stable = all(shapes.stable_order(v) is not None for v in by_region.values())
    split = next(k for k, v in shapes.SPLITS.items() if name in v)
    spec = shapes.SPECS[name]
    return {'name': name, 'split': split, 'family': spec.family, 'custom': spec.custom,
            'cells': scene.num_target_cells, 'blocks': len(scene.blocks), 'status': result.status,
            'objective': result.objective, 'coverage': placements_coverage(scene, result.placements),
            'heur_order': heur, 'stable_order': stable, 'problems': problems}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default=str(ROOT / 'scenes' / 'shapes'), help='output folder')
    parser.add_argument('--check', action='store_true', help='compare with the files instead of writing them')
    parser.add_argument('--time-limit', type=float, default=10.0, help='CP-SAT time limit per shape, s')
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = AllocationParams(time_limit_s=args.time_limit)
    stale = []
    print(f'{"shape":13} {"split":8} {"family":10} {"cells":>5} {"blocks":>6} {"status":8} {"obj":>5} '
          f'{"cover":>5} {"heur":>5} {"stable":>6}')
    for name in shapes.SPECS:
        scene = shapes.shape_scene(name)
        text = scene.dumps() + '\n'
        path = out / f'{name}.json'
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(str(path))
        else:
            path.write_text(text)
        s = summary(name, scene, params)
        print(f'{name:13} {s["split"]:8} {s["family"] + ("*" if s["custom"] else ""):10} {s["cells"]:5d} '
              f'{s["blocks"]:6d} {s["status"]:8} {s["objective"]:5.0f} {s["coverage"]:5.2f} '
              f'{"yes" if s["heur_order"] else "no":>5} {"yes" if s["stable_order"] else "no":>6}'
              + (f'  PROBLEMS: {s["problems"]}' if s['problems'] else ''))
    print('* defines its own block types')
    if stale:
        print('out of date: ' + ', '.join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())

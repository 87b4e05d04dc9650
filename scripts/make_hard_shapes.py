"""Write scenes/hard/<name>.json, the hard hand-made cases of rad_core.domain.hard_shapes (seed 0).

    .venv/bin/python scripts/make_hard_shapes.py [--out DIR] [--check] [--time-limit S] [--no-solve]

As scripts/make_shapes.py for scenes/shapes/: the module is what the scenes come from,
this script the only writer, and tests/core/test_hard_shapes.py fails when the two drift
apart; --check compares instead of writing (exit 1 on a difference). Per case it prints
the split, unit, target cells, blocks (decoys the hand cannot take in brackets), the
layout (gap, outer reach), how far out the target reaches, and two CP-SAT allocations:
the paper's (support='none', blind to the arm) and rad's arm-aware one (support='arm'),
each as target coverage and how many ungraspable blocks (O4, O6) it uses.
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

from rad_core.allocation import AllocationParams, solve  # noqa: E402
from rad_core.domain import hard_shapes  # noqa: E402
from rad_core.domain.coverage import placements_coverage  # noqa: E402


def allocation(scene, support: str, time_limit: float) -> str:
    """'coverage/ungraspable blocks used' of one CP-SAT allocation."""
    result = solve(scene, AllocationParams(support=support, time_limit_s=time_limit))
    bad = sum(p.type in hard_shapes.UNGRASPABLE for p in result.placements)
    return f'{placements_coverage(scene, result.placements):.2f}/{bad}'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default=str(ROOT / 'scenes' / 'hard'), help='output folder')
    parser.add_argument('--check', action='store_true', help='compare with the files instead of writing them')
    parser.add_argument('--time-limit', type=float, default=10.0, help='CP-SAT time limit per allocation, s')
    parser.add_argument('--no-solve', action='store_true', help='skip the two allocations')
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stale = []
    print(f'{"case":14} {"split":8} {"unit":>4} {"cells":>5} {"blocks":>9} {"gap":>4} {"reach":>5} {"edge":>5} '
          f'{"paper":>7} {"arm":>7}')
    for name, case in hard_shapes.CASES.items():
        scene = hard_shapes.hard_scene(name)
        text = scene.dumps() + '\n'
        path = out / f'{name}.json'
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(str(path))
        else:
            path.write_text(text)
        split = next((k for k, v in hard_shapes.HARD_SPLITS.items() if name in v), '-')
        decoys = len(case.spec.decoys)
        blocks = f'{len(scene.blocks)}' + (f' [{decoys}]' if decoys else '')
        solved = ('', '') if args.no_solve else (allocation(scene, 'none', args.time_limit),
                                                   allocation(scene, 'arm', args.time_limit))
        print(f'{name:14} {split:8} {case.unit * 100:3.0f}cm {scene.num_target_cells:5d} {blocks:>9} '
              f'{case.layout.gap * 100:3.0f}cm {case.layout.reach[1]:5.2f} {hard_shapes.edge_distance(case):5.3f} '
              f'{solved[0]:>7} {solved[1]:>7}', flush=True)
    print('blocks [n]: n of them are decoys the hand cannot take; paper / arm: CP-SAT allocation coverage / '
          'ungraspable blocks it uses (support none / arm)')
    if stale:
        print('out of date: ' + ', '.join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())

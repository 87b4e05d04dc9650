"""How well `rad calibrate` recovers the motion-capture frame, against the marker's noise.

    python benchmarks/bench_calibration.py [--transforms 40] [--draws 10] [--points 8,15,30]
        [--noise-mm 0,0.1,0.5,1,2] [--seed 0] [--results docs/results] [--rows FILE]

Synthetic pairs with a known transform: for each of --transforms random transforms mocap -> base
(a uniformly random rotation, the motion-capture origin uniform in a 6 m cube around the robot)
and --draws draws each, n marker positions uniform in the arm's workspace in front of the robot
(x 0.25..0.75 m, y -0.4..0.4 m, z 0.05..0.6 m above the table: where a flange marker goes), seen by
motion capture with Gaussian noise of sigma per axis. Each set is fitted by
`rad_core.cell.calibration.fit` (no residual bound, so every draw counts; how many the default 5 mm bound
would refuse is counted beside) and compared with the truth:
- rotation error: the angle of R_fit R_true^T, degrees;
- translation error: |t_fit - t_true|, mm (where the motion-capture origin lands: the rotation error
  times the lever from the points to that origin, metres away, adds to it);
- error at the table's centre: a point at the middle of the table top (WorldConfig's table centre,
  z = 0: below the points, as a block is), mapped by the fit and by the truth, mm: the error
  registration makes there;
- the fit's rms residual, mm.
Printed and written per (n, sigma): median and 95th percentile, and the ratio of the error at the
table point to sigma (the noise's gain). Writes the page, docs/results/calibration.md
(`common.write_page`: its table has a line per (n, sigma)), and one compact JSON line per (n, sigma)
with every statistic to --rows (out/cache/calibration/rows.jsonl by default; floats to 6
significant digits: `write_rows`'s 4 decimals would flatten the noise-free rows' 1e-14 errors
to 0 and move the table's third digit).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from common import CACHE, RESULTS, split_table, write_page

WORKSPACE = (np.array([0.25, -0.4, 0.05]), np.array([0.75, 0.4, 0.6]))
ORIGIN_RANGE = 3.0


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    from rad_core.domain.transforms import matrix_from_quaternion
    q = rng.normal(size=4)
    return matrix_from_quaternion(q / np.linalg.norm(q))


def trial(rng: np.random.Generator, rotation: np.ndarray, translation: np.ndarray, n: int, sigma: float,
          point: np.ndarray) -> dict:
    from rad_core.cell.calibration import DEFAULT_MAX_RMS, PointPairs, fit
    base = rng.uniform(*WORKSPACE, size=(n, 3))
    mocap = (base - translation) @ rotation + rng.normal(0.0, sigma, size=(n, 3))
    c = fit(PointPairs(base, mocap), max_rms=math.inf)
    err = c.rotation @ rotation.T           # the angle by atan2: acos loses it below about 1e-6 deg
    sin_axis = np.array([err[2, 1] - err[1, 2], err[0, 2] - err[2, 0], err[1, 0] - err[0, 1]]) / 2.0
    angle = math.atan2(float(np.linalg.norm(sin_axis)), (np.trace(err) - 1.0) / 2.0)
    at_point = c.apply((point - translation) @ rotation)
    return {'rot_deg': math.degrees(angle),
            'trans_mm': float(np.linalg.norm(c.translation - translation)) * 1e3,
            'point_mm': float(np.linalg.norm(at_point - point)) * 1e3,
            'rms_mm': c.rms_m * 1e3, 'refused': c.rms_m > DEFAULT_MAX_RMS}


def run(transforms: int, draws: int, points: list[int], noise_mm: list[float], seed: int) -> list[dict]:
    from rad_core.sim.world import WorldConfig
    point = np.array([*WorldConfig().table_centre, 0.0])
    rng = np.random.default_rng(seed)
    poses = [(random_rotation(rng), rng.uniform(-ORIGIN_RANGE, ORIGIN_RANGE, 3)) for _ in range(transforms)]
    rows = []
    for n in points:
        for sigma_mm in noise_mm:
            results = [trial(rng, r, t, n, sigma_mm * 1e-3, point) for r, t in poses for _ in range(draws)]
            row = {'points': n, 'noise_mm': sigma_mm, 'trials': len(results),
                   'refused_at_5mm': sum(r['refused'] for r in results)}
            for key in ('rot_deg', 'trans_mm', 'point_mm', 'rms_mm'):
                values = np.array([r[key] for r in results])
                row[key] = {'median': float(np.median(values)), 'p95': float(np.percentile(values, 95)),
                            'max': float(values.max())}
            row['point_gain'] = row['point_mm']['median'] / sigma_mm if sigma_mm else None
            rows.append(row)
    return rows


def table(rows: list[dict]) -> list[str]:
    lines = ['| points | noise sigma (mm) | rotation error (deg) median / p95 | translation error (mm) median / p95 '
             '| error at table centre (mm) median / p95 | / sigma | rms residual (mm) median | refused at 5 mm |',
             '|---|---|---|---|---|---|---|---|']
    for r in rows:
        gain = f'{r["point_gain"]:.2f}' if r['point_gain'] is not None else ''
        lines.append(f'| {r["points"]} | {r["noise_mm"]:g} | {r["rot_deg"]["median"]:.3g} / {r["rot_deg"]["p95"]:.3g} '
                     f'| {r["trans_mm"]["median"]:.3g} / {r["trans_mm"]["p95"]:.3g} '
                     f'| {r["point_mm"]["median"]:.3g} / {r["point_mm"]["p95"]:.3g} | {gain} '
                     f'| {r["rms_mm"]["median"]:.3g} | {r["refused_at_5mm"]}/{r["trials"]} |')
    return lines


def significant(value, digits: int = 6):
    """value with its floats (nested in lists and dicts too) rounded to `digits` significant digits."""
    if isinstance(value, float):
        return float(f'{value:.{digits}g}')
    if isinstance(value, dict):
        return {k: significant(v, digits) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [significant(v, digits) for v in value]
    return value


def write_rows(path: Path, rows: list[dict]) -> Path:
    """One JSON line per row, floats to 6 significant digits (`significant`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(''.join(json.dumps(significant(r), separators=(',', ':')) + '\n' for r in rows))
    return path


def _floats(text: str, kind=float) -> list:
    try:
        return [kind(v) for v in text.split(',') if v.strip()]
    except ValueError:
        raise SystemExit(f'expected comma-separated numbers, got {text!r}') from None


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--transforms', type=int, default=40, help='random transforms mocap -> base')
    p.add_argument('--draws', type=int, default=10, help='point sets drawn per transform')
    p.add_argument('--points', default='8,15,30', help='pairs per set, comma-separated')
    p.add_argument('--noise-mm', default='0,0.1,0.5,1,2', help='marker noise sigma per axis, mm, comma-separated')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--results', default=str(RESULTS), help='folder of the page, calibration.md')
    p.add_argument('--rows', default=str(CACHE / 'calibration' / 'rows.jsonl'),
                   help="every row's statistics (the page's table holds every row)")
    args = p.parse_args()
    points, noise = _floats(args.points, int), _floats(args.noise_mm)
    t0 = time.perf_counter()
    rows = run(args.transforms, args.draws, points, noise, args.seed)
    wall = time.perf_counter() - t0
    lines = table(rows)
    print('\n'.join(lines))
    print(f'wall time {wall:.1f} s')
    rows_file = write_rows(Path(args.rows), rows)
    headers, cells = split_table(lines)
    note = (f'{args.transforms} random transforms x {args.draws} point sets per row; markers uniform in x 0.25..0.75, '
            'y -0.4..0.4, z 0.05..0.6 m; Gaussian noise of sigma per axis; the motion-capture origin up to 3 m '
            'away. "Error at table centre" is what registration of a block sees; "/ sigma" its median over sigma. '
            '"Refused at 5 mm": fits `rad calibrate` would refuse with its default bound.')
    page = write_page('calibration', 'Calibration of the motion-capture frame against marker noise', headers, cells,
                      note, results=args.results)
    print(f'wrote {page} and {rows_file}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

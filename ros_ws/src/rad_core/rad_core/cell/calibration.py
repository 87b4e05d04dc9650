"""The motion-capture frame in the robot's base frame, fitted from point pairs.

A cell's motion capture reports poses in its own frame; rad plans in the robot's
base frame. The calibration is the rigid transform between them,
p_base = R p_mocap + t (no scale: both systems measure metres), fitted by least
squares from pairs of one point seen by both, typically a marker on the flange
at several arm poses: its base-frame position from the arm's forward kinematics,
its motion-capture position from the marker's body.

The fit is the SVD solution of Kabsch and Umeyama (centre both sets, the SVD of
their cross-covariance gives the rotation, with the sign fix that keeps it a
rotation rather than a reflection). A set that cannot fix the transform
(fewer than three points, all on one line, all at one place), non-finite
values and a fit whose rms residual is over a bound (a wrong pair, a marker
that moved) are refused with a RadError that says which.

Pairs CSV: a header row naming at least the six columns of PAIR_COLUMNS, in any
order; other columns (the recorder adds the joint positions q1..q7) are ignored;
blank lines and lines starting with '#' are skipped. `rad calibrate` reads it,
`rad_planner.calibration_recorder` writes it from a live cell.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion, quaternion_from_matrix, rotation_angle_deg

PAIR_COLUMNS = ('x_base', 'y_base', 'z_base', 'x_mocap', 'y_mocap', 'z_mocap')
DEFAULT_MAX_RMS = 0.005
"""m: a fit with a larger rms residual is refused (a pair is wrong, or the marker moved)."""
MIN_SPREAD = 1e-3
"""m: points whose rms distance from their centroid is below this are one place, not a set."""
MIN_LINE_RATIO = 0.01
"""Second over first singular value of the centred points: below it the points lie on a line,
and the turn about that line is fixed only by noise."""
FLANGE_LINK = 'panda_link8'


@dataclass(frozen=True)
class PointPairs:
    """Matching points: base[i] (robot base frame) and mocap[i] (motion-capture frame), metres."""

    base: np.ndarray
    mocap: np.ndarray
    labels: tuple[str, ...] = ()
    """What to call each pair in a message ('line 7'); default 'pair i' (1-based)."""

    def label(self, i: int) -> str:
        return self.labels[i] if i < len(self.labels) else f'pair {i + 1}'


@dataclass(frozen=True)
class Calibration:
    """A fitted transform mocap -> base and how well it fits its pairs."""

    rotation: np.ndarray
    translation: np.ndarray
    residuals_m: tuple[float, ...]

    @property
    def quaternion(self) -> list[float]:
        """[x, y, z, w] of `rotation`, w >= 0."""
        q = quaternion_from_matrix(self.rotation)
        return [-v for v in q] if q[3] < 0 else q

    @property
    def rms_m(self) -> float:
        return float(math.sqrt(np.mean(np.square(self.residuals_m))))

    @property
    def rotation_deg(self) -> float:
        return rotation_angle_deg(self.rotation)

    def apply(self, p_mocap) -> np.ndarray:
        """Points (3,) or (n, 3) from the motion-capture frame into the base frame."""
        return np.asarray(p_mocap, dtype=float) @ self.rotation.T + self.translation

    def to_dict(self) -> dict:
        residuals = [float(r) for r in self.residuals_m]
        return {'translation': [float(v) for v in self.translation], 'quaternion': self.quaternion,
                'rotation_deg': self.rotation_deg, 'rms_m': self.rms_m, 'max_residual_m': max(residuals),
                'residuals_m': residuals, 'points': len(residuals)}

    def params_yaml(self, mocap_frame: str = 'mocap', header: str = '') -> str:
        """The assembly node's ROS 2 parameter file for this calibration."""
        if not mocap_frame:
            raise RadError("mocap_frame must name the motion-capture frame ('' means no calibration)")
        lines = [f'# {line}' for line in header.splitlines()]
        lines += ['# p_base = R(mocap_to_base_quaternion) p_mocap + mocap_to_base_translation (m; q: x, y, z, w)',
                  'assembly:', '  ros__parameters:',
                  f'    mocap_frame: {_yaml_string(mocap_frame)}',
                  f'    mocap_to_base_translation: [{", ".join(_yaml_float(v) for v in self.translation)}]',
                  f'    mocap_to_base_quaternion: [{", ".join(_yaml_float(v) for v in self.quaternion)}]']
        return '\n'.join(lines) + '\n'


def _yaml_float(value: float) -> str:
    """A float YAML 1.1 readers (PyYAML) also read as a float: repr, with a '.' in the mantissa
    (they take 1e-05 for a string)."""
    text = repr(float(value))
    mantissa, e, exponent = text.partition('e')
    if e and '.' not in mantissa:
        text = f'{mantissa}.0e{exponent}'
    return text


def _yaml_string(text: str) -> str:
    """A YAML double-quoted scalar (JSON's string syntax is valid YAML)."""
    return json.dumps(text)


def fit(pairs: PointPairs, max_rms: float = DEFAULT_MAX_RMS) -> Calibration:
    """The rigid transform mocap -> base that fits `pairs` best (least squares), or RadError."""
    if not (max_rms > 0):          # also refuses NaN; inf means no bound
        raise RadError(f'the rms bound must be a positive number of metres, got {max_rms}')
    base, mocap = (np.asarray(a, dtype=float) for a in (pairs.base, pairs.mocap))
    if base.ndim != 2 or base.shape[1:] != (3,) or base.shape != mocap.shape:
        raise RadError(f'expected two (n, 3) point sets of one size, got {base.shape} and {mocap.shape}')
    n = len(base)
    if n < 3:
        raise RadError(f'{n} point pair{"" if n == 1 else "s"}: a calibration needs at least three, '
                       'not all on one line')
    for name, points in (('base', base), ('mocap', mocap)):
        bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
        if len(bad):
            raise RadError(f'{pairs.label(int(bad[0]))}: the {name} point is not finite')
    for name, points in (('base', base), ('mocap', mocap)):
        _check_spread(name, points - points.mean(axis=0), n)
    rotation, translation = _kabsch(mocap, base)
    residuals = np.linalg.norm(mocap @ rotation.T + translation - base, axis=1)
    result = Calibration(rotation, translation, tuple(float(r) for r in residuals))
    if result.rms_m > max_rms:
        worst = int(np.argmax(residuals))
        raise RadError(f'rms residual {result.rms_m * 1e3:.2f} mm is over the bound of {max_rms * 1e3:g} mm '
                       f'(worst: {pairs.label(worst)}, {residuals[worst] * 1e3:.2f} mm): a wrong pair, '
                       'a marker that moved, or a wrong marker offset?')
    return result


def _check_spread(name: str, centred: np.ndarray, n: int) -> None:
    s = np.linalg.svd(centred, compute_uv=False)
    spread = float(np.sqrt(np.sum(s ** 2) / n))
    if spread < MIN_SPREAD:
        raise RadError(f'degenerate set: the {n} {name} points coincide (rms {spread * 1e3:.3g} mm from their '
                       f'centre, need {MIN_SPREAD * 1e3:g} mm): move the arm between pairs')
    if s[1] < MIN_LINE_RATIO * s[0]:
        raise RadError(f'degenerate set: the {n} {name} points lie on one line (second singular value '
                       f'{s[1] / s[0]:.2g} of the first, need {MIN_LINE_RATIO:g}): the turn about that line is '
                       'unknown; add points off it')


def _kabsch(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising sum |R source_i + t - target_i|^2, R a proper rotation."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    h = (source - cs).T @ (target - ct)            # 3x3 cross-covariance
    u, _, vt = np.linalg.svd(h)
    d = 1.0 if np.linalg.det(vt.T @ u.T) >= 0 else -1.0   # a reflection fits coplanar/noisy sets: undo it
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, ct - rotation @ cs


# ---- the pairs CSV -------------------------------------------------------------------

def parse_pairs_csv(text: str, source: str = 'pairs') -> PointPairs:
    """Pairs from CSV text (see the module docstring); RadError names the file and line."""
    a, labels = read_columns(text, PAIR_COLUMNS, source)
    return PointPairs(a[:, :3], a[:, 3:], labels)


def read_columns(text: str, columns: Sequence[str], source: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """The named columns of CSV text as finite floats, one row per data line, and each row's 'line K':
    a header naming at least `columns` in any order (others ignored), blank lines and lines starting
    with '#' skipped; RadError naming the file and line of anything else."""
    lines = [(k, line) for k, line in enumerate(text.splitlines(), start=1)
             if line.strip() and not line.lstrip().startswith('#')]
    if not lines:
        raise RadError(f'{source}: no header row; expected {",".join(columns)}')
    rows = list(csv.reader(io.StringIO('\n'.join(line for _, line in lines))))
    header = [h.strip() for h in rows[0]]
    missing = [c for c in columns if c not in header]
    if missing:
        raise RadError(f'{source} line {lines[0][0]}: the header lacks {", ".join(missing)} '
                       f'(expected {",".join(columns)}; got {",".join(header)})')
    twice = sorted({c for c in columns if header.count(c) > 1})
    if twice:
        raise RadError(f'{source} line {lines[0][0]}: the header names {", ".join(twice)} more than once')
    index = [header.index(c) for c in columns]
    values, labels = [], []
    for (k, _), row in zip(lines[1:], rows[1:]):
        if len(row) != len(header):
            raise RadError(f'{source} line {k}: {len(row)} fields, the header has {len(header)}')
        out = []
        for c, i in zip(columns, index):
            try:
                v = float(row[i])
            except ValueError:
                raise RadError(f'{source} line {k}: {c} is {row[i].strip()!r}, not a number') from None
            if not math.isfinite(v):
                raise RadError(f'{source} line {k}: {c} is {row[i].strip()}, not a finite number')
            out.append(v)
        values.append(out)
        labels.append(f'line {k}')
    return np.array(values, dtype=float).reshape(-1, len(columns)), tuple(labels)


def read_pairs_csv(path: str | Path) -> PointPairs:
    return parse_pairs_csv(read_text(path), str(path))


def read_text(path: str | Path) -> str:
    """A file's text; RadError naming the file and why it cannot be read."""
    try:
        return Path(path).read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise RadError(f'cannot read {str(path)!r}: {getattr(e, "strerror", None) or e}') from None


def append_pair_row(path: str | Path, p_base, p_mocap, extra: dict[str, float] | None = None) -> int:
    """Append one pair (and `extra` columns) to a pairs CSV, writing the header to a new or empty
    file; RadError when the file's header differs. Returns the number of pairs now in the file."""
    path = Path(path)
    extra = extra or {}
    header = list(PAIR_COLUMNS) + list(extra)
    row = [*(float(v) for v in p_base), *(float(v) for v in p_mocap), *(float(v) for v in extra.values())]
    if len(row) != len(header) or not all(math.isfinite(v) for v in row):
        raise RadError(f'a pair row needs two finite 3-vectors, got {row[:6]}')
    try:
        existing = path.read_text().splitlines() if path.exists() else []
        first = next((line for line in existing if line.strip() and not line.startswith('#')), None)
        if first is not None and [h.strip() for h in first.split(',')] != header:
            raise RadError(f'{path} has the header {first!r}, not {",".join(header)}: '
                           'give the recorder another csv_file')
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open('a', newline='') as f:
            writer = csv.writer(f, lineterminator='\n')
            if first is None:
                writer.writerow(header)
            writer.writerow([repr(v) for v in row])
    except OSError as e:
        raise RadError(f'cannot write {str(path)!r}: {e.strerror}') from None
    rows_before = sum(1 for line in existing if line.strip() and not line.startswith('#')) - (first is not None)
    return rows_before + 1


# ---- a pair from a live cell -----------------------------------------------------------

@dataclass(frozen=True)
class RestConfig:
    """When a pair may be taken: both inputs fresh, the arm and the marker still."""

    window_s: float = 0.5
    """s: the arm and the marker must have been still this long; the pair averages this window."""
    joint_tol: float = 1e-3
    """rad: the most any arm joint may move within the window."""
    marker_tol: float = 1e-3
    """m: the most the marker may move within the window (motion capture's noise must fit in it)."""
    stale_after_s: float = 0.5
    """s: the newest joint state and marker pose must be younger than this."""

    def __post_init__(self):
        for name in ('window_s', 'joint_tol', 'marker_tol', 'stale_after_s'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise RadError(f'{name} must be a positive number, got {v}')


def still_mean(samples: Sequence[tuple[float, np.ndarray]], now: float, config: RestConfig, what: str,
               tol: float, unit: str) -> np.ndarray:
    """The mean of the samples (t, value) of the last window_s when the newest is fresh, the samples
    cover the whole window and no component moved more than `tol`; RadError says which fails."""
    if not samples:
        raise RadError(f'no {what} received yet')
    age = now - samples[-1][0]
    if age > config.stale_after_s:
        raise RadError(f'{what} is stale: the last one is {age:.2f} s old (limit {config.stale_after_s:g} s)')
    start = now - config.window_s
    if samples[0][0] > start:
        raise RadError(f'{what} heard for only {now - samples[0][0]:.2f} s: wait {config.window_s:g} s '
                       'with the arm still')
    recent = np.array([v for t, v in samples if t >= start], dtype=float)
    spread = recent.max(axis=0) - recent.min(axis=0)
    worst = int(np.argmax(spread))
    if spread[worst] > tol:
        raise RadError(f'{what} is moving: component {worst + 1} changed by {spread[worst]:.4g} {unit} in the '
                       f'last {config.window_s:g} s (limit {tol:g} {unit}); wait until the arm is at rest')
    return recent.mean(axis=0)


def marker_in_base(world, arm_q, offset=(0.0, 0.0, 0.0), link: str = FLANGE_LINK) -> np.ndarray:
    """Base-frame position of a marker `offset` (m, in the flange frame) from `link`, the arm at
    `arm_q` (7 joint positions), by the forward kinematics of `world` (a rad_core.sim.world.World:
    the simulated URDF's). The world's robot is moved there and back."""
    q = np.asarray(arm_q, dtype=float).ravel()
    if len(q) != 7 or not np.all(np.isfinite(q)):
        raise RadError(f'expected 7 finite arm joint positions, got {q.tolist()}')
    if link not in world.link_index:
        raise RadError(f'the robot has no link {link!r}')
    with world.preserved():
        world.set_joint_positions(q, hold=False)
        position, orientation = world.link_pose(world.link_index[link])
    return position + matrix_from_quaternion(orientation) @ np.asarray(offset, dtype=float)

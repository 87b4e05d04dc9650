"""A fixed camera in the robot's base frame, fitted from flange and tag poses (hand-eye calibration).

The camera is fixed in the cell and a tag is fixed on the flange; at each arm pose i the robot gives
B_i, the flange in the base frame (forward kinematics), and the camera gives C_i, the tag in the
camera frame. Two unknowns close the loop base -> flange -> tag = base -> camera -> tag:

    X C_i = B_i Y       X: the camera in the base frame, Y: the tag in the flange frame,

all of them rigid transforms (p_base = R_X p_cam + t_X, as `rad calibrate` gives the motion-capture
frame). The fit has two stages:

- a closed-form start from the relative motions. Two poses give A X = X D with A = B_j B_i^-1 and
  D = C_j C_i^-1 (Y cancels); the rotation vectors obey log(R_A) = R_X log(R_D), so R_X is the
  rotation that best maps the D vectors onto the A vectors over all pairs (the Kabsch SVD, the
  Park-Martin solution), and t_X solves the stacked (R_A - I) t_X = R_X t_D - t_A by linear least
  squares. Y is then the mean of B_i^-1 X C_i (the rotations' mean projected back on a rotation).
  Pairs that turn by more than PAIR_MAX_DEG are left out of the start: near half a turn the sign of
  a rotation vector is ill-defined.
- a joint nonlinear least squares over X and Y together (scipy's least_squares, 12 parameters as
  small corrections to the start) on every pose's disagreement between X C_i and B_i Y: the tag's
  position in metres and its orientation as a rotation vector in radians times ROTATION_WEIGHT
  (0.1 m per radian: a tag seen with 1 mm of position noise and 0.5 degree, 0.0087 rad, of angle
  noise has about equal noise in both). The loss is soft-L1 at ROBUST_SCALE, quadratic for noise of
  a few millimetres and linear beyond, so one bad pose moves the fit little and stands out in its
  residual.

Refused with a RadError that says which: fewer than three poses, non-finite values, quaternions
that are not of unit length (within QUATERNION_TOL), a flange that keeps one orientation, or turns
about one axis only (then the camera's position along that axis and the turn about it are not
fixed: the second singular value of the stacked rotation vectors of the flange's relative turns,
as an rms angle over the pairs, must reach MIN_SECOND_AXIS_DEG), and a fit whose rms residual is
over a bound (a bad pose: a misread tag, a tag that slipped, a pose taken while moving).

Poses CSV: a header row naming at least the fourteen columns of POSE_COLUMNS, in any order (bf_*:
the flange in the base frame, ct_*: the tag in the camera frame; metres, quaternions x, y, z, w);
other columns are ignored; blank lines and lines starting with '#' are skipped.
`rad calibrate --hand-eye` reads it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rad_core.cell.calibration import Calibration, read_columns, read_text
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import quaternion_from_matrix

FLANGE_COLUMNS = ('bf_x', 'bf_y', 'bf_z', 'bf_qx', 'bf_qy', 'bf_qz', 'bf_qw')
TAG_COLUMNS = ('ct_x', 'ct_y', 'ct_z', 'ct_qx', 'ct_qy', 'ct_qz', 'ct_qw')
POSE_COLUMNS = FLANGE_COLUMNS + TAG_COLUMNS

DEFAULT_MAX_RMS = 0.005
"""m: a fit whose rms position residual is larger is refused (a bad pose)."""
DEFAULT_MAX_RMS_DEG = 2.0
"""deg: a fit whose rms rotation residual is larger is refused (a bad pose)."""
ROTATION_WEIGHT = 0.1
"""m per radian: a rotation residual's weight against a position residual in the joint fit."""
ROBUST_SCALE = 0.003
"""m (and ROTATION_WEIGHT * rad): residual components above this count linearly, not squared."""
QUATERNION_TOL = 1e-3
"""A quaternion whose length differs from 1 by more than this is refused (not a rotation, or a
column mixed up); shorter differences are normalised away."""
MIN_TURN_DEG = 5.0
"""deg: the flange's turns between poses, rms over the pairs, must reach this."""
MIN_SECOND_AXIS_DEG = 5.0
"""deg: the flange's turns off their main axis, rms over the pairs, must reach this. With tag noise
of 1 mm and 0.5 degree (per axis) and ten poses, the camera's position errs by about 3 mm (median)
at 7 degrees, 5 mm at 4.5 and 7 mm at 3; none of it is fixed at 0."""
PAIR_MAX_DEG = 150.0
"""deg: pairs of poses that turn by more are left out of the closed-form start."""


@dataclass(frozen=True)
class HandEyePoses:
    """Matching poses, one row each: the flange in the base frame and the tag in the camera frame
    (translations (n, 3) in metres, quaternions (n, 4) x, y, z, w)."""

    flange_translation: np.ndarray
    flange_quaternion: np.ndarray
    tag_translation: np.ndarray
    tag_quaternion: np.ndarray
    labels: tuple[str, ...] = ()
    """What to call each pose in a message ('line 7'); default 'pose i' (1-based)."""

    def label(self, i: int) -> str:
        return self.labels[i] if i < len(self.labels) else f'pose {i + 1}'

    def __len__(self) -> int:
        return len(np.asarray(self.flange_translation).reshape(-1, 3))


@dataclass(frozen=True)
class HandEye:
    """A fitted camera-in-base X, tag-on-flange Y and each pose's disagreement between X C_i and B_i Y."""

    camera_rotation: np.ndarray
    camera_translation: np.ndarray
    tag_rotation: np.ndarray
    tag_translation: np.ndarray
    residuals_position_m: tuple[float, ...]
    residuals_rotation_deg: tuple[float, ...]
    second_axis_deg: float
    """The flange's turns off their main axis, rms over the pairs of poses, degrees."""

    @property
    def camera(self) -> Calibration:
        """The camera frame -> base frame transform as a Calibration (its residuals: the position ones)."""
        return Calibration(self.camera_rotation, self.camera_translation, self.residuals_position_m)

    @property
    def rms_position_m(self) -> float:
        return float(math.sqrt(np.mean(np.square(self.residuals_position_m))))

    @property
    def rms_rotation_deg(self) -> float:
        return float(math.sqrt(np.mean(np.square(self.residuals_rotation_deg))))

    def to_dict(self) -> dict:
        position = [float(r) for r in self.residuals_position_m]
        rotation = [float(r) for r in self.residuals_rotation_deg]
        return {'translation': [float(v) for v in self.camera_translation], 'quaternion': self.camera.quaternion,
                'tag_on_flange': {'translation': [float(v) for v in self.tag_translation],
                                  'quaternion': _canonical(quaternion_from_matrix(self.tag_rotation))},
                'rms_position_m': self.rms_position_m, 'rms_rotation_deg': self.rms_rotation_deg,
                'max_residual_position_m': max(position), 'max_residual_rotation_deg': max(rotation),
                'residuals_position_m': position, 'residuals_rotation_deg': rotation,
                'second_axis_deg': self.second_axis_deg, 'poses': len(position)}

    def params_yaml(self, camera_frame: str, header: str = '') -> str:
        """The assembly node's ROS 2 parameter file with the camera as the frame poses arrive in."""
        return self.camera.params_yaml(camera_frame, header)


def _canonical(q: list[float]) -> list[float]:
    return [-v for v in q] if q[3] < 0 else q


def _rotations(quaternions: np.ndarray):
    from scipy.spatial.transform import Rotation  # scipy: this module's fit only
    return Rotation.from_quat(quaternions)


def fit(poses: HandEyePoses, max_rms: float = DEFAULT_MAX_RMS,
        max_rms_deg: float = DEFAULT_MAX_RMS_DEG) -> HandEye:
    """X (the camera in the base frame) and Y (the tag on the flange) that fit `poses` best, or RadError."""
    for name, bound in (('rms bound', max_rms), ('rms rotation bound', max_rms_deg)):
        if not (bound > 0):          # also refuses NaN; inf means no bound
            raise RadError(f'the {name} must be a positive number, got {bound}')
    bt, bq, ct, cq = (np.asarray(a, dtype=float) for a in (poses.flange_translation, poses.flange_quaternion,
                                                             poses.tag_translation, poses.tag_quaternion))
    n = len(bt)
    if bt.shape != (n, 3) or ct.shape != (n, 3) or bq.shape != (n, 4) or cq.shape != (n, 4):
        raise RadError(f'expected (n, 3) translations and (n, 4) quaternions of one n, got {bt.shape}, '
                       f'{bq.shape}, {ct.shape} and {cq.shape}')
    if n < 3:
        raise RadError(f'{n} pose{"" if n == 1 else "s"}: a hand-eye calibration needs at least three, '
                       'with the flange turned about two different axes between them')
    for name, values in (('flange pose', np.hstack([bt, bq])), ('tag pose', np.hstack([ct, cq]))):
        bad = np.flatnonzero(~np.all(np.isfinite(values), axis=1))
        if len(bad):
            raise RadError(f'{poses.label(int(bad[0]))}: the {name} is not finite')
    for name, q in (('flange', bq), ('tag', cq)):
        length = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(length - 1.0) > QUATERNION_TOL)
        if len(bad):
            i = int(bad[0])
            raise RadError(f'{poses.label(i)}: the {name} quaternion has length {length[i]:.4g}, not 1 '
                           f'(within {QUATERNION_TOL:g}): is it x, y, z, w, written with enough digits?')
    rb, rc = _rotations(bq), _rotations(cq)
    second = _check_turns(rb, poses)
    rx, tx, ry, ty = _closed_form(rb, bt, rc, ct)
    rx, tx, ry, ty = _refine(rb, bt, rc, ct, rx, tx, ry, ty)
    position, rotation = _residuals(rb, bt, rc, ct, rx, tx, ry, ty)
    result = HandEye(rx.as_matrix(), tx, ry.as_matrix(), ty, tuple(float(r) for r in position),
                     tuple(float(math.degrees(r)) for r in rotation), second)
    if result.rms_position_m > max_rms or result.rms_rotation_deg > max_rms_deg:
        worst = int(np.argmax(position / max_rms + np.degrees(rotation) / max_rms_deg))
        raise RadError(f'rms residual {result.rms_position_m * 1e3:.2f} mm, {result.rms_rotation_deg:.2f} deg is '
                       f'over the bound of {max_rms * 1e3:g} mm, {max_rms_deg:g} deg (worst: {poses.label(worst)}, '
                       f'{position[worst] * 1e3:.2f} mm, {math.degrees(rotation[worst]):.2f} deg): a misread tag, '
                       'a tag that slipped on the flange, or a pose taken while the arm moved? Leave that row out')
    return result


def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.triu_indices(n, k=1)
    return i, j


def _check_turns(rb, poses: HandEyePoses) -> float:
    """The flange's turns between poses off their main axis (rms over the pairs, deg); RadError when
    the flange keeps one orientation or turns about one axis only."""
    i, j = _pairs(len(rb))
    turns = (rb[j] * rb[i].inv()).as_rotvec()        # in the base frame; the same axis for turns about a flange axis
    s = np.linalg.svd(turns, compute_uv=False)
    main, second = (math.degrees(v / math.sqrt(len(turns))) for v in s[:2])
    n = len(rb)
    if main < MIN_TURN_DEG:
        raise RadError(f'degenerate set: the flange keeps one orientation over the {n} poses (turns of '
                       f'{main:.3g} deg rms between them, need {MIN_TURN_DEG:g}): tilt it between poses, '
                       'about at least two different axes')
    if second < MIN_SECOND_AXIS_DEG:
        axis = np.linalg.svd(turns)[2][0]
        axis = axis if axis[np.argmax(np.abs(axis))] > 0 else -axis
        axis_text = ', '.join(f'{float(round(v, 2)) + 0.0:.2f}' for v in axis)     # + 0.0: no '-0.00'
        raise RadError(f'degenerate set: the flange turns about one axis only over the {n} poses (about '
                       f'[{axis_text}] in the base frame; {second:.3g} deg rms off it, '
                       f'need {MIN_SECOND_AXIS_DEG:g}): the camera\'s position along that axis is unknown; '
                       'add poses tilted about another axis')
    return second


def _closed_form(rb, bt, rc, ct):
    """X from A X = X D over the pairs of poses (rotation by Kabsch on the rotation vectors, then the
    translation by linear least squares), Y as the mean of B_i^-1 X C_i."""
    from scipy.spatial.transform import Rotation
    i, j = _pairs(len(rb))
    ra, rd = rb[j] * rb[i].inv(), rc[j] * rc[i].inv()
    alpha, delta = ra.as_rotvec(), rd.as_rotvec()
    keep = np.linalg.norm(alpha, axis=1) < math.radians(PAIR_MAX_DEG)
    if keep.sum() < 2:
        keep[:] = True
    h = delta[keep].T @ alpha[keep]
    u, _, vt = np.linalg.svd(h)
    d = 1.0 if np.linalg.det(vt.T @ u.T) >= 0 else -1.0
    rx_m = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    ta = bt[j] - ra.apply(bt[i])                      # A = B_j B_i^-1
    td = ct[j] - rd.apply(ct[i])                      # D = C_j C_i^-1
    lhs = (ra.as_matrix() - np.eye(3))[keep].reshape(-1, 3)
    rhs = (td @ rx_m.T - ta)[keep].reshape(-1)
    tx = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    rx = Rotation.from_matrix(rx_m)
    # Y_i = B_i^-1 X C_i for each pose; their mean
    ry_i = rb.inv() * rx * rc
    ty_i = rb.inv().apply(rx.apply(ct) + tx - bt)
    u, _, vt = np.linalg.svd(ry_i.as_matrix().sum(axis=0))
    ry = Rotation.from_matrix(u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt)
    return rx, tx, ry, ty_i.mean(axis=0)


def _residuals(rb, bt, rc, ct, rx, tx, ry, ty) -> tuple[np.ndarray, np.ndarray]:
    """Per pose: |t(X C_i) - t(B_i Y)| (m) and the angle of (B_i Y)^-1 X C_i (rad)."""
    position = np.linalg.norm(rx.apply(ct) + tx - (rb.apply(ty) + bt), axis=1)
    rotation = np.linalg.norm(((rb * ry).inv() * rx * rc).as_rotvec(), axis=1)
    return position, rotation


def _refine(rb, bt, rc, ct, rx0, tx0, ry0, ty0):
    """The joint least squares over X and Y from the start (module docstring), or RadError."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    def unpack(p):
        return (Rotation.from_rotvec(p[0:3]) * rx0, tx0 + p[3:6], Rotation.from_rotvec(p[6:9]) * ry0, ty0 + p[9:12])

    def residuals(p):
        rx, tx, ry, ty = unpack(p)
        position = rx.apply(ct) + tx - (rb.apply(ty) + bt)
        rotation = ((rb * ry).inv() * rx * rc).as_rotvec() * ROTATION_WEIGHT
        return np.concatenate([position, rotation], axis=1).ravel()

    solution = least_squares(residuals, np.zeros(12), loss='soft_l1', f_scale=ROBUST_SCALE, x_scale=1.0,
                             xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    if not np.all(np.isfinite(solution.x)):
        raise RadError(f'the joint fit of camera and tag did not converge ({solution.message}): '
                       'check that every row pairs the flange and the tag of one pose')
    return unpack(solution.x)


# ---- the poses CSV ---------------------------------------------------------------------

def parse_poses_csv(text: str, source: str = 'poses') -> HandEyePoses:
    """Poses from CSV text (see the module docstring); RadError names the file and line."""
    a, labels = read_columns(text, POSE_COLUMNS, source)
    return HandEyePoses(a[:, 0:3], a[:, 3:7], a[:, 7:10], a[:, 10:14], labels)


def read_poses_csv(path: str | Path) -> HandEyePoses:
    return parse_poses_csv(read_text(path), str(path))

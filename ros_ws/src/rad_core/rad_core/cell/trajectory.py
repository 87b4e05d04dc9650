"""Joint trajectories: the one type GAMP plans and every plant executes.

The shape is that of trajectory_msgs/JointTrajectory without ROS types, so the
core stays free of rclpy and the dict form goes straight into result files and
through rad_ros.motion: ``{"joint_names": [...], "points": [{"positions": [...],
"velocities": [...], "accelerations": [...], "time_from_start": seconds}]}``.
Velocities and accelerations may be empty (or, in the dict form, left out).

`Spline` interpolates the way a ros2_control joint_trajectory_controller does:
from the state the arm is in (at rest) to the first point, then between points
linearly (positions only), cubic (with velocities) or quintic (with velocities and
accelerations). `limit_violation` samples that motion at Franka's 1 kHz and
compares it with a `rad_core.cell.robot_model.RobotModel`: what a real Franka would
refuse. The twin, the dry run and the benchmarks all check through it.

`parse_trajectory` is what an executor accepts before anything moves; a bad
trajectory raises `TrajectoryRejected` (a RadError with the controller's error
code) naming the point and what is wrong.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from rad_core.cell.robot_model import PANDA, RobotModel
from rad_core.domain.errors import RadError

MAX_POINTS = 10_000
MAX_DURATION = 3600.0
CONTROL_PERIOD = 1e-3
"""Franka's control period (s): limits are checked on samples this far apart."""

# control_msgs/action/FollowJointTrajectory result codes, as a controller answers.
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
OLD_HEADER_TIMESTAMP = -3
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5


class TrajectoryRejected(RadError):
    """A plant refused a trajectory; `code` is the FollowJointTrajectory error code."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


class TrajectoryAborted(RadError):
    """A plant stopped a trajectory it had started (PATH_TOLERANCE_VIOLATED: something held the arm
    back; GOAL_TOLERANCE_VIOLATED): the arm holds where it is. `code` is the error code."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


@dataclass
class TrajectoryPoint:
    positions: list[float]
    velocities: list[float]      # empty when not given
    time_from_start: float
    accelerations: list[float] = field(default_factory=list)   # empty when not given

    def to_dict(self) -> dict:
        return {'positions': list(map(float, self.positions)), 'velocities': list(map(float, self.velocities)),
                'accelerations': list(map(float, self.accelerations)),
                'time_from_start': float(self.time_from_start)}


@dataclass
class Trajectory:
    joint_names: tuple[str, ...]
    points: list[TrajectoryPoint] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.points[-1].time_from_start if self.points else 0.0

    def positions(self) -> np.ndarray:
        """(n, joints) array of the points' positions."""
        return np.array([pt.positions for pt in self.points])

    def times(self) -> np.ndarray:
        return np.array([pt.time_from_start for pt in self.points])

    def to_dict(self) -> dict:
        return {'joint_names': list(self.joint_names), 'points': [pt.to_dict() for pt in self.points]}

    @classmethod
    def from_dict(cls, doc: dict) -> Trajectory:
        """The inverse of `to_dict`; checks the shape only (see `parse_trajectory` for the rest)."""
        try:
            names = tuple(str(n) for n in doc['joint_names'])
            points = [TrajectoryPoint([float(v) for v in pt['positions']],
                                      [float(v) for v in pt.get('velocities') or []],
                                      float(pt['time_from_start']),
                                      [float(v) for v in pt.get('accelerations') or []]) for pt in doc['points']]
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise RadError(f'not a trajectory document: {e}') from None
        return cls(names, points)


def reversed_trajectory(traj: Trajectory, start) -> Trajectory:
    """The same motion backwards, from traj's last point (at rest) to `start` (where traj began, at
    rest): positions in reverse order at T - t, velocities negated, accelerations as they were. The
    path is the one already checked, and |v|, |a|, |jerk| are those of the forward motion."""
    T = traj.duration
    back = [TrajectoryPoint(list(p.positions), [-v for v in p.velocities], T - p.time_from_start,
                            list(p.accelerations)) for p in traj.points[-2::-1]]
    k = len(traj.joint_names)
    end = TrajectoryPoint([float(v) for v in np.asarray(start, dtype=float)[:k]],
                          [0.0] * k if traj.points[0].velocities else [], T,
                          [0.0] * k if traj.points[0].accelerations else [])
    return Trajectory(traj.joint_names, back + [end])


def parse_trajectory(doc: Trajectory | dict, model: RobotModel = PANDA, limit_tol: float = 1e-3) -> Trajectory:
    """An arm trajectory (or its dict form), checked as a Franka arm controller checks a goal.

    The joint names must be the model's 7 arm joints, each once, in any order
    (INVALID_JOINTS otherwise: a franka_ros2 arm controller knows no others, the
    fingers belong to the gripper); the rest is INVALID_GOAL: one position per
    name, all velocities or none, accelerations only with velocities, finite
    numbers, positions within the model's joint range (up to `limit_tol` past it
    is clipped: rounding in planners), times strictly increasing. The result is in
    the model's joint order. Raises `TrajectoryRejected` naming the point.
    """
    if isinstance(doc, Trajectory):
        names, points = doc.joint_names, doc.points
    elif not isinstance(doc, dict) or 'joint_names' not in doc or 'points' not in doc:
        raise TrajectoryRejected(INVALID_GOAL, 'trajectory: expected {"joint_names": [...], "points": [...]}')
    else:
        names, points = doc['joint_names'], doc['points']
    if not isinstance(names, (list, tuple)) or not names or not all(isinstance(n, str) for n in names):
        raise TrajectoryRejected(INVALID_JOINTS, 'trajectory: joint_names must be a non-empty list of strings')
    expected = model.arm_joint_names
    unknown = [n for n in names if n not in expected]
    if unknown:
        raise TrajectoryRejected(INVALID_JOINTS, f'trajectory: incoming joint {unknown[0]!r} does not match the '
                                 f'controller\'s joints ({", ".join(expected)})')
    dup = sorted({n for n in names if list(names).count(n) > 1})
    if dup:
        raise TrajectoryRejected(INVALID_JOINTS, f'trajectory: joint {dup[0]!r} is named twice')
    missing = [n for n in expected if n not in names]
    if missing:
        raise TrajectoryRejected(INVALID_JOINTS, f'trajectory: joint {missing[0]!r} is missing (the controller '
                                 f'takes only goals for all of {", ".join(expected)})')
    if not isinstance(points, (list, tuple)) or not points:
        raise TrajectoryRejected(INVALID_GOAL, 'trajectory: has no points')
    if len(points) > MAX_POINTS:
        raise TrajectoryRejected(INVALID_GOAL, f'trajectory: {len(points)} points exceed the limit of {MAX_POINTS}')
    k = len(names)
    order = [list(names).index(n) for n in expected]
    lower, upper = np.asarray(model.q_min), np.asarray(model.q_max)
    fast = _parse_regular(points, k, order, lower, upper, limit_tol)
    if fast is not None:
        return Trajectory(expected, fast)
    out = []
    for i, p in enumerate(points):
        where = f'trajectory point {i}'
        if isinstance(p, TrajectoryPoint):
            q, v, a, t = p.positions, p.velocities, p.accelerations, p.time_from_start
        elif isinstance(p, dict):
            q, v, a, t = (p.get('positions'), p.get('velocities') or [], p.get('accelerations') or [],
                          p.get('time_from_start'))
        else:
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: expected an object with positions and time_from_start')
        q = _vector(q, f'{where} positions')
        v = _vector(v, f'{where} velocities')
        a = _vector(a, f'{where} accelerations')
        if not isinstance(t, (int, float)) or isinstance(t, bool) or not math.isfinite(t):
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: time_from_start must be a finite number of seconds, '
                                     f'got {t!r}')
        if len(q) != k:
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: {len(q)} positions for {k} joint names')
        if len(v) not in (0, k):
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: {len(v)} velocities for {k} joint names '
                                     '(give all or none)')
        if len(a) not in (0, k) or (len(a) and not len(v)):
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: {len(a)} accelerations for {k} joint names '
                                     '(all or none, and only with velocities)')
        q, v, a = q[order], (v[order] if len(v) else v), (a[order] if len(a) else a)
        bad = np.flatnonzero((q < lower - limit_tol) | (q > upper + limit_tol))
        if len(bad):
            j = bad[0]
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: {expected[j]} = {q[j]:.4f} is outside its limits '
                                     f'[{lower[j]:.4f}, {upper[j]:.4f}] ({model.name})')
        if i == 0 and t < 0:
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: time_from_start {t} is negative')
        if i > 0 and not t > out[-1].time_from_start:
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: time_from_start {t} does not increase '
                                     f'(previous {out[-1].time_from_start})')
        if t > MAX_DURATION:
            raise TrajectoryRejected(INVALID_GOAL, f'{where}: time_from_start {t} s exceeds the limit of '
                                     f'{MAX_DURATION:g} s')
        out.append(TrajectoryPoint(np.clip(q, lower, upper).tolist(), v.tolist(), float(t), a.tolist()))
    if not all(pt.velocities for pt in out):
        for pt in out:
            pt.velocities, pt.accelerations = [], []
    elif not all(pt.accelerations for pt in out):
        for pt in out:
            pt.accelerations = []
    return Trajectory(expected, out)


class Spline:
    """The motion a joint_trajectory_controller makes of a parsed trajectory.

    It starts from `start` at rest at t = 0 (when the first point lies later) and
    interpolates each segment by what the points give: quintic Hermite with
    velocities and accelerations, cubic with velocities, linear with positions only.
    After the last point it holds there. Each segment's polynomial is computed once
    (the twin evaluates it at every physics step).
    """

    def __init__(self, traj: Trajectory, start):
        times, pos = traj.times(), traj.positions()
        k = pos.shape[1]
        vel = np.array([p.velocities for p in traj.points]) if traj.points[0].velocities else None
        acc = np.array([p.accelerations for p in traj.points]) if traj.points[0].accelerations else None
        if times[0] > 0:
            times = np.concatenate([[0.0], times])
            pos = np.vstack([np.asarray(start, dtype=float)[:k], pos])
            vel = None if vel is None else np.vstack([np.zeros(k), vel])
            acc = None if acc is None else np.vstack([np.zeros(k), acc])
        self.times, self.pos, self.vel, self.acc = times, pos, vel, acc
        # Coefficients in s = (t - t_i) / h, lowest power first: (segments, 6, joints).
        h = np.diff(times)[:, None]
        p0, p1 = pos[:-1], pos[1:]
        d, zero = p1 - p0, np.zeros_like(p0)
        if acc is not None:
            v0, v1, a0, a1 = vel[:-1] * h, vel[1:] * h, acc[:-1] * h * h, acc[1:] * h * h
            c = [p0, v0, a0 / 2, 10 * d - 6 * v0 - 4 * v1 - 1.5 * a0 + 0.5 * a1,
                 -15 * d + 8 * v0 + 7 * v1 + 1.5 * a0 - a1, 6 * d - 3 * v0 - 3 * v1 - 0.5 * a0 + 0.5 * a1]
        elif vel is not None:
            v0, v1 = vel[:-1] * h, vel[1:] * h
            c = [p0, v0, 3 * d - 2 * v0 - v1, -2 * d + v0 + v1, zero, zero]
        else:
            c = [p0, d, zero, zero, zero, zero]
        self._coef = np.stack(c, axis=1) if len(times) > 1 else np.zeros((0, 6, k))
        self._h = h[:, 0]
        self._times_list = [float(x) for x in times]

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at one time t (the fast path of a physics step)."""
        times = self._times_list
        if len(times) == 1 or t >= times[-1]:
            zero = np.zeros(self.pos.shape[1])
            return self.pos[-1], zero, zero
        i = min(max(bisect.bisect_right(times, t) - 1, 0), len(times) - 2)
        h = times[i + 1] - times[i]
        s = min(max((t - times[i]) / h, 0.0), 1.0)
        c = self._coef[i]
        q = ((((c[5] * s + c[4]) * s + c[3]) * s + c[2]) * s + c[1]) * s + c[0]
        dq = ((((5 * c[5] * s + 4 * c[4]) * s + 3 * c[3]) * s + 2 * c[2]) * s + c[1]) / h
        ddq = (((20 * c[5] * s + 12 * c[4]) * s + 6 * c[3]) * s + 2 * c[2]) / (h * h)
        return q, dq, ddq

    def __call__(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at time(s) t: (k,) each for a scalar, (n, k) for an array."""
        if np.ndim(t) == 0:
            return self.at(float(t))
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        n = len(self.times)
        if n == 1:
            q = np.repeat(self.pos[:1], len(ts), axis=0)
            zero = np.zeros_like(q)
            out = (q, zero, zero)
        else:
            seg = np.clip(np.searchsorted(self.times, ts, side='right') - 1, 0, n - 2)
            h = self._h[seg][:, None]
            s = np.clip((ts - self.times[seg])[:, None] / h, 0.0, 1.0)
            c = self._coef[seg]                                   # (m, 6, k)
            q = c[:, 5]
            dq = 5 * c[:, 5]
            ddq = 20 * c[:, 5]
            for p in (4, 3, 2):                                   # Horner, with the derivatives alongside
                q = q * s + c[:, p]
                dq = dq * s + p * c[:, p]
                ddq = ddq * s + p * (p - 1) * c[:, p]
            q = (q * s + c[:, 1]) * s + c[:, 0]
            dq = (dq * s + c[:, 1]) / h
            ddq = ddq / (h * h)
            after = ts >= self.times[-1]
            if after.any():
                q[after], dq[after], ddq[after] = self.pos[-1], 0.0, 0.0
            out = (q, dq, ddq)
        return out


def _parse_regular(points, k: int, order: list[int], lower: np.ndarray, upper: np.ndarray,
                   limit_tol: float) -> list[TrajectoryPoint] | None:
    """`parse_trajectory`'s points checked all at once, for the trajectories planners send: every
    point the same kind (`TrajectoryPoint` or dict) with k positions, velocities and accelerations
    each given at every point or at none, all finite and valid. None for anything else, and for
    any point the checks would refuse: the point-by-point parse then says which and why (the
    same points come out either way; tests/core/test_trajectory_parse.py)."""
    try:
        if all(type(p) is TrajectoryPoint for p in points):
            fields = [(p.positions, p.velocities, p.accelerations, p.time_from_start) for p in points]
        elif all(type(p) is dict for p in points):
            fields = [(p.get('positions'), p.get('velocities') or [], p.get('accelerations') or [],
                       p.get('time_from_start')) for p in points]
        else:
            return None
        qs, vs, as_, ts = zip(*fields)
        if not all(isinstance(t, (int, float)) and not isinstance(t, bool) for t in ts):
            return None
        t = np.array(ts, dtype=float)
        q = np.array(qs, dtype=float)
        v = np.array(vs, dtype=float)
        a = np.array(as_, dtype=float)
    except (TypeError, ValueError):
        return None
    n = len(points)
    if q.shape != (n, k) or v.shape not in ((n, k), (n, 0)) or a.shape not in ((n, k), (n, 0)):
        return None
    if a.shape[1] and not v.shape[1]:
        return None
    if not (np.isfinite(q).all() and np.isfinite(v).all() and np.isfinite(a).all() and np.isfinite(t).all()):
        return None
    q = q[:, order]
    if ((q < lower - limit_tol) | (q > upper + limit_tol)).any():
        return None
    if t[0] < 0 or (n > 1 and not (np.diff(t) > 0).all()) or t[-1] > MAX_DURATION:
        return None
    q = np.clip(q, lower, upper).tolist()
    v = v[:, order].tolist() if v.shape[1] else [[]] * n
    a = a[:, order].tolist() if a.shape[1] else [[]] * n
    return [TrajectoryPoint(q[i], list(v[i]), float(ts[i]), list(a[i])) for i in range(n)]


def limit_violation(traj: Trajectory | dict, start, model: RobotModel = PANDA, slack: float = 1.0,
                    dt: float = CONTROL_PERIOD) -> str:
    """Why a real Franka would refuse this arm trajectory from `start` (at rest), or ''.

    The trajectory is parsed as the controller parses it, then its interpolated
    motion (`Spline`) is sampled every `dt` (1 kHz) and its velocity, acceleration
    and jerk, the finite differences of the sampled positions as the robot's 1 kHz
    loop sees them, are compared with the model's limits times `slack`. A first
    point at t = 0 away from the start is a jump the robot cannot make.
    """
    parsed = parse_trajectory(traj, model)
    start = np.asarray(start, dtype=float)[:7]
    first = parsed.points[0]
    if first.time_from_start <= 0 and np.abs(np.asarray(first.positions) - start).max() > 1e-3:
        j = int(np.abs(np.asarray(first.positions) - start).argmax())
        return (f'{model.arm_joint_names[j]}: the first point at t = 0 is {first.positions[j] - start[j]:+.4f} rad '
                f'from where the arm is (a jump)')
    ts, peaks = _sampled(parsed, start, model, dt)
    for label, (ratio, values) in peaks.items():
        if ratio.size and ratio.max() > slack:
            i, k = np.unravel_index(int(ratio.argmax()), ratio.shape)
            limit = abs(values[i, k]) / ratio[i, k]
            return (f'{model.arm_joint_names[k]}: {label} {abs(values[i, k]):.4g} exceeds the {model.name} '
                    f'limit {limit * slack:.4g} ({ratio[i, k]:.2f}x its limit) at t = {max(ts[i], 0.0):.3f} s')
    return ''


def limit_ratios(traj: Trajectory | dict, start, model: RobotModel = PANDA,
                 dt: float = CONTROL_PERIOD) -> dict[str, float]:
    """Peak |v|, |a|, |jerk| of the interpolated motion as ratios to the model's limits (1 kHz samples)."""
    _, peaks = _sampled(parse_trajectory(traj, model), start, model, dt)
    return {label: float(ratio.max()) if ratio.size else 0.0 for label, (ratio, _) in peaks.items()}


def _sampled(parsed: Trajectory, start, model: RobotModel, dt: float):
    """Sample times and, per quantity, (ratio to the model's limit, value) arrays of the controller's motion.

    Positions are sampled every dt, from a few samples at rest before the start to a few held
    after the end. Each quantity is judged both ways a 1 kHz check may take it, and the worse
    counts: as finite differences of the sampled positions (what the robot's loop sees of a
    command, so a position-only trajectory's velocity steps count), and from the interpolant's
    own velocity and acceleration (jerk as the difference of the sampled acceleration: stricter
    where a jerk phase lasts only a few milliseconds)."""
    spline = Spline(parsed, np.asarray(start, dtype=float)[:7])
    ts = np.arange(-3 * dt, spline.duration + 3.5 * dt, dt)
    q, v_an, a_an = spline(np.clip(ts, 0.0, None))
    v_fd = np.diff(q, axis=0) / dt
    a_fd = np.diff(v_fd, axis=0) / dt
    limits = model.limits()
    out = {}
    for label, values, limit in (('velocity', (v_fd, v_an), limits[0]), ('acceleration', (a_fd, a_an), limits[1]),
                                 ('jerk', (np.diff(a_fd, axis=0) / dt, np.diff(a_an, axis=0) / dt), limits[2])):
        both = np.vstack(values)
        out[label] = (np.abs(both) / limit, both)
    if model.braking is not None:
        # The FR3's position-dependent velocity limits: each velocity against the bound where it is (within
        # the table's v_max, so this ratio replaces the table's).
        both = np.vstack((v_fd, v_an))
        lower, upper = model.velocity_bounds(np.vstack((0.5 * (q[:-1] + q[1:]), q)))
        bound = np.where(both >= 0, upper, -lower)
        out['velocity'] = (np.where(np.abs(both) <= 1e-9, 0.0, np.abs(both) / np.maximum(bound, 1e-9)), both)
    return np.concatenate([ts, ts]), out


def _vector(v, where: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise TrajectoryRejected(INVALID_GOAL, f'{where}: expected a list of numbers') from None
    if not np.all(np.isfinite(a)):
        raise TrajectoryRejected(INVALID_GOAL, f'{where}: contains NaN or infinity')
    return a

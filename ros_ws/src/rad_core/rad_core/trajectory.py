"""Joint trajectories: the one type GAMP plans and the twin executes.

The shape is that of trajectory_msgs/JointTrajectory without ROS types, so the
core stays free of rclpy and the dict form goes straight into result files and
through rad_ros.motion: ``{"joint_names": [...], "points": [{"positions": [...],
"velocities": [...], "time_from_start": seconds}]}``. Velocities may be empty
(or, in the dict form, left out): an executor then interpolates linearly.

`parse_trajectory` is what an executor accepts, checked against the Panda
before anything moves, the way a ros2_control joint_trajectory_controller
checks a goal: joint names known and not repeated (any order, a subset
allowed), one position per name, all velocities or none, finite numbers,
positions within the joint limits, times strictly increasing. A bad trajectory
raises RadError naming the point and what is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rad_core.errors import RadError
from rad_core.sim import panda
from rad_core.sim.panda import JOINT_NAMES

MAX_POINTS = 10_000
MAX_DURATION = 3600.0


@dataclass
class TrajectoryPoint:
    positions: list[float]
    velocities: list[float]      # empty when not given
    time_from_start: float

    def to_dict(self) -> dict:
        return {'positions': list(map(float, self.positions)), 'velocities': list(map(float, self.velocities)),
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
            points = [TrajectoryPoint([float(v) for v in pt['positions']], [float(v) for v in pt['velocities']],
                                      float(pt['time_from_start'])) for pt in doc['points']]
        except (KeyError, TypeError, ValueError) as e:
            raise RadError(f'not a trajectory document: {e}') from None
        return cls(names, points)


def parse_trajectory(doc: Trajectory | dict, limit_tol: float = 1e-3) -> Trajectory:
    """The trajectory (or its dict form), checked for the Panda; RadError says what is wrong.

    Positions up to `limit_tol` (rad or m) past a joint limit are accepted and
    clipped to it (rounding in planners); velocities come back empty unless
    every point gives them.
    """
    if isinstance(doc, Trajectory):
        names, points = doc.joint_names, doc.points
    elif not isinstance(doc, dict) or 'joint_names' not in doc or 'points' not in doc:
        raise RadError('trajectory: expected {"joint_names": [...], "points": [...]}')
    else:
        names, points = doc['joint_names'], doc['points']
    if not isinstance(names, (list, tuple)) or not names or not all(isinstance(n, str) for n in names):
        raise RadError('trajectory: joint_names must be a non-empty list of strings')
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown:
        raise RadError(f'trajectory: unknown joint name {unknown[0]!r} (the Panda has {", ".join(JOINT_NAMES)})')
    dup = sorted({n for n in names if list(names).count(n) > 1})
    if dup:
        raise RadError(f'trajectory: joint {dup[0]!r} is named twice')
    if not isinstance(points, (list, tuple)) or not points:
        raise RadError('trajectory: has no points')
    if len(points) > MAX_POINTS:
        raise RadError(f'trajectory: {len(points)} points exceed the limit of {MAX_POINTS}')
    k = len(names)
    joints = np.array([JOINT_NAMES.index(n) for n in names])
    lower, upper = panda.LOWER[joints] - limit_tol, panda.UPPER[joints] + limit_tol
    out = []
    for i, p in enumerate(points):
        where = f'trajectory point {i}'
        if isinstance(p, TrajectoryPoint):
            q, v, t = p.positions, p.velocities, p.time_from_start
        elif isinstance(p, dict):
            q, v, t = p.get('positions'), p.get('velocities') or [], p.get('time_from_start')
        else:
            raise RadError(f'{where}: expected an object with positions and time_from_start')
        q = _vector(q, f'{where} positions')
        v = _vector(v, f'{where} velocities')
        if not isinstance(t, (int, float)) or isinstance(t, bool) or not math.isfinite(t):
            raise RadError(f'{where}: time_from_start must be a finite number of seconds, got {t!r}')
        if len(q) != k:
            raise RadError(f'{where}: {len(q)} positions for {k} joint names')
        if len(v) not in (0, k):
            raise RadError(f'{where}: {len(v)} velocities for {k} joint names (give all or none)')
        bad = np.flatnonzero((q < lower) | (q > upper))
        if len(bad):
            j = bad[0]
            raise RadError(f'{where}: {names[j]} = {q[j]:.4f} is outside its limits '
                           f'[{panda.LOWER[joints[j]]:.4f}, {panda.UPPER[joints[j]]:.4f}]')
        if i == 0 and t < 0:
            raise RadError(f'{where}: time_from_start {t} is negative')
        if i > 0 and not t > out[-1].time_from_start:
            raise RadError(f'{where}: time_from_start {t} does not increase (previous {out[-1].time_from_start})')
        if t > MAX_DURATION:
            raise RadError(f'{where}: time_from_start {t} s exceeds the limit of {MAX_DURATION:g} s')
        out.append(TrajectoryPoint(np.clip(q, panda.LOWER[joints], panda.UPPER[joints]).tolist(), v.tolist(),
                                   float(t)))
    if not all(pt.velocities for pt in out):
        for pt in out:
            pt.velocities = []
    return Trajectory(tuple(names), out)


def _vector(v, where: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise RadError(f'{where}: expected a list of numbers') from None
    if not np.all(np.isfinite(a)):
        raise RadError(f'{where}: contains NaN or infinity')
    return a

"""Timing GAMP's waypoints from the Panda's velocity limits into a `rad_core.trajectory.Trajectory`.

Timing rule (`time_parameterize`): the start configuration is where the robot
is now and is not a point (as a ros2_control joint_trajectory_controller
expects, the first point lies after t = 0). Each segment lasts
``max(min_segment_s, max_j |dq_j| / (velocity_scale * vmax_j))``, finger-only
segments (closing, opening) at least ``min_gripper_segment_s`` so a gripper
has time to close. Velocities are zero at stop points (where the motion
changes direction or the gripper acts) and the central finite difference
``(q[i+1] - q[i-1]) / (t[i+1] - t[i-1])`` at pass-through points (waypoints of
a straight vertical approach), clipped to the scaled limits. With cubic
interpolation between rest points the peak speed is 1.5x the average, so the
default scale 0.5 keeps every joint under 75 % of its limit.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Sequence

import numpy as np

from rad_core.errors import RadError
from rad_core.sim import panda
from rad_core.trajectory import Trajectory, TrajectoryPoint


@dataclass(frozen=True)
class TimingConfig:
    """How fast a planned motion runs."""

    velocity_scale: float = 0.5
    """Fraction of each joint's URDF velocity limit a segment's average speed may use."""
    min_segment_s: float = 0.2
    """Shortest segment (s): tiny moves still get time to settle."""
    min_gripper_segment_s: float = 0.5
    """Shortest finger-only segment (s): the gripper closes or opens in this time."""


def time_parameterize(start: np.ndarray, waypoints: Sequence[np.ndarray], stops: Sequence[bool],
                      config: TimingConfig = TimingConfig(),
                      joint_names: tuple[str, ...] = panda.JOINT_NAMES) -> Trajectory:
    """Timed trajectory from `start` (not a point) through waypoints (9,) each.

    stops[i]: the robot is at rest at waypoint i (the last one always is).
    """
    if len(waypoints) != len(stops) or not waypoints:
        raise RadError('time_parameterize needs one stop flag per waypoint and at least one waypoint')
    vmax = panda.VELOCITY_LIMITS * config.velocity_scale
    qs = np.vstack([np.asarray(start, dtype=float)] + [np.asarray(w, dtype=float) for w in waypoints])
    times = [0.0]
    for a, b in zip(qs[:-1], qs[1:]):
        dq = np.abs(b - a)
        arm_moves = np.any(dq[:7] > 1e-9)
        floor = config.min_segment_s if arm_moves or not np.any(dq[7:] > 1e-9) else config.min_gripper_segment_s
        times.append(times[-1] + max(floor, float(np.max(dq / vmax))))
    times = np.asarray(times)
    stop = [True] + [bool(s) for s in stops[:-1]] + [True]
    points = []
    for i in range(1, len(qs)):
        if stop[i]:
            vel = np.zeros(qs.shape[1])
        else:
            vel = (qs[i + 1] - qs[i - 1]) / (times[i + 1] - times[i - 1])
            vel = np.clip(vel, -vmax, vmax)
        points.append(TrajectoryPoint(qs[i].tolist(), vel.tolist(), float(times[i])))
    return Trajectory(tuple(joint_names), points)

"""Timing GAMP's waypoints within a Franka's limits, into a `rad_core.cell.motion.Motion`.

GAMP plans configurations (9 joints: arm and fingers) and checks the straight
joint-space segments between them for collisions. `plan_motion` turns that path
into what a real cell runs: gripper commands where only the fingers move, and
arm trajectories (7 joints, named as the robot model names them) between them.

Each arm segment, rest to rest at every waypoint, moves along the straight
joint-space line between two waypoints that GAMP checked for collisions, so the
retimed motion is the checked path. Along it, q(t) = a + s(t) (b - a), and ruckig
times the path parameter s from 0 to 1 time-optimally within the tightest of the
joints' limits divided by their share of the move (velocity, acceleration and jerk
of the model times `speed_scale`): every joint stays within its own limits. (A
7-DoF ruckig problem with phase synchronization would leave the line whenever
ruckig falls back to time synchronization, which it does for ordinary moves of
the Panda: measured up to 0.011 rad off the line.) Why ruckig and not toppra:
TOPP-RA bounds velocity and acceleration only, and its bang-bang accelerations
switch in one step, which at 1 kHz is a jerk far over Franka's limits.

Points are placed at ruckig's phase boundaries with positions, velocities and
accelerations. Between two boundaries s(t), and so every joint, is a cubic
(constant jerk), and a quintic Hermite through both ends' position, velocity and
acceleration reproduces a cubic exactly: the joint_trajectory_controller's
quintic interpolation follows the ruckig motion to rounding, so the limits hold
along the motion the robot actually makes, not only at the points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, Result, Ruckig
from ruckig import Trajectory as RuckigTrajectory

from rad_core.cell.motion import GripperCommand, Motion
from rad_core.cell.panda import FINGER_OPEN
from rad_core.cell.robot_model import RobotModel, envelope, robot_model
from rad_core.cell.trajectory import Trajectory, TrajectoryPoint
from rad_core.domain.errors import RadError

_MIN_PHASE = 1e-6     # s: ruckig phases shorter than this add no point
_MARGIN = 1e-3
LEAD_IN_S = 0.05
"""s: the first point, the planned start at rest (see `retime`)."""


@dataclass(frozen=True)
class TimingConfig:
    """How fast a planned motion runs, and on which robot."""

    robot: str = 'panda'
    """Robot model whose joint names the motion carries ('panda' | 'fr3') and, with limits='robot',
    whose limits bound it."""
    limits: str = 'both'
    """'both': time within the limits of the Panda and the FR3 at once (`robot_model.envelope`), so a
    plan suits either robot; 'robot': within the robot's own (faster on a Panda)."""
    joint_prefix: str = ''
    """Joint names `<prefix>_joint1..7` ('' = the model's)."""
    speed_scale: float = 0.7
    """Fraction of the model's velocity limits the motion may use (0, 1] (the old velocity rule's
    cubic segments peaked at 0.75 of the URDF's)."""
    acceleration_scale: float = 1.0
    """Fraction of the model's acceleration and jerk limits the motion may use (0, 1] (as MoveIt's
    velocity and acceleration scaling factors, the two are separate; the motions are short, so
    acceleration decides their time more than the top speed does)."""
    grasp_force: float = 20.0
    """max_effort (N) of a grasp: the hand squeezes the block with this force (a Panda hand: up to 70 N)."""

    @property
    def model(self) -> RobotModel:
        """The robot model whose joint names the motion carries."""
        return robot_model(self.robot, self.joint_prefix)

    @property
    def timing_model(self) -> RobotModel:
        """The model whose limits bound the motion (names as `model`'s)."""
        return envelope(self.model) if self.limits == 'both' else self.model

    def validate(self) -> None:
        """RadError naming a bad robot, joint prefix, limits, scale or force."""
        if self.limits not in ('both', 'robot'):
            raise RadError(f"limits must be 'both' or 'robot', got {self.limits!r}")
        self.model.limits(self.speed_scale)
        self.model.limits(self.acceleration_scale)
        if not (np.isfinite(self.grasp_force) and self.grasp_force > 0):
            raise RadError(f'grasp_force must be a positive number of newtons, got {self.grasp_force}')


def retime(waypoints: Sequence[np.ndarray], model: RobotModel, speed_scale: float,
           joint_names: Sequence[str] | None = None, acceleration_scale: float | None = None) -> Trajectory:
    """A trajectory through (7,) waypoints from waypoints[0] (not a point: where the arm is), at rest at each;
    velocities within speed_scale x the model's limits, accelerations and jerks within acceleration_scale x
    theirs (default: speed_scale)."""
    qs = [np.asarray(w, dtype=float)[:7] for w in waypoints]
    if len(qs) < 2:
        raise RadError('retime needs a start and at least one waypoint')
    # 0.1 % under the limits: rounding (at the points, in the controller) never crosses them.
    v_max = model.limits(speed_scale)[0] * (1.0 - _MARGIN)
    _, a_max, j_max = (x * (1.0 - _MARGIN) for x in model.limits(speed_scale if acceleration_scale is None
                                                                else acceleration_scale))
    otg = Ruckig(1)
    # The controller starts from where the arm actually is, a little off the planned start (tracking,
    # a stale joint state): the first point holds the planned start after LEAD_IN_S, so catching up is a
    # gentle quintic (1 mrad: 2.3 rad/s^2, 480 rad/s^3) and never rides on the motion's own jerk ramp.
    points: list[TrajectoryPoint] = [TrajectoryPoint(qs[0].tolist(), [0.0] * 7, LEAD_IN_S, [0.0] * 7)]
    t0 = LEAD_IN_S
    for a, b in zip(qs[:-1], qs[1:]):
        d = b - a
        moving = np.abs(d) > 1e-12
        if not moving.any():
            continue
        # The path parameter s runs 0 -> 1 along q = a + s d; each joint's limit bounds s's.
        inp = InputParameter(1)
        inp.current_position, inp.target_position = [0.0], [1.0]
        v_seg = v_max if model.braking is None else np.minimum(v_max, _braking_caps(a, d, model) * (1.0 - _MARGIN))
        if not (v_seg[moving] > 0).all():
            raise RadError(f'retime: between {a.round(4).tolist()} and {b.round(4).tolist()} a joint moves into '
                           f'the {model.name}\'s braking zone at the end of its range, where it may not move')
        inp.max_velocity = [float(np.min(v_seg[moving] / np.abs(d[moving])))]
        inp.max_acceleration = [float(np.min(a_max[moving] / np.abs(d[moving])))]
        inp.max_jerk = [float(np.min(j_max[moving] / np.abs(d[moving])))]
        traj = _segment(otg, inp, a, b)
        profile = traj.profiles[0][0]
        knots = np.cumsum(profile.t) + profile.brake.duration
        knots = [float(k) for k in knots if k > _MIN_PHASE]
        knots = sorted(set(round(k, 12) for k in knots[:-1] if k < traj.duration - _MIN_PHASE)) + [traj.duration]
        for k in knots:
            (s,), (ds,), (dds,) = traj.at_time(k)
            q, v, acc = a + s * d, ds * d, dds * d
            if k == knots[-1]:
                q, v, acc = b, np.zeros(7), np.zeros(7)
            points.append(TrajectoryPoint(q.tolist(), v.tolist(), t0 + float(k), acc.tolist()))
        t0 += traj.duration
    if len(points) == 1:
        raise RadError('retime: the arm does not move')
    return Trajectory(tuple(joint_names or model.arm_joint_names), points)


def _segment(otg: Ruckig, inp: InputParameter, a: np.ndarray, b: np.ndarray) -> RuckigTrajectory:
    traj = RuckigTrajectory(1)
    result = otg.calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise RadError(f'retime: ruckig failed ({result}) between {a.round(4).tolist()} and {b.round(4).tolist()}')
    return traj


def _braking_caps(a: np.ndarray, d: np.ndarray, model: RobotModel) -> np.ndarray:
    """Per joint, the lowest velocity limit the model allows anywhere on the segment a -> a + d in the
    direction the joint moves (the FR3's position-dependent limits, sampled every 1/64 of the way and at
    both ends): a segment timed within these keeps to them everywhere."""
    s_ = np.linspace(0.0, 1.0, 65)[:, None]
    lower, upper = model.velocity_bounds(a + s_ * d)
    return np.where(d >= 0, upper.min(axis=0), -lower.max(axis=0))


def plan_motion(start: np.ndarray, waypoints: Sequence[np.ndarray], config: TimingConfig = TimingConfig(),
                grasp_expected: float = float('nan'), vacuum: tuple[int, int] | None = None) -> Motion:
    """The Motion through GAMP's (9,) waypoints from `start` (9,): arm where the arm moves, gripper where only
    the fingers move (closing = 'grasp', expecting the fingers to stop at `grasp_expected`; opening after a grasp
    = 'release'; opening before it = 'open'). The first commands set the hand to the approach's opening if the
    start's fingers differ from it ('close' first when it is narrower).

    vacuum: (level in 10 mbar, timeout in ms) for the vacuum gripper, whose waypoints' finger coordinate
    stands for the vacuum (`planner._try_grasp`): a grasp is then a 'vacuum' command, a release a 'drop_off',
    and there is nothing to open."""
    motion = _plan_motion(start, waypoints, config, grasp_expected)
    if vacuum is None:
        return motion
    level, timeout_ms = vacuum
    gripper = []
    for g in motion.gripper:
        if g.action == 'grasp':
            gripper.append(GripperCommand('vacuum', FINGER_OPEN, 0.0, g.before, vacuum=level, timeout_ms=timeout_ms))
        elif g.action == 'release':
            gripper.append(GripperCommand('drop_off', FINGER_OPEN, 0.0, g.before, timeout_ms=timeout_ms))
    motion.gripper = gripper
    return motion


def _plan_motion(start: np.ndarray, waypoints: Sequence[np.ndarray], config: TimingConfig,
                 grasp_expected: float) -> Motion:
    model = config.timing_model
    qs = [np.asarray(start, dtype=float)] + [np.asarray(w, dtype=float) for w in waypoints]
    motion = Motion()
    arm_path = [qs[0]]
    fingers = float(np.mean(qs[0][7:]))
    held = False

    def flush():
        nonlocal arm_path
        if len(arm_path) > 1:
            motion.trajectories.append(retime(arm_path, model, config.speed_scale,
                                              acceleration_scale=config.acceleration_scale))
        arm_path = [arm_path[-1]]

    for q in qs[1:]:
        f = float(np.mean(q[7:]))
        arm_moves = np.abs(q[:7] - arm_path[-1][:7]).max() > 1e-9
        if abs(f - fingers) > 1e-9:
            if arm_moves:
                if len(arm_path) == 1 and not motion.trajectories and not held:
                    # The approach's opening differs from the start's: set it first. A Franka hand's
                    # gripper_action only moves when opening (a closing command is a grasp, which fails
                    # on air), so a narrower opening is reached by closing the empty hand, then opening.
                    if f < fingers:
                        motion.gripper.append(GripperCommand('close', 0.0, config.grasp_force, 0))
                    motion.gripper.append(GripperCommand('open', f, config.grasp_force, 0))
                    fingers = f
                else:
                    raise RadError('plan_motion: the arm and the fingers move in the same segment')
            else:
                flush()
                closing = f < fingers
                action = 'grasp' if closing else ('release' if held else 'open')
                motion.gripper.append(GripperCommand(action, f, config.grasp_force, len(motion.trajectories),
                                                     grasp_expected if closing else float('nan')))
                held = closing
                fingers = f
                continue
        if arm_moves:
            arm_path.append(q)
    flush()
    if not motion.trajectories:
        raise RadError('plan_motion: the arm does not move')
    return motion

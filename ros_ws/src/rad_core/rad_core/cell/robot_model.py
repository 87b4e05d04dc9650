"""The robots rad drives: Franka's published limits for the Panda and the FR3.

A real Franka refuses (a libfranka "reflex") any command whose 1 kHz finite
differences break these limits, and a franka_ros2 arm controller knows only the
7 arm joints, named with the robot's prefix. So every arm trajectory rad sends is
timed within one of these models (`rad_core.gamp.trajectory.retime`) and checked
against it (`rad_core.cell.trajectory.limit_violation`), and the twin refuses what
breaks them.

Positions: the planner (IK, GAMP) keeps every configuration inside
`PLANNING_LOWER`/`PLANNING_UPPER`, the intersection of both robots' published
ranges and the simulated URDF's, so one plan is valid on either robot (both share
the Panda's kinematics). Velocity, acceleration and jerk come from the model the
cell runs (parameter `robot`), times a speed scale. The FR3's velocity limits also
depend on the joint's position (`RobotModel.velocity_bounds`, as libfranka
computes them: a joint must be able to brake to rest before its range ends), so
near the ends of a range it moves slower than its table value.

Source: Franka's "robot and interface specifications" (libfranka), as gathered in
the project's REAL_CELL.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rad_core.domain.errors import RadError


@dataclass(frozen=True)
class RobotModel:
    """One robot's arm joints and limits, in joint order 1..7."""

    name: str
    prefix: str
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    v_max: tuple[float, ...]
    a_max: tuple[float, ...]
    j_max: tuple[float, ...]
    braking: tuple[tuple[float, float, float, float], ...] | None = None
    """Position-dependent velocity limits (the FR3), per joint (offset, 2 x deceleration, lower end, upper
    end): moving up, |v| <= sqrt(2 x deceleration x (upper end - q)) - offset, moving down the same from
    the lower end, both within the table's v_max; None: the table's v_max everywhere."""

    def velocity_bounds(self, q) -> tuple[np.ndarray, np.ndarray]:
        """(lowest, highest) joint velocities allowed at positions q (..., 7), rad/s."""
        q = np.asarray(q, dtype=float)
        v = np.broadcast_to(np.asarray(self.v_max, dtype=float), q.shape)
        if self.braking is None:
            return -v, v
        offset, decel2, low, high = (np.asarray(c, dtype=float) for c in zip(*self.braking))
        up = np.minimum(v, np.maximum(0.0, np.sqrt(np.maximum(0.0, decel2 * (high - q))) - offset))
        down = np.minimum(v, np.maximum(0.0, np.sqrt(np.maximum(0.0, decel2 * (q - low))) - offset))
        return -down, up

    @property
    def arm_joint_names(self) -> tuple[str, ...]:
        return tuple(f'{self.prefix}_joint{k}' for k in range(1, 8))

    @property
    def finger_joint_names(self) -> tuple[str, ...]:
        return (f'{self.prefix}_finger_joint1', f'{self.prefix}_finger_joint2')

    def limits(self, speed_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(v, a, j) arrays, each times speed_scale (0 < speed_scale <= 1)."""
        if not 0.0 < speed_scale <= 1.0:
            raise RadError(f'speed_scale must be in (0, 1], got {speed_scale}')
        return tuple(np.asarray(x, dtype=float) * speed_scale for x in (self.v_max, self.a_max, self.j_max))


PANDA = RobotModel(
    'panda', 'panda',
    q_min=(-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
    q_max=(2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
    v_max=(2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61),
    a_max=(15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
    j_max=(7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0),
)

FR3 = RobotModel(
    'fr3', 'fr3',
    q_min=(-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159),
    q_max=(2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159),
    v_max=(2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26),
    a_max=(10.0,) * 7,
    j_max=(5000.0,) * 7,
    # libfranka's computeUpper/LowerLimitsJointVelocity (rate_limiting.h), Franka's "Limits for Franka
    # Research 3": offset, 2 x deceleration, and the range ends they brake towards (slightly past q_min/q_max).
    braking=((0.30, 12.0, -2.7501, 2.7501), (0.20, 5.17, -1.7918, 1.7918), (0.20, 7.0, -2.9065, 2.9065),
             (0.30, 8.0, -3.0481, -0.1458), (0.35, 34.0, -2.8101, 2.8101), (0.35, 11.0, 0.54092, 4.5205),
             (0.35, 34.0, -3.0196, 3.0196)),
)

MODELS = {m.name: m for m in (PANDA, FR3)}


def envelope(model: RobotModel) -> RobotModel:
    """`model` (its name and joint names) with the limits both the Panda and the FR3 keep: the
    smaller velocity, acceleration and jerk of each joint, the narrower position range. A motion
    timed within it is one either robot takes."""
    pick = {f: tuple(float(v) for v in (np.minimum if f != 'q_min' else np.maximum)(
        np.asarray(getattr(PANDA, f)), np.asarray(getattr(FR3, f)))) for f in ('q_min', 'q_max', 'v_max', 'a_max',
                                                                              'j_max')}
    return replace(model, **pick, braking=FR3.braking)

BRAKING_MARGIN = 0.02
"""How far (rad) plans keep outside the FR3's braking zones (where its velocity limit toward the end
of the range is zero: within offset^2 / (2 x deceleration) of the end)."""
_offset, _decel2, _low, _high = (np.asarray(c, dtype=float) for c in zip(*FR3.braking))
PLANNING_LOWER = np.maximum.reduce([np.asarray(PANDA.q_min), np.asarray(FR3.q_min),
                                    _low + _offset ** 2 / _decel2 + BRAKING_MARGIN])
PLANNING_UPPER = np.minimum.reduce([np.asarray(PANDA.q_max), np.asarray(FR3.q_max),
                                    _high - _offset ** 2 / _decel2 - BRAKING_MARGIN])
"""The arm's position range every plan keeps to: valid on the Panda and on the FR3, clear of the FR3's
braking zones, so every waypoint can be reached at a speed the FR3 allows."""
for _a in (PLANNING_LOWER, PLANNING_UPPER):
    _a.setflags(write=False)


def robot_model(name: str, joint_prefix: str = '') -> RobotModel:
    """The model called `name` ('panda' or 'fr3'), its joints named `<joint_prefix>_joint1..7`
    ('' = the model's own prefix; e.g. 'fer' for franka_description's newer Panda); RadError
    names the known models."""
    try:
        model = MODELS[name]
    except KeyError:
        raise RadError(f'unknown robot model {name!r} (known: {", ".join(sorted(MODELS))})') from None
    if joint_prefix and joint_prefix != model.prefix:
        if not joint_prefix.replace('_', '').isalnum():
            raise RadError(f'joint_prefix {joint_prefix!r} must be letters, digits and underscores')
        model = replace(model, prefix=joint_prefix)
    return model

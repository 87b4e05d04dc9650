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
cell runs (parameter `robot`), times a speed scale. Not modelled: the FR3's
position-dependent velocity limits (its table values are used as they stand).

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
)

MODELS = {m.name: m for m in (PANDA, FR3)}


def envelope(model: RobotModel) -> RobotModel:
    """`model` (its name and joint names) with the limits both the Panda and the FR3 keep: the
    smaller velocity, acceleration and jerk of each joint, the narrower position range. A motion
    timed within it is one either robot takes."""
    pick = {f: tuple(float(v) for v in (np.minimum if f != 'q_min' else np.maximum)(
        np.asarray(getattr(PANDA, f)), np.asarray(getattr(FR3, f)))) for f in ('q_min', 'q_max', 'v_max', 'a_max',
                                                                              'j_max')}
    return replace(model, **pick)

PLANNING_LOWER = np.maximum(np.asarray(PANDA.q_min), np.asarray(FR3.q_min))
PLANNING_UPPER = np.minimum(np.asarray(PANDA.q_max), np.asarray(FR3.q_max))
"""The arm's position range every plan keeps to: valid on the Panda and on the FR3."""
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

"""The Panda's forward kinematics and Jacobian in numpy, read off the loaded robot, and Newton steps
towards a grasp-target pose: what `gamp.ik` finishes its answers with.

pybullet's `calculateInverseKinematics` is damped least squares: from an answer a few millimetres
off it needs about a hundred iterations a call (each ~2.5 us in C, plus the call) and one to six
calls to come within 0.2 mm. A Newton step on the exact Jacobian squares the error: two or three
from there reach 1e-6 m, at about 45 us a step in numpy. Both move the joints the least-squares way
(the smallest joint step that removes the error), so they end near each other on the arm's
self-motion, not at the same joints.

The chain is read from pybullet, not typed in: every arm link's frame at zero joints gives the
fixed transform from its parent's frame (`PandaKinematics.__init__`), so the URDF the world loaded
(rad's Panda with Franka's finger boxes) is the one computed. All seven arm joints of that URDF
turn about their frame's z axis; the grasp target hangs off link 7 by a fixed transform (the
flange, the hand, the target frame). Agrees with pybullet's forward kinematics to 1e-6
(tests/core/test_ik.py).
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion
from rad_core.sim.world import World

# World -> (the robot's base pose when read, PandaKinematics).
_KINEMATICS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_WHISKER = 1e-12 * np.eye(6)


class PandaKinematics:
    """Forward kinematics of a world's Panda: arm joints (7,) -> the grasp target's pose."""

    def __init__(self, world: World):
        p, cid, robot = world.pybullet, world.client, world.robot
        frames = []
        with world.preserved():
            zero = np.zeros(len(world.joints))
            zero[7:] = world.joint_positions()[7:]
            world.set_joint_positions(zero, hold=False)
            for link in [*world.joints[:7], world.ee_link]:
                state = p.getLinkState(robot, link, computeForwardKinematics=True, physicsClientId=cid)
                frames.append(_matrix(state[4], state[5]))
        for link in world.joints[:7]:
            axis = p.getJointInfo(robot, link, physicsClientId=cid)[13]
            if tuple(axis) != (0.0, 0.0, 1.0):
                raise RadError(f'PandaKinematics expects every arm joint to turn about z, joint {link} about {axis}')
        # At zero joints every joint's rotation is the identity, so link j's frame is the chain of the
        # fixed transforms up to it: constants[j] = frame[j-1]^-1 frame[j] (the first one from the world).
        self.constants = np.stack([frames[0]] + [np.linalg.inv(frames[j - 1]) @ frames[j] for j in range(1, 7)])
        self.tip = np.linalg.inv(frames[6]) @ frames[7]

    def forward(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The grasp target's pose (4, 4) at arm joints q[:7], with each joint's axis (7, 3) and
        origin (7, 3) in the world: what `jacobian` needs."""
        c, s = np.cos(q[:7])[:, None], np.sin(q[:7])[:, None]
        x, y = self.constants[:, :, 0], self.constants[:, :, 1]
        # Every joint's fixed transform turned by its joint about z, all seven at once: C_j Rz(q_j)
        # mixes C_j's first two columns.
        links = self.constants.copy()
        links[:, :, 0] = c * x + s * y
        links[:, :, 1] = c * y - s * x
        frames = [links[0]]
        for j in range(1, 7):
            frames.append(frames[-1] @ links[j])
        chain = np.stack(frames)
        return frames[-1] @ self.tip, chain[:, :3, 2], chain[:, :3, 3]

    @staticmethod
    def jacobian(tip: np.ndarray, axes: np.ndarray, origins: np.ndarray) -> np.ndarray:
        """(6, 7): the grasp target's linear and angular velocity per unit speed of each revolute joint
        (axis x (tip - origin) and the axis)."""
        d = tip[:3, 3] - origins
        a = axes
        return np.stack([a[:, 1] * d[:, 2] - a[:, 2] * d[:, 1], a[:, 2] * d[:, 0] - a[:, 0] * d[:, 2],
                         a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0], a[:, 0], a[:, 1], a[:, 2]])


def kinematics(world: World) -> PandaKinematics:
    """The world's PandaKinematics, made once (again if the robot's base was moved)."""
    p = world.pybullet
    base = p.getBasePositionAndOrientation(world.robot, physicsClientId=world.client)
    known = _KINEMATICS.get(world)
    if known is None or known[0] != base:
        known = _KINEMATICS[world] = (base, PandaKinematics(world))
    return known[1]


def pose_error(target_position: np.ndarray, target_rotation: np.ndarray, tip: np.ndarray) -> np.ndarray:
    """(6,): what turns the tip's pose into the target's: the position difference (m) and the rotation
    vector (rad, world frame) of target_rotation @ tip_rotation^T."""
    m = target_rotation @ tip[:3, :3].T
    v = 0.5 * np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    s = math.sqrt(v @ v)
    angle = math.atan2(s, 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0))
    if s > 1e-15:
        v *= angle / s
    elif angle > 1.0:
        # Half a turn away (s ~ 0, angle ~ pi): any axis the rotation keeps; Newton steps off it.
        w, vecs = np.linalg.eigh(0.5 * (m + m.T))
        v = vecs[:, int(np.argmax(w))] * angle
    return np.concatenate([target_position - tip[:3, 3], v])


def newton(kin: PandaKinematics, position: np.ndarray, rotation: np.ndarray, q: np.ndarray,
           steps: int, max_step: float = 0.5, start_within: tuple[float, float] | None = None
           ) -> tuple[np.ndarray, float, float] | None:
    """Up to `steps` Newton steps of the arm joints q[:7] (a copy) towards the grasp-target pose;
    the joints and the final residual (m, deg). Each step is the smallest joint change the Jacobian
    says removes the error (J^T (J J^T)^-1 e, a whisker of damping against singular poses), scaled
    down to at most max_step rad on any joint. start_within (m, deg): None, without a step, when q
    does not put the target that near the pose to begin with."""
    q = np.array(q, dtype=float)
    tip, axes, origins = kin.forward(q)
    e = pose_error(position, rotation, tip)
    if start_within is not None and (e[:3] @ e[:3] > start_within[0] ** 2
                                     or math.degrees(math.sqrt(e[3:] @ e[3:])) > start_within[1]):
        return None
    for _ in range(steps):
        if abs(e[:3]).max() < 1e-6 and abs(e[3:]).max() < 1e-5:
            break
        jac = kin.jacobian(tip, axes, origins)
        dq = jac.T @ np.linalg.solve(jac @ jac.T + _WHISKER, e)
        largest = abs(dq).max()
        if largest > max_step:
            dq *= max_step / largest
        q[:7] += dq
        tip, axes, origins = kin.forward(q)
        e = pose_error(position, rotation, tip)
    return q, float(np.linalg.norm(e[:3])), math.degrees(float(np.linalg.norm(e[3:])))


def _matrix(position, quaternion) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = matrix_from_quaternion(quaternion)
    out[:3, 3] = position
    return out

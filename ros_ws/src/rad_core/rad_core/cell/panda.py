"""The Franka Panda of pybullet_data (franka_panda/panda.urdf) as rad uses it.

One change to that model: the fingers collide as Franka's own robot description models them
(`FINGER_BOXES`), not as pybullet_data's convex hull of the finger mesh. The hull spans the
whole finger, so at a block's height it is about 25 mm thick where the real finger (a 15 mm
rubber tip under a thin slanted web) is not: it refuses grasps between blocks 2.5 cm apart
that the real hand makes. `urdf_path` writes the changed URDF once (meshes by absolute path)
into a per-user temporary folder; `source_urdf_path` is pybullet_data's own file.

Fixed base at the world origin, standing on the table top (z = 0). Joint
position limits: the arm's are Franka's published ranges, narrower than the
URDF's by about 0.07 rad (`rad_core.cell.robot_model.PLANNING_LOWER`/`UPPER`: valid on
the Panda and the FR3); the fingers' and the velocity limits are read from the URDF
itself (plain XML, no pybullet import).

Geometry worth knowing (measured in pybullet):
- link indices: arm joints 0-6, fixed panda_joint8 (7) and panda_hand_joint (8),
  fingers 9 and 10 (prismatic, 0..0.04 m each, so the hand opens 0.08 m),
  panda_grasptarget 11, a frame 0.105 m below the hand between the fingertips;
  it has no collision shape.
- The fingers close along the hand's y axis. With the hand pointing straight
  down (hand z = world -z) and hand yaw theta (hand x = (cos theta, sin theta)),
  the closing axis points along theta - 90 deg: see `closing_yaw_to_hand_yaw`.
- The hand is mounted 45 deg off the flange, so at HOME (joint 7 = 2.356 rad)
  the fingers close along world x.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from functools import lru_cache
from pathlib import Path

import numpy as np

from rad_core.cell.robot_model import PLANNING_LOWER, PLANNING_UPPER
from rad_core.domain.errors import RadError

URDF_RELATIVE = 'franka_panda/panda.urdf'

JOINT_NAMES = (
    'panda_joint1', 'panda_joint2', 'panda_joint3', 'panda_joint4',
    'panda_joint5', 'panda_joint6', 'panda_joint7',
    'panda_finger_joint1', 'panda_finger_joint2',
)
ARM_JOINT_NAMES = JOINT_NAMES[:7]
FINGER_JOINT_NAMES = JOINT_NAMES[7:]

GRASP_TARGET_LINK = 'panda_grasptarget'
HAND_LINK = 'panda_hand'
FINGER_LINKS = ('panda_leftfinger', 'panda_rightfinger')

FINGER_OPEN = 0.04
"""Each finger's travel when open (m): the hand opens FINGER_OPEN * 2 = 0.08 m."""
MAX_OPENING = 2 * FINGER_OPEN

HOME = np.array([0.0, -0.215, 0.0, -2.57, 0.0, 2.356, 2.356, FINGER_OPEN, FINGER_OPEN])
"""The predecessor's home pose, fingers open: hand above the table in front of the robot."""

HAND_YAW_AT_HOME_OFFSET = math.pi / 4
"""Top-down hand yaw ~= joint1 - joint7 + this (hand mounted 45 deg off the flange);
used to predict joint 7 for a requested hand yaw."""


FINGER_BOXES = (
    # (centre x, y, z; roll about x (rad); size x, y, z) in the left finger's frame (m): the
    # finger joint's frame, y the closing axis pointing away from the other finger, z down the
    # finger. Franka's franka_description (end_effectors/common/franka_hand.xacro) models the
    # finger's collision with these four boxes; the right finger mirrors them in y.
    ((0.0, 0.0185, 0.011), 0.0, (0.022, 0.015, 0.020)),           # screw mount
    ((0.0, 0.0068, 0.0022), 0.0, (0.022, 0.0088, 0.0038)),        # carriage sledge
    ((0.0, 0.0159, 0.02835), math.pi / 6, (0.0175, 0.007, 0.0235)),  # slanted web
    ((0.0, 0.00758, 0.04525), 0.0, (0.0175, 0.0152, 0.0185)),     # rubber tip, the grasping pad
)


EFFECTORS = ('hand', 'suction')
"""The end effectors rad plans for: Franka's parallel hand, and a vacuum gripper in its place on the
flange (libfranka's VacuumGripper: the Schmalz cobot pump with one suction cup)."""

SUCTION_HOUSING = (0.08, 0.08, 0.09)
"""The vacuum gripper's pump housing as a box under the flange (x, y, z size, m), the z size from the
flange down. Approximate: a cobot pump's outline; give yours here."""
CUP_RADIUS = 0.01
"""The suction cup's radius (m): a 20 mm cup. It seals only on a flat face at least this far from
every edge (`gamp.grasps.suction_grasps`)."""
CUP_LENGTH = 0.03
"""From the housing's bottom to the cup's lip (m): the cup and its holder, a cylinder of CUP_RADIUS."""
SUCTION_TCP = SUCTION_HOUSING[2] + CUP_LENGTH
"""How far below the flange the cup's lip is (m): the vacuum gripper's grasp target (its TCP)."""


def source_urdf_path() -> Path:
    """pybullet_data's franka_panda/panda.urdf (finger collision: the hull of the finger mesh)."""
    import pybullet_data  # a plain data package: no banner, unlike pybullet itself
    return Path(pybullet_data.getDataPath()) / URDF_RELATIVE


def urdf_path(effector: str = 'hand') -> Path:
    """The URDF rad loads: pybullet_data's with the fingers' collision as `FINGER_BOXES`, or for the
    'suction' effector the vacuum gripper in the hand's place (`suction_urdf`).

    Written per content and pybullet_data folder (its meshes are named by absolute path) into a
    per-user temporary folder, atomically, so processes starting together are safe; written again
    whenever it is gone (a temporary folder's cleaner may take it from a long-running node)."""
    check_effector(effector)
    path, source, text = _urdf_name(effector)
    if not path.exists():
        _write_urdf(path, source, text, effector)
    return path


def check_effector(effector: str) -> None:
    if effector not in EFFECTORS:
        raise RadError(f'effector must be one of {", ".join(EFFECTORS)}, got {effector!r}')


@lru_cache(maxsize=2)
def _urdf_name(effector: str) -> tuple[Path, Path, bytes]:
    """(where the URDF goes, pybullet_data's URDF, its text)."""
    source = source_urdf_path()
    text = source.read_bytes()
    shapes = (FINGER_BOXES, SUCTION_HOUSING, CUP_RADIUS, CUP_LENGTH) if effector == 'suction' else FINGER_BOXES
    digest = hashlib.sha256(text + repr((shapes, str(source.parent))).encode()).hexdigest()[:12]
    name = 'panda' if effector == 'hand' else f'panda-{effector}'
    return Path(tempfile.gettempdir()) / f'rad-{os.getuid()}' / f'{name}-{digest}.urdf', source, text


def _write_urdf(path: Path, source: Path, text: bytes, effector: str = 'hand') -> None:
    root = ET.fromstring(text)
    for mesh in root.iter('mesh'):
        name = mesh.get('filename', '')
        if name.startswith('package://'):
            mesh.set('filename', str(source.parent / name[len('package://'):]))
    if effector == 'suction':
        suction_urdf(root)
        _write_atomically(path, ET.tostring(root))
        return
    for link in root.iter('link'):
        side = {'panda_leftfinger': 1, 'panda_rightfinger': -1}.get(link.get('name'))
        if side is None:
            continue
        for old in link.findall('collision'):
            link.remove(old)
        for (x, y, z), roll, size in FINGER_BOXES:
            collision = ET.SubElement(link, 'collision')
            ET.SubElement(collision, 'origin', xyz=f'{x} {side * y} {z}', rpy=f'{side * roll} 0 0')
            ET.SubElement(ET.SubElement(collision, 'geometry'), 'box', size=' '.join(map(str, size)))
    _write_atomically(path, ET.tostring(root))


def suction_urdf(root: ET.Element) -> None:
    """Turn the Panda URDF's tree (`root`) into the arm with the vacuum gripper: panda_hand becomes the
    pump housing (`SUCTION_HOUSING`) and the cup (`CUP_RADIUS`, `CUP_LENGTH`), its visual and collision
    alike; the fingers keep their joints (rad's joint vectors stay 9 long; nothing moves them) and lose
    every shape; panda_grasptarget moves to the cup's lip (`SUCTION_TCP`)."""
    for link in root.iter('link'):
        name = link.get('name')
        if name in FINGER_LINKS:
            for old in link.findall('visual') + link.findall('collision'):
                link.remove(old)
        if name != HAND_LINK:
            continue
        for old in link.findall('visual') + link.findall('collision'):
            link.remove(old)
        hx, hy, hz = SUCTION_HOUSING
        for tag in ('visual', 'collision'):
            housing = ET.SubElement(link, tag)
            ET.SubElement(housing, 'origin', xyz=f'0 0 {hz / 2}', rpy='0 0 0')
            ET.SubElement(ET.SubElement(housing, 'geometry'), 'box', size=f'{hx} {hy} {hz}')
            cup = ET.SubElement(link, tag)
            ET.SubElement(cup, 'origin', xyz=f'0 0 {hz + CUP_LENGTH / 2}', rpy='0 0 0')
            ET.SubElement(ET.SubElement(cup, 'geometry'), 'cylinder', radius=str(CUP_RADIUS), length=str(CUP_LENGTH))
    for joint in root.iter('joint'):
        if joint.get('name') == 'panda_grasptarget_hand':
            joint.find('origin').set('xyz', f'0 0 {SUCTION_TCP}')


def _write_atomically(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile('wb', dir=path.parent, suffix='.tmp', delete=False) as f:
        f.write(data)
    os.replace(f.name, path)


@lru_cache(maxsize=1)
def _limits() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    root = ET.parse(source_urdf_path()).getroot()
    by_name = {j.get('name'): j for j in root.iter('joint')}
    lower, upper, velocity = [], [], []
    for name in JOINT_NAMES:
        limit = by_name[name].find('limit')
        lower.append(float(limit.get('lower')))
        upper.append(float(limit.get('upper')))
        velocity.append(float(limit.get('velocity')))
    return np.array(lower), np.array(upper), np.array(velocity)


URDF_LOWER, URDF_UPPER, VELOCITY_LIMITS = (a.copy() for a in _limits())
"""The URDF's joint limits (rad, or m for the fingers) and velocity limits, (9,) in JOINT_NAMES order."""
LOWER = np.concatenate([np.maximum(PLANNING_LOWER, URDF_LOWER[:7]), URDF_LOWER[7:]])
UPPER = np.concatenate([np.minimum(PLANNING_UPPER, URDF_UPPER[:7]), URDF_UPPER[7:]])
"""The joint range every plan keeps to, (9,) in JOINT_NAMES order: Franka's published arm limits."""
for _a in (URDF_LOWER, URDF_UPPER, LOWER, UPPER, VELOCITY_LIMITS):
    _a.setflags(write=False)


def within_limits(q, tol: float = 1e-6) -> bool:
    """True when every joint of a (9,) or (7,) vector is inside the planning range (LOWER, UPPER)."""
    q = np.asarray(q, dtype=float)
    n = len(q)
    return bool(np.all(q >= LOWER[:n] - tol) and np.all(q <= UPPER[:n] + tol))


def closing_yaw_to_hand_yaw(closing_yaw: float) -> float:
    """Hand yaw (rad) of a top-down hand whose fingers close along `closing_yaw`."""
    return closing_yaw + math.pi / 2


def top_down_quaternion(hand_yaw: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of the hand pointing down (z = world -z), x at hand_yaw.

    R = Rz(hand_yaw) Rx(pi).
    """
    h = hand_yaw / 2
    # Rz(a) = (0, 0, sin a/2, cos a/2); Rx(pi) = (1, 0, 0, 0); product Rz * Rx:
    return np.array([math.cos(h), math.sin(h), 0.0, 0.0])


def load_panda(client: int, base_position=(0.0, 0.0, 0.0), effector: str = 'hand') -> int:
    """Load the Panda with its hand or the vacuum gripper (`EFFECTORS`) into a client (fixed base,
    self-collision on); returns the body id."""
    import pybullet as p  # pybullet: importing it prints a banner on stdout
    flags = p.URDF_USE_SELF_COLLISION | p.URDF_USE_SELF_COLLISION_EXCLUDE_ALL_PARENTS
    return p.loadURDF(str(urdf_path(effector)), basePosition=list(base_position), useFixedBase=True,
                      flags=flags, physicsClientId=client)

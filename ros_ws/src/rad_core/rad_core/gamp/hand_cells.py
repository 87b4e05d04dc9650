"""The cells a top-down hand fills when it holds a unit: a built one there refuses every plan.

At a placement the planner puts the grasp target on the held unit's centre (or, in a tight
grasp, over it: `planner.grasp_styles`), the hand pointing straight down at one of two hand yaws
per grasp, the fingers open (`planner.plan_action`). The
hand, the fingers and panda_link7 are rigid with the grasp target there (joint 7 turns them
together; the links above depend on the IK solution), so whether they run into a neighbouring
cell's block does not depend on the arm, the order or the start: only on the cell's offset from
the held unit, the hand yaw, the unit, the finger opening and the grasp's height.

`blocking_offsets` measures that once per (unit, clearance, opening, hand yaw, height), in a Bullet
world of its own (one per effector and process): a unit cube put at each offset around the held
unit, turned into the hand's frame. An offset blocks when the cube sinks more than `DEPTH` into one
of those links. The planner may take a unit in one of two ways (`planner.grasp_styles`); each is
measured apart. The planner refuses a contact closer than its margin (2 mm); `DEPTH` asks for more,
so that a block resting a few millimetres off its cell, or an IK answer within its 2 mm tolerance,
cannot turn a blocking offset into a free one. The cube is the smallest box a block's unit can have
(its side faces set back by the scene's clearance, no overlap). So a blocking offset is one the
planner always refuses; others may be refused too (the links above, the descent, the carried block),
which this test leaves to the planner.

Used through `allocation.arm.HandBlocked`: a pose all of whose grasps, at either hand yaw, have a
built cell at a blocking offset can never be placed once those cells are built, and cells are never
unbuilt. The robot ceiling's bound and the hand's order models count on it.
"""

from __future__ import annotations

import math
import os
import threading
from functools import lru_cache

import numpy as np

from rad_core.cell import panda
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion, quaternion_from_matrix
from rad_core.sim.physics import PhysicsConfig

DEPTH = 0.004
"""How far (m) a neighbour's cube must sink into the hand for the offset to count as blocking."""

NEAR_DEPTH = -0.0015
"""A depth for orders that should agree with the planner rather than bound it: a cube closer than
1.5 mm to those links, which the planner's 2 mm collision margin refuses (with half a millimetre for
a block resting a little off its cell the other way)."""

REACH = (4, 4, 4)
"""Offsets measured: |di|, |dj| up to 4 units (the palm is 0.21 m across), dk from -1 to 4."""

_RIGID = ('panda_link7', 'panda_link8', 'panda_hand', 'panda_leftfinger', 'panda_rightfinger')


@lru_cache(maxsize=64)
def blocking_offsets(unit: float, clearance: float, finger_open: float, hand_yaw_deg: int,
                     lift: float = 0.0, shift: tuple[float, float] = (0.0, 0.0), effector: str = 'hand',
                     course: float | None = None, depth: float = DEPTH) -> frozenset:
    """The integer cell offsets (di, dj, dk) from a held unit whose built cube the hand, its fingers
    open `finger_open` each, or panda_link7 enters by more than `DEPTH`, the hand pointing down at
    `hand_yaw_deg` (a multiple of 90) with its grasp target `lift` (m) over the held unit's centre.
    shift: where the grasp target sits beside that unit's centre, in units along world x and y (a
    wide grasp's target is the middle of its row: `grasps.grasp_centre`; offsets then count from
    the row's first unit). effector: the hand, or the vacuum gripper (`cell.panda.EFFECTORS`: its
    housing and cup, no fingers). course: the lattice's z pitch (m) where it is not the unit (a stud
    system's course height). depth: how far the cube must sink in (m, default `DEPTH`); a negative one
    counts a cube that comes closer than -depth (`NEAR_DEPTH`: what the planner's margin refuses)."""
    import pybullet as p  # pybullet: importing it prints a banner on stdout

    if hand_yaw_deg % 90:
        raise RadError(f'blocking_offsets: hand yaw must be a multiple of 90 deg, got {hand_yaw_deg}')
    with _PROBE_LOCK:
        return _measure(p, _probe(effector, os.getpid()), unit, clearance, finger_open, hand_yaw_deg, lift, shift,
                        course, depth)


def _measure(p, probe, unit, clearance, finger_open, hand_yaw_deg, lift, shift, course, depth) -> frozenset:
    cid, robot, index, movable, cubes = probe
    q = list(panda.HOME)
    q[7:] = [finger_open, finger_open]
    for j, v in zip(movable, q):
        p.resetJointState(robot, j, v, physicsClientId=cid)
    # The links are rigid with the grasp target: measure them wherever it is, with the cubes
    # put where they would be, relative to it, for a hand exactly at the asked yaw.
    got = p.getLinkState(robot, index[panda.GRASP_TARGET_LINK], computeForwardKinematics=1, physicsClientId=cid)
    hand = matrix_from_quaternion(np.asarray(got[5]))
    asked = matrix_from_quaternion(panda.top_down_quaternion(math.radians(hand_yaw_deg)))
    turn = hand @ asked.T                  # world offsets for the asked hand -> this hand's
    # The held (first) unit's centre: under the grasp target, `shift` units beside it.
    at = np.asarray(got[4]) + turn @ (-shift[0] * unit, -shift[1] * unit, -lift)
    # A block's unit box as `physics.block_shape` makes it, its sides set back by the scene's
    # clearance, without its overlap: the smallest it can be.
    side = unit / 2 - PhysicsConfig().side_gap * unit - clearance * unit / 2
    pitch = np.array([unit, unit, unit if course is None else course])
    halves = (round(side, 9), round(side, 9), round(float(pitch[2]) / 2, 9))
    cube = cubes.get(halves)
    if cube is None:       # (cubes stay: only the pairs asked about are measured)
        box = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(halves), physicsClientId=cid)
        cube = cubes[halves] = p.createMultiBody(0.0, box, -1, physicsClientId=cid)
    turned = list(quaternion_from_matrix(turn))
    links = [index[name] for name in _RIGID]
    out = set()
    ri, rj, rk = REACH
    for di in range(-ri, ri + 1):
        for dj in range(-rj, rj + 1):
            for dk in range(-1, rk + 1):
                if (di, dj, dk) == (0, 0, 0):
                    continue
                centre = at + turn @ (np.array([di, dj, dk], dtype=float) * pitch)
                p.resetBasePositionAndOrientation(cube, centre.tolist(), turned, physicsClientId=cid)
                if any(pt[8] < -depth for link in links
                       for pt in p.getClosestPoints(cube, robot, max(0.0, -depth), linkIndexB=link,
                                                    physicsClientId=cid)):
                    out.add((di, dj, dk))
    return frozenset(out)


_PROBE_LOCK = threading.Lock()


@lru_cache(maxsize=None)
def _probe(effector: str, pid: int) -> tuple[int, int, dict, list, dict]:
    """A Bullet world of process `pid`'s own with the robot carrying `effector`, loaded once:
    (client, robot, link index by name, the movable joints, a cube body per size asked). Each
    `blocking_offsets` call sets the joints and moves its cube about (one call at a time: `_PROBE_LOCK`)."""
    import pybullet as p

    cid = p.connect(p.DIRECT)
    robot = panda.load_panda(cid, effector=effector)
    index = {p.getJointInfo(robot, i, physicsClientId=cid)[12].decode(): i
             for i in range(p.getNumJoints(robot, physicsClientId=cid))}
    movable = [i for i in range(p.getNumJoints(robot, physicsClientId=cid))
               if p.getJointInfo(robot, i, physicsClientId=cid)[2] != p.JOINT_FIXED]
    return cid, robot, index, movable, {}

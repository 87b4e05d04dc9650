"""The blocks of a rad scene as MoveIt 2 collision objects (moveit_msgs/CollisionObject).

MoveIt's planning scene monitor (move_group) reads CollisionObjects on /collision_object; the
markers node (rad_viz) publishes these there when its `collision_objects` parameter is on, so
that MoveIt plans around the blocks. Message types only: no rclpy, no DDS.

One object per block, id ``rad/block/<block id>`` (`OBJECT_PREFIX`), in the frame given (the
robot's base frame). The object's pose is the block's: its anchor unit's centre and its
orientation, where motion capture sees it (`poses[id]`, as rad_ros.markers takes them) or else
where the scene has it. Its primitives are one shape_msgs/SolidPrimitive BOX per unit cube of the
polycube, each at its unit's place in the block's frame (`primitive_poses`, relative to the
object's pose, as CollisionObject defines them): cubes of edge `scene.unit` that touch where
units meet, their outer side faces set back by half the scene's clearance
(rad_core.domain.blocks.unit_boxes), so the boxes are the block's solid, not the smaller cubes
RViz's markers draw. Since the boxes ride in the block's frame, a tilted or knocked-over block
is exact, not snapped to the grid.

What is left out:
  * blocks waiting inside a feeder (`scene.in_feeder`): they are parked in it, out of the
    robot's reach, and have no pose of their own; the one the feeder presents gets its object
    as soon as motion capture sees it;
  * the table: the robot stands on it, so a box for it touches panda_link0 and MoveIt would
    report every state in collision unless the cell's SRDF allows that contact; a cell's MoveIt
    configuration models its table itself;
  * a block in the gripper is a world object like any other, where motion capture sees it (in
    the hand): attaching it to the hand (moveit_msgs/AttachedCollisionObject, so that MoveIt
    carries it and allows its contact with the fingers) is not done.
"""

from __future__ import annotations

import math
from typing import Mapping

from geometry_msgs.msg import Point, Pose, Quaternion
from moveit_msgs.msg import CollisionObject
from rad_core.domain.blocks import unit_boxes
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_quaternion
from shape_msgs.msg import SolidPrimitive

OBJECT_PREFIX = 'rad/block/'
"""A block's collision object id is this prefix and the block's id."""

MOVE_TOLERANCE = 1e-3
"""An object is sent again when its block moved more than this (m) or turned more than this (rad)."""


def object_id(block_id: str) -> str:
    """The collision object id of a block: ``rad/block/<block id>``."""
    return OBJECT_PREFIX + block_id


def _pose(position, quaternion) -> Pose:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def block_object(scene: Scene, block_id: str, frame_id: str, pose: tuple | None = None) -> CollisionObject:
    """One block as an ADD CollisionObject in frame_id: at `pose` = (position, quaternion xyzw) where
    given, else at the scene's pose; one BOX per unit cube, placed in the block's frame.
    The header's stamp is left zero (the publisher sets it)."""
    block = scene.block(block_id)
    position, quaternion = pose if pose is not None else (block.position, yaw_quaternion(block.yaw))
    offsets = scene.block_types[block.type].offsets
    half = scene.unit / 2
    shift, halves = unit_boxes(offsets, half, scene.course / 2, scene.clearance * scene.unit / 2)
    obj = CollisionObject(id=object_id(block.id), operation=CollisionObject.ADD, pose=_pose(position, quaternion))
    obj.header.frame_id = frame_id
    for offset, d, h in zip(offsets, shift, halves):
        centre = [float(pitch) * float(o) + float(s) for pitch, o, s in zip(scene.pitch, offset, d)]
        obj.primitives.append(SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[float(2 * v) for v in h]))
        obj.primitive_poses.append(_pose(centre, (0.0, 0.0, 0.0, 1.0)))
    return obj


def block_objects(scene: Scene, frame_id: str, poses: Mapping[str, tuple] | None = None) -> dict[str, CollisionObject]:
    """Object id -> ADD CollisionObject of every block the robot can meet (module docstring): each at
    `poses[block id]` where given, else at its scene pose; feeder blocks only where `poses` has them."""
    poses = poses or {}
    return {object_id(b.id): block_object(scene, b.id, frame_id, poses.get(b.id))
            for b in scene.blocks if b.id in poses or not scene.in_feeder(b.id)}


def remove_object(obj_id: str, frame_id: str) -> CollisionObject:
    """The REMOVE CollisionObject of an object id (MoveIt removes everything with that id)."""
    obj = CollisionObject(id=obj_id, operation=CollisionObject.REMOVE)
    obj.header.frame_id = frame_id
    return obj


def _moved(a: Pose, b: Pose, tolerance: float) -> bool:
    pa, pb, qa, qb = a.position, b.position, a.orientation, b.orientation
    if math.dist((pa.x, pa.y, pa.z), (pb.x, pb.y, pb.z)) > tolerance:
        return True
    dot = min(1.0, abs(qa.x * qb.x + qa.y * qb.y + qa.z * qb.z + qa.w * qb.w))
    return 2 * math.acos(dot) > tolerance


def changes(sent: Mapping[str, CollisionObject], current: Mapping[str, CollisionObject], frame_id: str,
            tolerance: float = MOVE_TOLERANCE) -> list[CollisionObject]:
    """What to publish to bring MoveIt from `sent` (object id -> what it was last sent) to `current`:
    the ADD of every object that is new, changed its frame or boxes, or moved by more than
    `tolerance` (m or rad; motion-capture jitter below it is not resent), then a REMOVE for every
    object of `sent` that `current` lacks. ADD replaces an object MoveIt has."""
    out = []
    for oid, obj in current.items():
        old = sent.get(oid)
        if (old is None or old.header.frame_id != obj.header.frame_id or old.primitives != obj.primitives
                or old.primitive_poses != obj.primitive_poses or _moved(old.pose, obj.pose, tolerance)):
            out.append(obj)
    out.extend(remove_object(oid, frame_id) for oid in sent if oid not in current)
    return out

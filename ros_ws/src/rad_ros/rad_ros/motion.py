"""Trajectory and motion-capture message conversions (message types only, no rclpy).

Trajectories travel inside rad_core as plain dicts of the result.json shape:
{"joint_names": [...], "points": [{"positions", "velocities", "time_from_start"}]}.
"""

from __future__ import annotations

import math

from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from rad_msgs.msg import RigidBodies, RigidBody
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def duration_to_s(d: Duration) -> float:
    return d.sec + d.nanosec * 1e-9


def s_to_duration(seconds: float) -> Duration:
    if not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f'time_from_start must be a finite, non-negative number, got {seconds}')
    sec = int(math.floor(seconds))
    nanosec = int(round((seconds - sec) * 1e9))
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return Duration(sec=sec, nanosec=nanosec)


def trajectory_to_msg(traj: dict, frame_id: str = '') -> JointTrajectory:
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.joint_names = list(traj['joint_names'])
    for p in traj['points']:
        point = JointTrajectoryPoint(positions=[float(v) for v in p['positions']],
                                     velocities=[float(v) for v in p.get('velocities', [])])
        point.time_from_start = s_to_duration(float(p['time_from_start']))
        msg.points.append(point)
    return msg


def trajectory_from_msg(msg: JointTrajectory) -> dict:
    """The dict form; no validation here (the executor validates before it moves)."""
    return {'joint_names': list(msg.joint_names),
            'points': [{'positions': list(p.positions), 'velocities': list(p.velocities),
                        'time_from_start': duration_to_s(p.time_from_start)} for p in msg.points]}


def pose_msg(position, quaternion) -> Pose:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def pose_from_msg(pose: Pose) -> tuple[list[float], list[float]]:
    p, q = pose.position, pose.orientation
    return [p.x, p.y, p.z], [q.x, q.y, q.z, q.w]


def rigid_bodies_msg(bodies, frame_number: int, stamp, frame_id: str) -> RigidBodies:
    """bodies: objects with name, position, quaternion, tracking_valid (sim.mocap.RigidBodyPose)."""
    msg = RigidBodies(frame_number=int(frame_number))
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.rigidbodies = [RigidBody(rigid_body_name=b.name, pose=pose_msg(b.position, b.quaternion),
                                 tracking_valid=bool(b.tracking_valid)) for b in bodies]
    return msg


def pose_stamped(body, stamp, frame_id: str) -> PoseStamped:
    msg = PoseStamped(pose=pose_msg(body.position, body.quaternion))
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    return msg

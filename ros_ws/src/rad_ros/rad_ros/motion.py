"""Trajectory, motion and motion-capture message conversions (message types only, no rclpy).

Trajectories travel inside rad_core as plain dicts of the result.json shape:
{"joint_names": [...], "points": [{"positions", "velocities", "accelerations", "time_from_start"}]};
a step's motion as {"trajectories": [...], "gripper": [...]} (`rad_core.cell.motion.Motion`).
"""

from __future__ import annotations

import math

from builtin_interfaces.msg import Duration
from control_msgs.msg import GripperCommand
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from rad_core.cell.motion import VACUUM_ACTIONS
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import yaw_of_quaternion, yaw_quaternion
from rad_msgs.msg import GripperStep, RigidBodies, RigidBody
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
                                     velocities=[float(v) for v in p.get('velocities') or []],
                                     accelerations=[float(v) for v in p.get('accelerations') or []])
        point.time_from_start = s_to_duration(float(p['time_from_start']))
        msg.points.append(point)
    return msg


def trajectory_from_msg(msg: JointTrajectory) -> dict:
    """The dict form; no validation here (the executor validates before it moves)."""
    return {'joint_names': list(msg.joint_names),
            'points': [{'positions': list(p.positions), 'velocities': list(p.velocities),
                        'accelerations': list(p.accelerations),
                        'time_from_start': duration_to_s(p.time_from_start)} for p in msg.points]}


def motion_to_msgs(motion: dict, frame_id: str = '') -> tuple[list[JointTrajectory], list[GripperStep]]:
    """A motion's arm trajectories and gripper steps as messages (a PlanStep's or PlanAction's fields)."""
    gripper = [GripperStep(before=int(g['before']), action=str(g['action']),
                           command=GripperCommand(position=float(g['position']), max_effort=float(g['max_effort'])),
                           expected_position=float(g.get('expected_position', math.nan)),
                           vacuum=int(g.get('vacuum', 0)), timeout_ms=int(g.get('timeout_ms', 0)))
               for g in motion.get('gripper') or []]
    return [trajectory_to_msg(t, frame_id) for t in motion['trajectories']], gripper


def motion_from_msgs(trajectories, gripper) -> dict:
    """The inverse of `motion_to_msgs` (no validation: `rad_core.cell.motion.Motion.from_dict` checks)."""
    steps = []
    for g in gripper:
        d = {'before': g.before, 'action': g.action, 'position': g.command.position,
             'max_effort': g.command.max_effort}
        if math.isfinite(g.expected_position):
            d['expected_position'] = g.expected_position
        if g.action in VACUUM_ACTIONS:
            d.update(vacuum=int(g.vacuum), timeout_ms=int(g.timeout_ms))
        steps.append(d)
    return {'trajectories': [trajectory_from_msg(t) for t in trajectories], 'gripper': steps}


def pose_msg(position, quaternion) -> Pose:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def pose_from_msg(pose: Pose) -> tuple[list[float], list[float]]:
    p, q = pose.position, pose.orientation
    return [p.x, p.y, p.z], [q.x, q.y, q.z, q.w]


def moved_aside_to_msgs(moved_aside) -> tuple[list[str], list[Pose]]:
    """Blocks moved aside ({'block', 'position', 'yaw'} in order) as the moved_aside_blocks and
    moved_aside_poses fields of PlanAction's response and of PlanStep."""
    return ([str(d['block']) for d in moved_aside],
            [pose_msg(d['position'], yaw_quaternion(d['yaw'])) for d in moved_aside])


def moved_aside_from_msgs(blocks, poses) -> list[dict]:
    """The inverse of `moved_aside_to_msgs` (yaws to whole degrees)."""
    if len(blocks) != len(poses):
        raise RadError(f'{len(blocks)} moved-aside blocks but {len(poses)} poses')
    out = []
    for block, pose in zip(blocks, poses):
        position, quaternion = pose_from_msg(pose)
        out.append({'block': str(block), 'position': [round(v, 6) for v in position],
                    'yaw': int(round(yaw_of_quaternion(quaternion))) % 360})
    return out


def rigid_bodies_msg(bodies, frame_number: int, stamp, frame_id: str) -> RigidBodies:
    """bodies: objects with name, position, quaternion, tracking_valid (cell.mocap.RigidBodyPose)."""
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

"""Motion capture in the three forms drivers publish it, fed into a rad_core MocapTracker.

  mocap_input 'rad'           rad_msgs/RigidBodies on mocap_topic: the twin's (tracking_valid per body)
              'mocap4r2'      mocap4r2_msgs/RigidBodies on mocap_topic: the mocap4r2 drivers (OptiTrack,
                              Vicon, Qualisys...); a body listed in a frame is tracked in it
              'pose_stamped'  one geometry_msgs/PoseStamped per body on pose_topic, '{body}' replaced by
                              the body's name: natnet_ros2 ('/natnet_ros/{body}/pose') and vrpn_mocap
                              ('/vrpn_mocap/{body}/pose'); a body is seen while its poses keep coming

Every message's frame_id is checked by the tracker (a refused message is logged, at most every
few seconds, and named when a registration then fails). The conversion functions take message
types only, so they are tested without DDS; `MocapInput` only adds the subscriptions.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable

from geometry_msgs.msg import PoseStamped, TransformStamped
from rad_core.cell.mocap import RigidBodyPose
from rad_core.cell.mocap_input import MocapFrames, MocapTracker
from rad_core.domain.errors import RadError
from rclpy.qos import qos_profile_sensor_data
from tf2_msgs.msg import TFMessage

from rad_ros.motion import pose_from_msg

MOCAP_INPUTS = ('rad', 'mocap4r2', 'pose_stamped')


def bodies_from_rad(msg) -> list[RigidBodyPose]:
    """rad_msgs/RigidBodies -> rigid bodies (tracking_valid as reported)."""
    return [RigidBodyPose(b.rigid_body_name, *pose_from_msg(b.pose), bool(b.tracking_valid)) for b in msg.rigidbodies]


def bodies_from_mocap4r2(msg) -> list[RigidBodyPose]:
    """mocap4r2_msgs/RigidBodies -> rigid bodies. mocap4r2 has no tracking flag: a listed body is tracked
    (a NaN pose, some drivers' way of saying lost, counts as not seen in the tracker)."""
    return [RigidBodyPose(b.rigid_body_name, *pose_from_msg(b.pose), True) for b in msg.rigidbodies]


def body_from_pose_stamped(name: str, msg: PoseStamped) -> RigidBodyPose:
    return RigidBodyPose(name, *pose_from_msg(msg.pose), True)


def body_topic(pattern: str, body: str) -> str:
    if '{body}' not in pattern:
        raise RadError(f"pose_topic {pattern!r} must contain '{{body}}' (e.g. '/natnet_ros/{{body}}/pose')")
    return pattern.replace('{body}', body)


def calibration_tf(frames: MocapFrames, stamp) -> TFMessage:
    """/tf_static's message for the calibration: parent frame_id (the base), child mocap_frame."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = frames.frame_id
    t.child_frame_id = frames.mocap_frame
    tx, ty, tz = frames.transform.translation
    qx, qy, qz, qw = frames.transform.quaternion
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = tx, ty, tz
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = qx, qy, qz, qw
    return TFMessage(transforms=[t])


class MocapInput:
    """The subscriptions of one mocap_input mode on `node`, feeding `tracker`."""

    def __init__(self, node, tracker: MocapTracker, mode: str, mocap_topic: str, pose_topic: str):
        if mode not in MOCAP_INPUTS:
            raise RadError(f'mocap_input must be one of {", ".join(MOCAP_INPUTS)}, got {mode!r}')
        self.node, self.tracker, self.mode = node, tracker, mode
        self.pose_topic = pose_topic
        self.lock = threading.Lock()
        self.watched: dict[str, object] = {}
        if mode == 'pose_stamped':
            body_topic(pose_topic, 'x')          # checks the pattern at start
            return
        if mode == 'rad':
            from rad_msgs.msg import RigidBodies
            convert = bodies_from_rad
        else:
            from mocap4r2_msgs.msg import RigidBodies
            convert = bodies_from_mocap4r2
        sub = node.create_subscription(RigidBodies, mocap_topic, lambda msg: self.frame_callback(msg, convert),
                                       qos_profile_sensor_data)
        self.source = f'{sub.topic_name} ({mode})'

    def frame_callback(self, msg, convert) -> None:
        try:
            self.tracker.frame(msg.header.frame_id, convert(msg), source=self.source)
        except RadError as e:
            self.node.get_logger().warning(f'motion capture refused: {e}', throttle_duration_sec=5.0)

    def pose_callback(self, name: str, source: str, msg: PoseStamped) -> None:
        try:
            self.tracker.pose(msg.header.frame_id, body_from_pose_stamped(name, msg), source=source)
        except RadError as e:
            self.node.get_logger().warning(f'motion capture refused: {e}', throttle_duration_sec=5.0)

    def watch(self, bodies: Iterable[str]) -> None:
        """pose_stamped: subscribe to each body's topic (once); other modes hear every body already."""
        if self.mode != 'pose_stamped':
            return
        with self.lock:
            for name in bodies:
                if name in self.watched:
                    continue
                topic = body_topic(self.pose_topic, name)
                try:
                    sub = self.node.create_subscription(PoseStamped, topic, lambda msg, n=name, s=topic:
                                                        self.pose_callback(n, s, msg), qos_profile_sensor_data)
                except Exception as e:  # noqa: BLE001 - rclpy's InvalidTopicNameException and kin
                    self.watched[name] = None
                    self.node.get_logger().error(f'rigid body {name!r}: cannot subscribe to {topic!r} '
                                                 f'(pose_topic {self.pose_topic!r}): {str(e).splitlines()[0]}')
                    continue
                self.watched[name] = sub

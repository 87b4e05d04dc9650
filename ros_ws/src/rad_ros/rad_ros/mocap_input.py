"""Motion capture in the forms drivers publish it, fed into a rad_core MocapTracker.

  mocap_input 'rad'           rad_msgs/RigidBodies on mocap_topic: the twin's (tracking_valid per body)
              'mocap4r2'      mocap4r2_msgs/RigidBodies on mocap_topic: the mocap4r2 drivers (OptiTrack,
                              Vicon, Qualisys...); a body listed in a frame is tracked in it
              'pose_stamped'  one geometry_msgs/PoseStamped per body on pose_topic, '{body}' replaced by
                              the body's name (natnet_ros2, vrpn_mocap, aruco_ros); a body is seen while
                              its poses keep coming
              'tf'            tf2_msgs/TFMessage on mocap_topic (/tf): each transform whose child frame is
                              a watched body is that body's pose in its parent frame (apriltag_ros
                              broadcasts camera frame -> '<family>:<id>' per detected tag)

`mocap_driver` picks all of it at once from DRIVERS (the input, its topics, the frame the driver reports in
by default); each is overridable by its own parameter. Every message's frame_id is checked by the tracker
(a refused message is logged, at most every few seconds, and named when a registration then fails). The
conversion functions take message types only, so they are tested without DDS; `MocapInput` only adds the
subscriptions.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from dataclasses import dataclass

from geometry_msgs.msg import PoseStamped, TransformStamped
from rad_core.cell.mocap import RigidBodyPose
from rad_core.cell.mocap_input import MocapFrames, MocapTracker
from rad_core.domain.errors import RadError
from rclpy.qos import qos_profile_sensor_data
from tf2_msgs.msg import TFMessage

from rad_ros.motion import pose_from_msg

MOCAP_INPUTS = ('rad', 'mocap4r2', 'pose_stamped', 'tf')


@dataclass(frozen=True)
class Driver:
    """What one motion-capture driver publishes, as it publishes it by default."""

    input: str
    mocap_topic: str
    pose_topic: str
    frame: str
    """The frame_id its messages carry by default ('' = the base frame: only the twin)."""
    about: str


DRIVERS = {
    'rad': Driver('rad', 'rigid_bodies', 'mocap/{body}/pose', '',
                  "the twin's rad_msgs/RigidBodies, in the base frame unless its mocap_frame says otherwise"),
    'mocap4r2_optitrack': Driver('mocap4r2', '/rigid_bodies', '', 'map',
                                 'mocap4r2_optitrack_driver: mocap4r2_msgs/RigidBodies on /rigid_bodies, bodies '
                                 "named by Motive ID ('1', '2', ...), frame 'map'; a lifecycle node: configure and "
                                 'activate it'),
    'natnet_ros2': Driver('pose_stamped', '', '/natnet_ros2/{body}/pose', 'world',
                          "natnet_ros2: PoseStamped per body on /natnet_ros2/<name in Motive>/pose, frame "
                          "global_frame ('world'); a lifecycle node: configure and activate it"),
    'vrpn_mocap': Driver('pose_stamped', '', '/vrpn_mocap/{body}/pose', 'world',
                         "vrpn_mocap: PoseStamped per tracker on /vrpn_mocap/<tracker>/pose, frame frame_id ('world')"),
    'fiducial_tags': Driver('tf', '/tf', '', '',
                            "a camera and fiducial tags: apriltag_ros's transforms camera -> '<family>:<id>' on /tf "
                            "(or mocap_input pose_stamped: a PoseStamped per tag); mocap_frame: the camera's frame"),
}


@dataclass(frozen=True)
class Source:
    """A driver's settings with the node's overrides applied."""

    driver: str
    input: str
    mocap_topic: str
    pose_topic: str
    frame: str


def resolve_driver(driver: str, mocap_input: str = '', mocap_topic: str = '', pose_topic: str = '',
                   mocap_frame: str = '') -> Source:
    """The driver's input, topics and frame, each replaced by its parameter where that is not ''; RadError
    naming the choices for an unknown driver or input."""
    if driver not in DRIVERS:
        raise RadError(f'mocap_driver must be one of {", ".join(DRIVERS)}, got {driver!r}')
    d = DRIVERS[driver]
    chosen = mocap_input or d.input
    if chosen not in MOCAP_INPUTS:
        raise RadError(f'mocap_input must be one of {", ".join(MOCAP_INPUTS)} (or \'\' for the driver\'s), '
                       f'got {chosen!r}')
    topic = mocap_topic or d.mocap_topic or {'tf': '/tf'}.get(chosen, 'rigid_bodies')
    poses = pose_topic or d.pose_topic or 'mocap/{body}/pose'
    return Source(driver, chosen, topic, poses, mocap_frame or d.frame)


def bodies_from_rad(msg) -> list[RigidBodyPose]:
    """rad_msgs/RigidBodies -> rigid bodies (tracking_valid as reported)."""
    return [RigidBodyPose(b.rigid_body_name, *pose_from_msg(b.pose), bool(b.tracking_valid)) for b in msg.rigidbodies]


def bodies_from_mocap4r2(msg) -> list[RigidBodyPose]:
    """mocap4r2_msgs/RigidBodies -> rigid bodies. mocap4r2 has no tracking flag: a listed body is tracked
    (a NaN pose, some drivers' way of saying lost, counts as not seen in the tracker)."""
    return [RigidBodyPose(b.rigid_body_name, *pose_from_msg(b.pose), True) for b in msg.rigidbodies]


def body_from_pose_stamped(name: str, msg: PoseStamped) -> RigidBodyPose:
    return RigidBodyPose(name, *pose_from_msg(msg.pose), True)


def bodies_from_tf(msg, watched) -> list[tuple[str, RigidBodyPose]]:
    """tf2_msgs/TFMessage -> (parent frame, body) for each transform whose child frame is a watched body
    (/tf carries every frame of the cell: the others are not motion capture)."""
    out = []
    for t in msg.transforms:
        if t.child_frame_id in watched:
            tr, q = t.transform.translation, t.transform.rotation
            out.append((t.header.frame_id, RigidBodyPose(t.child_frame_id, (tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w),
                                                         True)))
    return out


def body_topic(pattern: str, body: str) -> str:
    if '{body}' not in pattern:
        raise RadError(f"pose_topic {pattern!r} must contain '{{body}}' (e.g. '/natnet_ros2/{{body}}/pose')")
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
    """The subscriptions of one source (`resolve_driver`) on `node`, feeding `tracker`."""

    def __init__(self, node, tracker: MocapTracker, source: Source):
        mode = source.input
        self.node, self.tracker, self.mode = node, tracker, mode
        self.pose_topic = source.pose_topic
        self.lock = threading.Lock()
        self.watched: dict[str, object] = {}
        self.tf_bodies: frozenset[str] = frozenset()
        if mode == 'pose_stamped':
            body_topic(self.pose_topic, 'x')          # checks the pattern at start
            self.source = self.pose_topic
            return
        if mode == 'tf':
            sub = node.create_subscription(TFMessage, source.mocap_topic, self.tf_callback, 100)
            self.source = f'{sub.topic_name} (tf)'
            return
        if mode == 'rad':
            from rad_msgs.msg import RigidBodies
            convert = bodies_from_rad
        else:
            from mocap4r2_msgs.msg import RigidBodies
            convert = bodies_from_mocap4r2
        sub = node.create_subscription(RigidBodies, source.mocap_topic, lambda msg: self.frame_callback(msg, convert),
                                       qos_profile_sensor_data)
        self.source = f'{sub.topic_name} ({mode})'

    def refused(self, e: RadError) -> None:
        self.node.get_logger().warning(f'motion capture refused: {e}', throttle_duration_sec=5.0)

    def frame_callback(self, msg, convert) -> None:
        try:
            self.tracker.frame(msg.header.frame_id, convert(msg), source=self.source)
        except RadError as e:
            self.refused(e)

    def pose_callback(self, name: str, source: str, msg: PoseStamped) -> None:
        try:
            self.tracker.pose(msg.header.frame_id, body_from_pose_stamped(name, msg), source=source)
        except RadError as e:
            self.refused(e)

    def tf_callback(self, msg: TFMessage) -> None:
        for parent, body in bodies_from_tf(msg, self.tf_bodies):
            try:
                self.tracker.pose(parent, body, source=f'{self.source}: {parent} -> {body.name}')
            except RadError as e:
                self.refused(e)

    def watch(self, bodies: Iterable[str]) -> None:
        """pose_stamped: subscribe to each body's topic (once); tf: take these child frames as bodies; the
        other modes hear every body already."""
        if self.mode == 'tf':
            with self.lock:
                self.tf_bodies = self.tf_bodies | frozenset(bodies)
            return
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

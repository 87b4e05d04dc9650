"""Motion capture as each driver really publishes it, from recorded bags (rad_ros.bag), into rad_ros.mocap_input.

For each preset of `mocap_driver` the test writes a small MCAP bag of messages in that driver's format, on its
real topics and in its default frame (the task's blocks seen through a calibration), plays it over DDS into a
MocapInput built from the preset alone, and checks that every block registers where it is in the base frame;
a bag in another frame is refused with a reason naming both frames. Also: the calibration's and the twin's
transforms on /tf_static hang the motion-capture frame and the robot from the base frame (one tree)."""

import threading

import numpy as np
import pytest
from rad_core.cell.mocap import RegistrationConfig, register_scene, scene_to_bodies
from rad_core.cell.mocap_input import BodyMap, FrameTransform, MocapFrames, MocapTracker
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_quaternion
from ros_harness import spin_until

from scenes import doc

TASK = Scene.from_dict(doc())                       # c0, c1 (cubes), i0 (I2 at yaw 90)
CAL = FrameTransform((0.35, -0.12, 0.74), yaw_quaternion(90))    # the driver's frame -> base
BLOCKS = {b.id: b.type for b in TASK.blocks}

# How each driver names the task's bodies (body map: name -> block), and the frame it stamps by default.
NAMES = {
    'mocap4r2_optitrack': {'1': 'c0', '2': 'c1', '3': 'i0'},              # Motive IDs
    'natnet_ros2': {'Block_0': 'c0', 'Block_1': 'c1', 'Long': 'i0'},      # Motive names
    'vrpn_mocap': {'c0': 'c0', 'c1': 'c1', 'i0': 'i0'},                   # trackers named like the blocks
    'fiducial_tags': {'tag36h11:0': 'c0', 'tag36h11:1': 'c1', 'tag36h11:7': 'i0'},   # apriltag_ros frames
}
CAMERA = 'camera_color_optical_frame'


def driver_frame(driver: str) -> str:
    return CAMERA if driver == 'fiducial_tags' else {'mocap4r2_optitrack': 'map'}.get(driver, 'world')


def body_map(driver: str) -> BodyMap:
    import yaml
    names = NAMES[driver]
    text = 'bodies:\n' + ''.join(f'  {n if n.isdigit() else repr(n)}: {{block: {b}}}\n' for n, b in names.items())
    return BodyMap.from_dict(yaml.safe_load(text))          # numeric IDs as YAML writes them: 1: {block: c0}


def driver_poses(driver: str):
    """(name, position, quaternion) of each body in the driver's frame."""
    inverse = CAL.inverse()
    by_block = {b: n for n, b in NAMES[driver].items()}
    return [(by_block[b.name], *inverse.apply(b.position, b.quaternion)) for b in scene_to_bodies(TASK)]


def driver_messages(driver: str, frame: str, stamp):
    """[(topic, type, message)] of one motion-capture frame as the driver publishes it."""
    from geometry_msgs.msg import PoseStamped, TransformStamped
    from rad_ros.motion import pose_msg
    poses = driver_poses(driver)
    if driver == 'mocap4r2_optitrack':
        from mocap4r2_msgs.msg import RigidBodies, RigidBody
        msg = RigidBodies(frame_number=1)
        msg.header.frame_id, msg.header.stamp = frame, stamp
        msg.rigidbodies = [RigidBody(rigid_body_name=n, pose=pose_msg(p, q)) for n, p, q in poses]
        msg.rigidbodies.append(RigidBody(rigid_body_name='9', pose=pose_msg((0.0, 0.0, 0.0), (0, 0, 0, 1))))
        return [('/rigid_bodies', 'mocap4r2_msgs/msg/RigidBodies', msg)]
    if driver == 'fiducial_tags':
        from tf2_msgs.msg import TFMessage
        out = TFMessage()
        for n, p, q in poses:
            t = TransformStamped(child_frame_id=n)
            t.header.frame_id, t.header.stamp = frame, stamp
            t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = p
            t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = q
            out.transforms.append(t)
        other = TransformStamped(child_frame_id='fr3_link1')            # /tf carries the robot's frames too
        other.header.frame_id, other.header.stamp = 'fr3_link0', stamp
        other.transform.rotation.w = 1.0
        out.transforms.append(other)
        return [('/tf', 'tf2_msgs/msg/TFMessage', out)]
    prefix = {'natnet_ros2': '/natnet_ros2', 'vrpn_mocap': '/vrpn_mocap'}[driver]
    out = []
    for n, p, q in poses:
        msg = PoseStamped(pose=pose_msg(p, q))
        msg.header.frame_id, msg.header.stamp = frame, stamp
        out.append((f'{prefix}/{n}/pose', 'geometry_msgs/msg/PoseStamped', msg))
    return out


def write_bag(path, driver: str, frame: str, clock, frames: int = 40, period_ns: int = 20_000_000):
    """The driver's messages at 50 Hz for frames / 50 s (reliable, as natnet_ros2 and vrpn_mocap offer)."""
    from rad_ros.bag import BagWriter, qos_profiles_yaml
    from rclpy.qos import QoSProfile
    from rclpy.serialization import serialize_message
    writer = BagWriter(path)
    t0 = clock.now().nanoseconds
    for k in range(frames):
        t = t0 + k * period_ns
        from builtin_interfaces.msg import Time
        stamp = Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)
        for topic, type_name, msg in driver_messages(driver, frame, stamp):
            writer.add_topic(topic, type_name, qos_profiles_yaml([QoSProfile(depth=100)]))
            writer.write(topic, serialize_message(msg), t)
    writer.close()
    return path


def play_into(ros_node, bag, source, frames: MocapFrames, bodies: BodyMap):
    """Play `bag` over DDS into a MocapInput of `source` on ros_node; the tracker and the resolved bodies."""
    import rclpy
    from rad_ros.bag import PlayOptions, play
    from rad_ros.mocap_input import MocapInput
    tracker = MocapTracker(frames, lost_timeout_s=10.0)
    mocap = MocapInput(ros_node, tracker, source)
    resolved = bodies.resolve(BLOCKS)
    mocap.watch(resolved.by_body)
    player = rclpy.create_node('bag_player')
    done = threading.Event()
    thread = threading.Thread(target=lambda: (play(player, bag, PlayOptions(delay_s=1.0)), done.set()), daemon=True)
    thread.start()
    spin_until(ros_node, done.is_set, timeout=20.0)
    spin_until(ros_node, lambda: False, timeout=0.2)
    thread.join(timeout=5.0)
    player.destroy_node()
    return tracker, resolved


@pytest.mark.parametrize('driver', sorted(NAMES))
def test_a_drivers_recorded_messages_register_every_block_in_the_base_frame(ros_node, tmp_path, driver):
    from rad_ros.mocap_input import DRIVERS, resolve_driver
    frame = driver_frame(driver)
    source = resolve_driver(driver, mocap_frame=CAMERA if driver == 'fiducial_tags' else '')
    assert source.frame == frame, (driver, source)           # the preset's frame is the driver's default
    assert source.input == DRIVERS[driver].input
    bag = write_bag(tmp_path / f'{driver}.mcap', driver, frame, ros_node.get_clock())
    tracker, resolved = play_into(ros_node, bag, source, MocapFrames('base', source.frame, CAL), body_map(driver))
    assert tracker.refused is None, tracker.refused
    snap = tracker.snapshot(resolved)
    assert {resolved.by_body[b.name].block for b in snap.bodies} == set(BLOCKS), snap
    registered = register_scene(snap.bodies, TASK, RegistrationConfig(body_map=resolved.registration_map))
    assert registered.to_dict()['blocks'] == TASK.to_dict()['blocks'], driver
    expected = {b.name: b for b in scene_to_bodies(TASK)}
    for b in snap.bodies:
        block = resolved.by_body[b.name].block
        assert np.allclose(b.position, expected[block].position, atol=1e-6), (driver, block)


@pytest.mark.parametrize('driver, stamped', [('mocap4r2_optitrack', 'world'), ('natnet_ros2', 'optitrack'),
                                             ('fiducial_tags', 'camera_link')])
def test_a_bag_in_another_frame_than_the_driver_reports_in_is_refused_naming_both(ros_node, tmp_path, driver,
                                                                                  stamped):
    from rad_ros.mocap_input import resolve_driver
    source = resolve_driver(driver, mocap_frame=CAMERA if driver == 'fiducial_tags' else '')
    bag = write_bag(tmp_path / 'wrong.mcap', driver, stamped, ros_node.get_clock(), frames=10)
    tracker, resolved = play_into(ros_node, bag, source, MocapFrames('base', source.frame, CAL), body_map(driver))
    assert tracker.refused is not None, 'nothing refused'
    reason = tracker.refused[1]
    assert f"in frame {stamped!r}, expected {source.frame!r}" in reason, reason
    with pytest.raises(RadError, match='was refused'):
        tracker.snapshot(resolved, now=tracker.clock() + 60.0)


def test_presets_are_overridable_and_unknown_ones_refused():
    from rad_ros.mocap_input import resolve_driver
    natnet = resolve_driver('natnet_ros2')
    assert (natnet.input, natnet.pose_topic, natnet.frame) == ('pose_stamped', '/natnet_ros2/{body}/pose', 'world')
    vrpn = resolve_driver('vrpn_mocap')
    assert (vrpn.input, vrpn.pose_topic, vrpn.frame) == ('pose_stamped', '/vrpn_mocap/{body}/pose', 'world')
    m4r2 = resolve_driver('mocap4r2_optitrack')
    assert (m4r2.input, m4r2.mocap_topic, m4r2.frame) == ('mocap4r2', '/rigid_bodies', 'map')
    tags = resolve_driver('fiducial_tags', mocap_frame=CAMERA)
    assert (tags.input, tags.mocap_topic, tags.frame) == ('tf', '/tf', CAMERA)
    aruco = resolve_driver('fiducial_tags', 'pose_stamped', pose_topic='/aruco_{body}/pose', mocap_frame=CAMERA)
    assert (aruco.input, aruco.pose_topic) == ('pose_stamped', '/aruco_{body}/pose')
    twin = resolve_driver('rad')
    assert (twin.input, twin.mocap_topic, twin.frame) == ('rad', 'rigid_bodies', '')
    assert resolve_driver('natnet_ros2', mocap_frame='optitrack').frame == 'optitrack'
    with pytest.raises(RadError, match='mocap_driver must be one of rad, mocap4r2_optitrack, natnet_ros2'):
        resolve_driver('natnet_ros')
    with pytest.raises(RadError, match="mocap_input must be one of .* got 'poses'"):
        resolve_driver('rad', 'poses')


def test_the_tf_tree_hangs_motion_capture_and_the_robot_from_the_base():
    from rad_ros.mocap_input import calibration_tf
    from rad_sim.twin_node import base_tf
    (t,) = calibration_tf(MocapFrames('base', 'optitrack', CAL), None).transforms
    assert (t.header.frame_id, t.child_frame_id) == ('base', 'optitrack')
    assert np.allclose([t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
                       CAL.translation)
    assert np.allclose([t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
                        t.transform.rotation.w], CAL.quaternion)
    (r,) = base_tf('base', 'fr3_link0', None).transforms
    assert (r.header.frame_id, r.child_frame_id, r.transform.rotation.w) == ('base', 'fr3_link0', 1.0)

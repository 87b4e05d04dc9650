"""The rad_sim twin node as a plant, over real DDS: topics, actions, services, bad input."""

import json
import math
import time

import numpy as np
import pytest
import rclpy
from rad_core.cell.panda import FINGER_OPEN, HOME, JOINT_NAMES
from rad_core.cell.robot_model import PANDA
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.gamp.trajectory import retime
from rclpy.action import ActionClient
from ros_harness import call_service, ros_args, spin_until, wait_for_service

from scenes import doc

TRAJ_TOPIC = 'joint_trajectory_controller/joint_trajectory'
ARM_ACTION = 'joint_trajectory_controller/follow_joint_trajectory'
GRIPPER_ACTION = 'franka_gripper/gripper_action'
ARM_NAMES = list(JOINT_NAMES[:7])          # panda_joint1..7: all the arm controller takes
HOME_ARM = np.asarray(HOME[:7], dtype=float)
RTF = 4.0


@pytest.fixture
def twin(node_process, ros_node, tmp_path):
    """A twin node with a generated scene, and helpers to talk to it."""
    from control_msgs.action import FollowJointTrajectory, GripperCommand
    from rad_msgs.msg import RigidBodies
    from rad_msgs.srv import GetSceneState, LoadScene
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from trajectory_msgs.msg import JointTrajectory

    scene = generate_scene(GeneratorConfig(grid=3), 5)
    path = tmp_path / 'scene.json'
    path.write_text(scene.dumps())
    proc = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path), 'real_time_factor': RTF}))
    seen = {'joints': [], 'bodies': [], 'events': []}
    ros_node.create_subscription(JointState, 'joint_states', seen['joints'].append, 10)
    ros_node.create_subscription(RigidBodies, 'rigid_bodies', seen['bodies'].append, qos_profile_sensor_data)
    events = ros_node.create_subscription(String, 'twin/events', lambda m: seen['events'].append(json.loads(m.data)),
                                          10)
    pub = ros_node.create_publisher(JointTrajectory, TRAJ_TOPIC, 10)
    state_client = wait_for_service(ros_node, GetSceneState, 'get_scene_state', timeout=30.0)
    load_client = wait_for_service(ros_node, LoadScene, 'load_scene', timeout=10.0)
    arm = ActionClient(ros_node, FollowJointTrajectory, ARM_ACTION)
    gripper = ActionClient(ros_node, GripperCommand, GRIPPER_ACTION)
    assert arm.wait_for_server(timeout_sec=10.0) and gripper.wait_for_server(timeout_sec=10.0)
    spin_until(ros_node, lambda: seen['joints'] and seen['bodies'], timeout=15.0)
    # Topics are not latched: a trajectory published, or an event sent, before the endpoints have
    # matched is lost (seen once in CI: nothing arrived in 20 s).
    assert spin_until(ros_node, lambda: pub.get_subscription_count() > 0 and events.get_publisher_count() > 0,
                      timeout=15.0)

    class Twin:
        pass
    t = Twin()
    t.proc, t.scene, t.seen, t.pub, t.node, t.arm, t.gripper = proc, scene, seen, pub, ros_node, arm, gripper
    t.state = lambda: call_service(ros_node, state_client, GetSceneState.Request(), timeout=10.0)
    t.load = lambda req: call_service(ros_node, load_client, req, timeout=10.0)
    yield t
    assert proc.stop() == 0, proc.output_tail()


def trajectory(points, names=JOINT_NAMES):
    from rad_ros.motion import trajectory_to_msg
    return trajectory_to_msg({'joint_names': list(names), 'points': [
        {'positions': list(p), 'velocities': [], 'time_from_start': t} for t, p in points]})


def retimed(target, start=HOME_ARM, speed_scale=0.5) -> dict:
    """A trajectory from `start` to `target` (7 arm joints) within the Panda's limits x speed_scale, as a dict."""
    return retime([np.asarray(start, dtype=float), np.asarray(target, dtype=float)], PANDA, speed_scale).to_dict()


def time_scaled(traj: dict, factor: float) -> dict:
    """The same path `factor` times as long (velocities and accelerations scaled to match)."""
    return {'joint_names': traj['joint_names'], 'points': [
        {'positions': p['positions'], 'velocities': [v / factor for v in p['velocities']],
         'accelerations': [a / factor ** 2 for a in p['accelerations']],
         'time_from_start': p['time_from_start'] * factor} for p in traj['points']]}


def arm_target(**offsets) -> np.ndarray:
    """HOME's arm joints with offsets, e.g. arm_target(j1=0.3)."""
    q = HOME_ARM.copy()
    for name, delta in offsets.items():
        q[int(name[1:]) - 1] += delta
    return q


def fresh_messages(t, key: str, count: int = 1, timeout: float = 5.0):
    """The next `count` messages of t.seen[key] published from now on.

    Messages still queued in the subscription from before the call (a loaded machine delivers them
    late) are skipped by their stamp: the twin stamps with the same system clock as this node."""
    now = t.node.get_clock().now().nanoseconds

    def fresh():
        return [m for m in t.seen[key] if m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec >= now]

    t.seen[key].clear()
    assert spin_until(t.node, lambda: len(fresh()) >= count, timeout=timeout), f'no fresh {key} messages'
    return fresh()


def fresh_joint_states(t, count: int = 1, timeout: float = 5.0):
    """The next `count` joint_states messages published from now on."""
    return fresh_messages(t, 'joints', count, timeout)


def send_arm_goal(t, traj, timeout: float = 10.0):
    """Send a FollowJointTrajectory goal (traj: dict or JointTrajectory); return the goal handle."""
    from control_msgs.action import FollowJointTrajectory
    from rad_ros.motion import trajectory_to_msg
    goal = FollowJointTrajectory.Goal()
    goal.trajectory = trajectory_to_msg(traj) if isinstance(traj, dict) else traj
    sent = t.arm.send_goal_async(goal)
    rclpy.spin_until_future_complete(t.node, sent, timeout_sec=timeout)
    assert sent.done(), 'the twin did not answer the goal'
    handle = sent.result()
    assert handle.accepted, 'the arm goal was rejected (goals are accepted, then aborted when bad)'
    return handle


def result_of(t, handle, timeout: float):
    """(status, result) of a goal, spinning the test node until it ends."""
    done = handle.get_result_async()
    rclpy.spin_until_future_complete(t.node, done, timeout_sec=timeout)
    assert done.done(), f'no result within {timeout} s'
    return done.result().status, done.result().result


def gripper_goal(t, position: float, max_effort: float = 20.0, timeout: float = 20.0):
    from control_msgs.action import GripperCommand
    goal = GripperCommand.Goal()
    goal.command.position, goal.command.max_effort = float(position), float(max_effort)
    sent = t.gripper.send_goal_async(goal)
    rclpy.spin_until_future_complete(t.node, sent, timeout_sec=10.0)
    assert sent.done() and sent.result().accepted
    return result_of(t, sent.result(), timeout)


def test_publishes_joint_states_and_every_block_as_motion_capture(twin):
    js = twin.seen['joints'][-1]
    assert list(js.name) == list(JOINT_NAMES)       # panda_joint1..7, panda_finger_joint1/2
    assert np.allclose(js.position, HOME, atol=0.02)
    assert js.header.stamp.sec > 0
    bodies = twin.seen['bodies'][-1]
    assert sorted(b.rigid_body_name for b in bodies.rigidbodies) == sorted(b.id for b in twin.scene.blocks)
    assert bodies.header.frame_id == 'world' and bodies.frame_number > 0
    for body in bodies.rigidbodies:
        block = twin.scene.block(body.rigid_body_name)
        p = body.pose.position
        assert np.allclose([p.x, p.y, p.z], block.position, atol=0.003)
    state = twin.state()
    assert state.success and Scene.loads(state.scene_json).to_dict() == twin.scene.to_dict()


def test_publishes_the_robot_description_and_each_blocks_frame_for_rviz(twin):
    import re
    from pathlib import Path

    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage
    described, tf, static = [], [], []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    twin.node.create_subscription(String, 'robot_description', described.append, latched)
    twin.node.create_subscription(TFMessage, '/tf', tf.append, 10)
    twin.node.create_subscription(TFMessage, '/tf_static', static.append, latched)
    assert spin_until(twin.node, lambda: described and len(tf) >= 2 and static, timeout=10.0)
    # One tree: the robot's root link hangs from the base frame, as the blocks do.
    (root,) = static[0].transforms
    assert (root.header.frame_id, root.child_frame_id, root.transform.rotation.w) == ('world', 'panda_link0', 1.0)
    urdf = described[0].data
    joints = set(re.findall(r'<joint name="([^"]+)"', urdf))
    assert set(JOINT_NAMES) <= joints, joints            # the names joint_states carries
    meshes = re.findall(r'filename="([^"]+)"', urdf)
    assert meshes and all(m.startswith('file:///') and Path(m[len('file://'):]).exists() for m in meshes)
    frames = {t.child_frame_id: t for msg in tf for t in msg.transforms}
    assert set(frames) == {f'block/{b.id}' for b in twin.scene.blocks}
    for block in twin.scene.blocks:
        t = frames[f'block/{block.id}']
        assert t.header.frame_id == 'world'
        assert np.allclose([t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
                           block.position, atol=0.003)


def test_executes_a_trajectory_on_the_topic_and_reports_done(twin):
    from rad_ros.motion import trajectory_to_msg
    target = arm_target(j1=0.3)
    twin.pub.publish(trajectory_to_msg(retimed(target)))
    spin_until(twin.node, lambda: any(e['event'] == 'done' for e in twin.seen['events']), timeout=20.0)
    assert twin.seen['events'][0]['event'] == 'accepted', twin.seen['events']
    done = next(e for e in twin.seen['events'] if e['event'] == 'done')
    assert done['error_code'] == 0, done
    assert fresh_joint_states(twin)[-1].position[0] == pytest.approx(target[0], abs=0.01)


def _bad_trajectories():
    home = list(HOME_ARM)
    nan = list(HOME_ARM)
    nan[2] = math.nan
    far = list(HOME_ARM)
    far[3] = 5.0
    return {
        'NaN': (trajectory([(1.0, nan)], ARM_NAMES), 'nan'),
        'unknown joint name': (trajectory([(1.0, home)], names=ARM_NAMES[:6] + ['elbow']), 'elbow'),
        'finger joints (they belong to the gripper)': (trajectory([(1.0, list(HOME))]), 'panda_finger_joint1'),
        'decreasing times': (trajectory([(2.0, home), (1.0, home)], ARM_NAMES), 'increas'),
        'outside joint limits': (trajectory([(1.0, far)], ARM_NAMES), 'limit'),
        'names and positions differ in length': (trajectory([(1.0, home[:6])], ARM_NAMES), 'position'),
        # Positions only, the controller interpolates linearly from rest: too fast for the joints' velocity.
        'fast position-only jump of several joints': (trajectory([(0.2, arm_target(j1=0.6, j2=0.6))], ARM_NAMES),
                                                      'velocity'),
        # Slow enough for the velocity limit, but the linear interpolation starts (and stops) at full speed:
        # a 0.6 rad/s step within one 1 kHz cycle, an acceleration no Franka can follow.
        'position-only jump of several joints': (trajectory([(0.5, arm_target(j1=0.3, j2=0.2, j4=0.2))],
                                                            ARM_NAMES), 'limit'),
    }


@pytest.mark.parametrize('case', list(_bad_trajectories()))
def test_bad_trajectories_are_rejected_and_change_nothing(twin, case):
    msg, expected = _bad_trajectories()[case]
    before = twin.state()
    twin.pub.publish(msg)
    spin_until(twin.node, lambda: any(e['event'] == 'rejected' for e in twin.seen['events']), timeout=10.0)
    rejected = [e for e in twin.seen['events'] if e['event'] == 'rejected']
    assert rejected, twin.seen['events']
    reason = rejected[0]['reason']
    assert expected in reason.lower(), reason
    assert not any(e['event'] == 'accepted' for e in twin.seen['events'])
    assert np.allclose(fresh_joint_states(twin)[-1].position, HOME, atol=0.02)
    assert twin.state().scene_json == before.scene_json
    assert twin.proc.is_running()


# ---- FollowJointTrajectory ---------------------------------------------------------------

def test_a_retimed_goal_succeeds_and_the_arm_ends_at_its_last_point(twin):
    from action_msgs.msg import GoalStatus
    target = arm_target(j1=0.3, j2=-0.2, j6=0.25)
    traj = retimed(target)
    t0 = time.monotonic()
    status, result = result_of(twin, send_arm_goal(twin, traj), timeout=30.0)
    assert status == GoalStatus.STATUS_SUCCEEDED, (status, result.error_code, result.error_string)
    assert result.error_code == 0, result.error_string
    # Not before the trajectory's own duration (at the twin's real-time factor).
    assert time.monotonic() - t0 >= traj['points'][-1]['time_from_start'] / RTF * 0.9
    js = fresh_joint_states(twin)[-1]
    assert np.allclose(js.position[:7], target, atol=0.005), np.round(np.asarray(js.position[:7]) - target, 4)
    assert np.allclose(js.position[7:], FINGER_OPEN, atol=0.002)     # the arm goal leaves the hand alone
    assert any(e['event'] == 'accepted' for e in twin.seen['events'])


def test_a_goal_over_the_limits_is_aborted_at_once_and_the_arm_does_not_move(twin):
    from action_msgs.msg import GoalStatus
    fast = time_scaled(retimed(arm_target(j1=0.3)), 0.3)    # the same path in 30 % of the time
    t0 = time.monotonic()
    handle = send_arm_goal(twin, fast)
    status, result = result_of(twin, handle, timeout=10.0)
    elapsed = time.monotonic() - t0
    assert status == GoalStatus.STATUS_ABORTED, status
    assert result.error_code == -1, (result.error_code, result.error_string)     # INVALID_GOAL
    assert elapsed < 2.0, elapsed
    message = result.error_string
    assert 'panda_joint1' in message and ('velocity' in message or 'acceleration' in message), message
    assert 'limit' in message, message
    states = fresh_joint_states(twin, count=10)      # ~0.2 s of joint states after the refusal
    for js in states:
        assert np.allclose(js.position[:7], HOME_ARM, atol=0.003), js.position
        assert np.abs(js.velocity[:7]).max() < 0.01
    rejected = [e for e in twin.seen['events'] if e['event'] == 'rejected']
    assert rejected and rejected[0]['error_code'] == -1
    assert not any(e['event'] == 'accepted' for e in twin.seen['events'])


@pytest.mark.parametrize('names', ['all nine joints', 'a finger joint for an arm joint'])
def test_a_goal_naming_finger_joints_is_aborted_with_invalid_joints(twin, names):
    from action_msgs.msg import GoalStatus
    if names == 'all nine joints':
        msg = trajectory([(1.0, list(HOME))], JOINT_NAMES)
    else:
        msg = trajectory([(1.0, list(HOME_ARM))], ARM_NAMES[:6] + ['panda_finger_joint1'])
    status, result = result_of(twin, send_arm_goal(twin, msg), timeout=10.0)
    assert status == GoalStatus.STATUS_ABORTED, status
    assert result.error_code == -2, (result.error_code, result.error_string)     # INVALID_JOINTS
    assert 'panda_finger_joint1' in result.error_string, result.error_string
    assert np.allclose(fresh_joint_states(twin)[-1].position, HOME, atol=0.02)


def test_cancel_stops_the_arm_where_it_is(twin):
    from action_msgs.msg import GoalStatus
    target = arm_target(j1=1.5)
    traj = retimed(target, speed_scale=0.05)        # ~14 s of simulated motion, ~3.5 s of wall time
    assert traj['points'][-1]['time_from_start'] > 10.0
    handle = send_arm_goal(twin, traj)
    # Wait until the arm is well under way.
    assert spin_until(twin.node, lambda: twin.seen['joints'] and twin.seen['joints'][-1].position[0] > 0.3,
                      timeout=10.0), 'the arm did not move'
    cancel = handle.cancel_goal_async()
    rclpy.spin_until_future_complete(twin.node, cancel, timeout_sec=5.0)
    assert cancel.done() and len(cancel.result().goals_canceling) == 1
    status, result = result_of(twin, handle, timeout=5.0)
    assert status == GoalStatus.STATUS_CANCELED, (status, result.error_code, result.error_string)
    time.sleep(0.2)
    states = fresh_joint_states(twin, count=25)      # 0.5 s at 50 Hz
    q = np.array([js.position[:7] for js in states])
    v = np.array([js.velocity[:7] for js in states])
    assert np.abs(v).max() < 0.02, np.abs(v).max(axis=0)
    assert np.ptp(q, axis=0).max() < 0.003, np.ptp(q, axis=0)
    assert 0.3 < q[-1, 0] < target[0] - 0.2, q[-1, 0]       # stopped short of the goal
    assert np.allclose(q[-1, 1:], HOME_ARM[1:], atol=0.01)
    assert not any(e['event'] == 'done' and e.get('error_code') == 0 and not e.get('preempted')
                   for e in twin.seen['events']), twin.seen['events']


# ---- GripperCommand ----------------------------------------------------------------------

def test_gripper_grasp_on_air_is_aborted_with_the_fingers_closed(twin):
    from action_msgs.msg import GoalStatus
    # A grasp for a 40 mm part with nothing between the fingers (the hand at HOME, high above the table):
    # a Franka hand closes until it feels the part, here to the end of its stroke, far from the commanded
    # width, so the grasp fails.
    status, result = gripper_goal(twin, 0.02, max_effort=20.0)
    assert status == GoalStatus.STATUS_ABORTED, (status, result.position, result.reached_goal)
    assert not result.reached_goal
    assert result.position < 0.003, result.position
    assert np.asarray(fresh_joint_states(twin)[-1].position[7:]).max() < 0.003


def test_gripper_closes_fully_and_opens_to_its_full_width(twin):
    from action_msgs.msg import GoalStatus
    status, result = gripper_goal(twin, 0.0, max_effort=20.0)
    assert result.position < 0.003, (status, result.position)
    assert np.asarray(fresh_joint_states(twin)[-1].position[7:]).max() < 0.003
    status, result = gripper_goal(twin, FINGER_OPEN, max_effort=0.0)
    assert status == GoalStatus.STATUS_SUCCEEDED, (status, result.position)
    assert result.reached_goal and result.position == pytest.approx(FINGER_OPEN, abs=0.001)
    assert np.allclose(fresh_joint_states(twin)[-1].position[7:], FINGER_OPEN, atol=0.001)


@pytest.mark.parametrize('position', [0.2, -0.01, math.nan])
def test_gripper_refuses_positions_outside_its_range(twin, position):
    from action_msgs.msg import GoalStatus
    status, result = gripper_goal(twin, position, max_effort=20.0, timeout=5.0)
    assert status == GoalStatus.STATUS_ABORTED, status
    assert not result.reached_goal
    assert np.allclose(fresh_joint_states(twin)[-1].position[7:], FINGER_OPEN, atol=0.001)
    assert twin.proc.wait_for_output(r'gripper goal refused: gripper: position', timeout=5.0)


def test_load_scene_refuses_bad_scenes_and_keeps_the_old_one(twin):
    from rad_msgs.srv import LoadScene
    bad = json.dumps(doc()).replace('"type": "I2"', '"type": "Q9"')
    response = twin.load(LoadScene.Request(scene_json=bad))
    assert not response.success and 'unknown block type' in response.reason
    response = twin.load(LoadScene.Request())
    assert not response.success and 'no scene given' in response.reason
    assert Scene.loads(twin.state().scene_json).to_dict() == twin.scene.to_dict()
    other = Scene.from_dict(doc())
    assert twin.load(LoadScene.Request(scene_json=other.dumps())).success
    assert Scene.loads(twin.state().scene_json).to_dict() == other.to_dict()


def test_set_block_pose_checks_id_workspace_and_numbers(twin, ros_node):
    from geometry_msgs.msg import Pose
    from rad_msgs.srv import SetBlockPose
    client = wait_for_service(ros_node, SetBlockPose, 'set_block_pose', timeout=10.0)

    def move(block_id, x, y, z, qw=1.0):
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z, pose.orientation.w = x, y, z, qw
        return call_service(ros_node, client, SetBlockPose.Request(block_id=block_id, pose=pose), timeout=10.0)

    bid = twin.scene.blocks[0].id
    assert "unknown block id 'nope'" in move('nope', 0.5, -0.3, 0.025).reason
    assert 'outside the workspace' in move(bid, 5.0, 0.0, 0.025).reason
    assert 'not finite' in move(bid, math.nan, 0.0, 0.025).reason
    assert 'unit quaternion' in move(bid, 0.5, -0.3, 0.025, qw=0.5).reason
    assert 'outside the workspace' in move(bid, 0.5, -0.3, -0.5).reason
    assert Scene.loads(twin.state().scene_json).to_dict() == twin.scene.to_dict()
    assert move(bid, 0.45, -0.55, 0.025).success
    body = [b for b in fresh_messages(twin, 'bodies')[-1].rigidbodies if b.rigid_body_name == bid][0]
    assert body.pose.position.y == pytest.approx(-0.55, abs=0.005)


def test_load_scene_refuses_blocks_outside_the_workspace(twin):
    from rad_msgs.srv import LoadScene
    d = doc()
    d['blocks'][0]['position'] = [3.0, 0.0, 0.025]
    response = twin.load(LoadScene.Request(scene_json=json.dumps(d)))
    assert not response.success and 'outside the workspace' in response.reason


def test_registration_rebuilds_the_scene_from_published_motion_capture(twin):
    from rad_core.cell.mocap import RegistrationConfig, RigidBodyPose, body_map_for, register_scene
    from rad_ros.motion import pose_from_msg
    twin.seen['bodies'].clear()
    spin_until(twin.node, lambda: twin.seen['bodies'], timeout=5.0)
    frame = twin.seen['bodies'][-1]
    bodies = [RigidBodyPose(b.rigid_body_name, *pose_from_msg(b.pose), b.tracking_valid) for b in frame.rigidbodies]
    rebuilt = register_scene(bodies, twin.scene, RegistrationConfig(body_map=body_map_for(twin.scene)))
    assert rebuilt.to_dict() == twin.scene.to_dict()


def test_latched_scene_topic_and_reset(twin, ros_node):
    from geometry_msgs.msg import Pose
    from rad_msgs.msg import Scene as SceneMsg
    from rad_msgs.srv import SetBlockPose
    from rad_ros.conversions import scene_from_msg
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_srvs.srv import Trigger
    got = []
    # Subscribing late still gets the scene: the topic is latched (transient local).
    ros_node.create_subscription(SceneMsg, 'scene', got.append,
                                 QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    spin_until(ros_node, lambda: got, timeout=10.0)
    assert scene_from_msg(got[-1]).to_dict() == twin.scene.to_dict()
    mover = wait_for_service(ros_node, SetBlockPose, 'set_block_pose', timeout=10.0)
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z, pose.orientation.w = 0.3, -0.6, 0.025, 1.0
    bid = twin.scene.blocks[0].id
    assert call_service(ros_node, mover, SetBlockPose.Request(block_id=bid, pose=pose), timeout=10.0).success
    assert Scene.loads(twin.state().scene_json).block(bid).position[1] == pytest.approx(-0.6, abs=1e-3)
    reset = wait_for_service(ros_node, Trigger, 'reset', timeout=10.0)
    assert call_service(ros_node, reset, Trigger.Request(), timeout=10.0).success
    assert Scene.loads(twin.state().scene_json).to_dict() == twin.scene.to_dict()


def test_faults_and_a_mocap_frame_shape_what_motion_capture_publishes(node_process, ros_node, tmp_path):
    """Motion capture as a tracker in its own frame publishes it: poses through the inverse calibration, stamped
    with mocap_frame; dropped frames leave gaps in the frame numbers; dropped bodies are untracked, at their
    last pose, and missing from their PoseStamped topic."""
    from geometry_msgs.msg import PoseStamped
    from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion
    from rad_msgs.msg import RigidBodies
    from rad_ros.motion import pose_from_msg
    from rclpy.qos import qos_profile_sensor_data

    scene = generate_scene(GeneratorConfig(grid=3), 5)
    (tmp_path / 'scene.json').write_text(scene.dumps())
    (tmp_path / 'faults.yaml').write_text('drop_frame: 0.3\ndrop_body: 0.3\n')
    t, q = [0.1, -0.2, 0.74], list(yaw_quaternion(90))
    proc = node_process('rad_sim', 'twin_node', *ros_args({
        'scene_file': str(tmp_path / 'scene.json'), 'faults': str(tmp_path / 'faults.yaml'), 'faults_seed': 3,
        'mocap_frame': 'optitrack', 'mocap_to_base_translation': t, 'mocap_to_base_quaternion': q}))
    frames, poses = [], []
    ros_node.create_subscription(RigidBodies, 'rigid_bodies', frames.append, qos_profile_sensor_data)
    block = scene.blocks[0].id
    ros_node.create_subscription(PoseStamped, f'mocap/{block}/pose', poses.append, qos_profile_sensor_data)
    assert spin_until(ros_node, lambda: len(frames) >= 60, timeout=30.0), proc.output_tail()
    proc.wait_for_output(r'faults \(seed 3\): drop_body=0.3, drop_frame=0.3', timeout=5.0)
    numbers = [f.frame_number for f in frames]
    assert numbers == sorted(numbers) and numbers[-1] - numbers[0] + 1 > len(numbers)     # gaps: dropped frames
    assert {f.header.frame_id for f in frames} == {'optitrack'} and {p.header.frame_id for p in poses} == {'optitrack'}
    r = matrix_from_quaternion(q)
    want = {b.id: np.asarray(b.position) for b in scene.blocks}
    tracked = untracked = 0
    for f in frames:
        for b in f.rigidbodies:
            p_mocap, _ = pose_from_msg(b.pose)
            np.testing.assert_allclose(r @ np.asarray(p_mocap) + t, want[b.rigid_body_name], atol=2e-4)
            tracked += b.tracking_valid
            untracked += not b.tracking_valid
    assert tracked and untracked                   # a dropped body: at its last pose, tracking_valid false
    assert 0 < len(poses) < len(frames)            # and not published on its own topic


@pytest.mark.parametrize('params, reason', [({'faults': 'sometimes'}, 'none, realistic or a JSON/YAML file'),
                                            ({'mocap_to_base_quaternion': [0.0, 0.0, 0.0, 2.0]},
                                             'mocap_to_base_quaternion must be a unit quaternion')])
def test_bad_fault_and_frame_parameters_stop_the_twin_with_the_reason(node_process, params, reason):
    proc = node_process('rad_sim', 'twin_node', *ros_args(params))
    assert proc.wait(timeout=20.0) == 1
    assert 'cannot start' in proc.stderr() and reason in proc.stderr()


def test_the_feeder_presents_a_block_motion_capture_then_sees(twin, ros_node):
    from rad_msgs.srv import LoadScene, PresentBlock
    fed = generate_scene(GeneratorConfig(grid=3, supply='feeder'), 5)
    assert twin.load(LoadScene.Request(scene_json=fed.dumps())).success
    client = wait_for_service(ros_node, PresentBlock, 'feeder/present', timeout=10.0)

    def present(block_id):
        return call_service(ros_node, client, PresentBlock.Request(block_id=block_id), timeout=10.0)

    assert fresh_messages(twin, 'bodies')[-1].rigidbodies == []       # no camera sees into the feeder
    assert Scene.loads(twin.state().scene_json) == fed
    assert "unknown block id 'nope'" in present('nope').reason
    first = fed.feeder.blocks[0]
    assert present(first).success
    seen = fresh_messages(twin, 'bodies')[-1].rigidbodies
    assert [b.rigid_body_name for b in seen] == [first]
    assert seen[0].pose.position.x == pytest.approx(fed.block(first).position[0], abs=0.005)
    assert Scene.loads(twin.state().scene_json).feeder.blocks == fed.feeder.blocks   # presented, not taken
    assert twin.load(LoadScene.Request(scene_json=twin.scene.dumps())).success
    assert 'has no feeder' in present(twin.scene.blocks[0].id).reason


@pytest.mark.parametrize('robot, prefix', [('panda', ''), ('fr3', ''), ('panda', 'fer')])
def test_the_robot_description_names_every_joint_as_joint_states_does(robot, prefix):
    """robot_state_publisher matches joint_states to the URDF by name: every joint the twin publishes
    is a joint of the description it publishes, and no joint keeps another robot's prefix."""
    import re as regex
    from rad_core.cell.robot_model import robot_model
    from rad_sim.twin_node import robot_description
    model = robot_model(robot, prefix)
    text = robot_description('hand', model.prefix)
    joints = set(regex.findall(r'<joint name="([^"]+)"', text))
    assert set(model.arm_joint_names + model.finger_joint_names) <= joints, joints
    assert all(j.startswith(f'{model.prefix}_') for j in joints), joints
    links = set(regex.findall(r'link="([^"]+)"', text))
    assert links and all(link.startswith(f'{model.prefix}_') for link in links), links
    assert 'file:///' in text

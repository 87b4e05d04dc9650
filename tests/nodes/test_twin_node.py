"""The rad_sim twin node as a plant, over real DDS: topics, services, bad input."""

import json
import math

import numpy as np
import pytest

from ros_harness import call_service, ros_args, spin_until, wait_for_service
from scenes import doc

from rad_core.generator import GeneratorConfig, generate_scene
from rad_core.scene import Scene
from rad_core.sim.panda import HOME, JOINT_NAMES

TRAJ_TOPIC = 'joint_trajectory_controller/joint_trajectory'


@pytest.fixture
def twin(node_process, ros_node, tmp_path):
    """A twin node with a generated scene, and helpers to talk to it."""
    from rad_msgs.msg import RigidBodies
    from rad_msgs.srv import GetSceneState, LoadScene
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from trajectory_msgs.msg import JointTrajectory

    scene = generate_scene(GeneratorConfig(grid=3), 5)
    path = tmp_path / 'scene.json'
    path.write_text(scene.dumps())
    proc = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path), 'real_time_factor': 4.0}))
    seen = {'joints': [], 'bodies': [], 'events': []}
    ros_node.create_subscription(JointState, 'joint_states', seen['joints'].append, 10)
    ros_node.create_subscription(RigidBodies, 'rigid_bodies', seen['bodies'].append, qos_profile_sensor_data)
    ros_node.create_subscription(String, 'twin/events', lambda m: seen['events'].append(json.loads(m.data)), 10)
    pub = ros_node.create_publisher(JointTrajectory, TRAJ_TOPIC, 10)
    state_client = wait_for_service(ros_node, GetSceneState, 'get_scene_state', timeout=30.0)
    load_client = wait_for_service(ros_node, LoadScene, 'load_scene', timeout=10.0)
    spin_until(ros_node, lambda: seen['joints'] and seen['bodies'], timeout=15.0)

    class Twin:
        pass
    t = Twin()
    t.proc, t.scene, t.seen, t.pub, t.node = proc, scene, seen, pub, ros_node
    t.state = lambda: call_service(ros_node, state_client, GetSceneState.Request(), timeout=10.0)
    t.load = lambda req: call_service(ros_node, load_client, req, timeout=10.0)
    yield t
    assert proc.stop() == 0, proc.output_tail()


def trajectory(points, names=JOINT_NAMES):
    from rad_ros.motion import trajectory_to_msg
    return trajectory_to_msg({'joint_names': list(names), 'points': [
        {'positions': list(p), 'velocities': [], 'time_from_start': t} for t, p in points]})


def test_publishes_joint_states_and_every_block_as_motion_capture(twin):
    js = twin.seen['joints'][-1]
    assert list(js.name) == list(JOINT_NAMES)
    assert np.allclose(js.position, HOME, atol=0.02)
    bodies = twin.seen['bodies'][-1]
    assert sorted(b.rigid_body_name for b in bodies.rigidbodies) == sorted(b.id for b in twin.scene.blocks)
    assert bodies.header.frame_id == 'world' and bodies.frame_number > 0
    for body in bodies.rigidbodies:
        block = twin.scene.block(body.rigid_body_name)
        p = body.pose.position
        assert np.allclose([p.x, p.y, p.z], block.position, atol=0.003)
    state = twin.state()
    assert state.success and Scene.loads(state.scene_json).to_dict() == twin.scene.to_dict()


def test_executes_a_trajectory_and_reports_done(twin):
    target = np.array(HOME)
    target[0] += 0.3
    twin.pub.publish(trajectory([(0.5, HOME), (1.5, target)]))
    spin_until(twin.node, lambda: any(e['event'] == 'done' for e in twin.seen['events']), timeout=20.0)
    assert twin.seen['events'][0]['event'] == 'accepted'
    twin.seen['joints'].clear()
    spin_until(twin.node, lambda: twin.seen['joints'], timeout=5.0)
    assert twin.seen['joints'][-1].position[0] == pytest.approx(target[0], abs=0.02)


def _bad_trajectories():
    home = list(HOME)
    nan = list(HOME)
    nan[2] = math.nan
    far = list(HOME)
    far[3] = 5.0
    return {
        'NaN': (trajectory([(1.0, nan)]), 'nan'),
        'unknown joint name': (trajectory([(1.0, home)], names=list(JOINT_NAMES[:8]) + ['elbow']), 'elbow'),
        'decreasing times': (trajectory([(2.0, home), (1.0, home)]), 'increas'),
        'outside joint limits': (trajectory([(1.0, far)]), 'limit'),
        'names and positions differ in length': (trajectory([(1.0, home[:7])]), 'position'),
    }


@pytest.mark.parametrize('case', list(_bad_trajectories()))
def test_bad_trajectories_are_rejected_and_change_nothing(twin, case):
    msg, expected = _bad_trajectories()[case]
    before = twin.state()
    twin.pub.publish(msg)
    spin_until(twin.node, lambda: any(e['event'] == 'rejected' for e in twin.seen['events']), timeout=10.0)
    reason = [e for e in twin.seen['events'] if e['event'] == 'rejected'][0]['reason']
    assert expected in reason.lower(), reason
    twin.seen['joints'].clear()
    spin_until(twin.node, lambda: twin.seen['joints'], timeout=5.0)
    assert np.allclose(twin.seen['joints'][-1].position, HOME, atol=0.02)
    assert twin.state().scene_json == before.scene_json
    assert twin.proc.is_running()


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
    twin.seen['bodies'].clear()
    spin_until(twin.node, lambda: twin.seen['bodies'], timeout=5.0)
    body = [b for b in twin.seen['bodies'][-1].rigidbodies if b.rigid_body_name == bid][0]
    assert body.pose.position.y == pytest.approx(-0.55, abs=0.005)


def test_load_scene_refuses_blocks_outside_the_workspace(twin):
    from rad_msgs.srv import LoadScene
    d = doc()
    d['blocks'][0]['position'] = [3.0, 0.0, 0.025]
    response = twin.load(LoadScene.Request(scene_json=json.dumps(d)))
    assert not response.success and 'outside the workspace' in response.reason


def test_registration_rebuilds_the_scene_from_published_motion_capture(twin):
    from rad_core.sim.mocap import RegistrationConfig, RigidBodyPose, body_map_for, register_scene
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

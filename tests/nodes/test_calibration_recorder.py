"""The calibration recorder node over real DDS: a pair recorded at rest, refusals with a reason."""

import numpy as np
from rad_core.cell.calibration import marker_in_base, read_pairs_csv
from rad_core.cell.panda import HOME, JOINT_NAMES
from rad_core.sim.world import World
from ros_harness import REPO_ROOT, call_service, ros_args, spin_until, wait_for_service

MARKER_TOPIC = 'cal_test/flange_marker/pose'
OFFSET = [0.0, 0.02, 0.05]


def test_records_a_pair_at_rest_and_refuses_no_input_motion_and_a_wrong_frame(node_process, ros_node, tmp_path):
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    csv_file = tmp_path / 'pairs.csv'
    proc = node_process('rad_planner', 'calibration_recorder', *ros_args({
        'robot': 'panda', 'csv_file': str(csv_file), 'marker_topic': MARKER_TOPIC, 'marker_offset': str(OFFSET),
        'mocap_frame': 'optitrack', 'rest_window_s': 0.3, 'stale_after_s': 0.3}))
    client = wait_for_service(ros_node, Trigger, 'calibration_recorder/record', timeout=20.0)

    def record():
        return call_service(ros_node, client, Trigger.Request(), timeout=10.0)

    r = record()
    assert not r.success and 'no /joint_states received yet' in r.message, r.message

    q = np.array(HOME, dtype=float)
    q[0], q[3] = 0.3, -2.2
    p_mocap = [1.25, -0.5, 2.0]
    state = {'moving': False, 'frame': 'optitrack'}
    joint_pub = ros_node.create_publisher(JointState, 'joint_states', 10)
    marker_pub = ros_node.create_publisher(PoseStamped, MARKER_TOPIC, 10)

    def publish():
        if state['moving']:
            q[1] += 0.002
        js = JointState(name=list(JOINT_NAMES), position=[float(v) for v in q])
        js.header.stamp = ros_node.get_clock().now().to_msg()
        joint_pub.publish(js)
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = js.header.stamp, state['frame']
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = p_mocap
        pose.pose.orientation.w = 1.0
        marker_pub.publish(pose)

    timer = ros_node.create_timer(0.02, publish)
    spin_until(ros_node, lambda: False, timeout=1.0)            # the rest window fills
    r = record()
    assert r.success and r.message.startswith('pair 1 recorded'), r.message
    pairs = read_pairs_csv(csv_file)
    with World() as world:
        expected = marker_in_base(world, q[:7], OFFSET)
    assert np.allclose(pairs.base, [expected], atol=1e-9) and np.allclose(pairs.mocap, [p_mocap], atol=1e-12)

    state['moving'] = True
    spin_until(ros_node, lambda: False, timeout=0.5)
    r = record()
    assert not r.success and '/joint_states is moving: component 2' in r.message, r.message

    state['moving'], state['frame'] = False, 'world'
    spin_until(ros_node, lambda: False, timeout=0.6)
    r = record()
    assert not r.success and "frame 'world', not mocap_frame 'optitrack'" in r.message, r.message
    ros_node.destroy_timer(timer)

    assert len(read_pairs_csv(csv_file).base) == 1
    assert proc.stop() == 0, proc.output_tail()


def test_the_robot_comes_from_the_cells_profile_and_unset_it_is_refused(node_process, ros_node, tmp_path):
    """franka.yaml's calibration_recorder section names the FR3 (fr3_joint1..7); with no robot at all the node
    stays up and refuses to record, saying how to set it."""
    from geometry_msgs.msg import PoseStamped
    from rad_core.cell.robot_model import robot_model
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger
    profile = REPO_ROOT / 'ros_ws/src/rad_planner/config/franka.yaml'
    fr3 = node_process('rad_planner', 'calibration_recorder', '--ros-args', '--params-file', str(profile),
                       '-p', f'csv_file:={tmp_path / "fr3.csv"}', '-p', 'rest_window_s:=0.3')
    unset = node_process('rad_planner', 'calibration_recorder', *ros_args(
        {'csv_file': str(tmp_path / 'none.csv')}, {'calibration_recorder:__node': 'recorder_unset'}))
    names = robot_model('fr3', '').arm_joint_names
    joint_pub = ros_node.create_publisher(JointState, 'joint_states', 10)
    marker_pub = ros_node.create_publisher(PoseStamped, '/natnet_ros2/flange_marker/pose', 10)

    def publish():
        js = JointState(name=list(names), position=[float(v) for v in HOME[:7]])
        js.header.stamp = ros_node.get_clock().now().to_msg()
        joint_pub.publish(js)
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = js.header.stamp, 'world'
        pose.pose.position.x, pose.pose.orientation.w = 1.0, 1.0
        marker_pub.publish(pose)

    ros_node.create_timer(0.02, publish)
    client = wait_for_service(ros_node, Trigger, 'calibration_recorder/record', timeout=20.0)
    refusing = wait_for_service(ros_node, Trigger, 'recorder_unset/record', timeout=20.0)
    spin_until(ros_node, lambda: False, timeout=1.0)
    r = call_service(ros_node, client, Trigger.Request(), timeout=10.0)
    assert r.success and r.message.startswith('pair 1 recorded'), r.message
    r = call_service(ros_node, refusing, Trigger.Request(), timeout=10.0)
    assert not r.success and 'the robot is not set' in r.message and 'robot:=fr3' in r.message, r.message
    assert fr3.is_running() and unset.is_running()

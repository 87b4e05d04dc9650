"""Managed nodes over DDS: the twin and the assembly node move through the ROS 2 lifecycle as
commanded, by their own lifecycle services and by rad's lifecycle manager; while not active they
refuse work with the reason, and deactivating stops a running arm goal."""

import numpy as np
import pytest
import rclpy
from rad_core.cell.panda import HOME
from rad_core.cell.robot_model import PANDA
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.gamp.trajectory import retime
from rclpy.action import ActionClient
from ros_harness import call_service, ros_args, spin_until, wait_for_service

ARM_ACTION = 'joint_trajectory_controller/follow_joint_trajectory'
GRIPPER_ACTION = 'franka_gripper/gripper_action'


def state_of(node, name: str) -> str:
    from lifecycle_msgs.srv import GetState
    client = wait_for_service(node, GetState, f'{name}/get_state', timeout=30.0)
    return call_service(node, client, GetState.Request(), timeout=10.0).current_state.label


def change(node, name: str, label: str) -> bool:
    from lifecycle_msgs.srv import ChangeState
    client = wait_for_service(node, ChangeState, f'{name}/change_state', timeout=30.0)
    request = ChangeState.Request()
    request.transition.label = label
    return call_service(node, client, request, timeout=30.0).success


def trigger(node, service: str):
    from std_srvs.srv import Trigger
    client = wait_for_service(node, Trigger, service, timeout=30.0)
    return call_service(node, client, Trigger.Request(), timeout=60.0)


def send_goal(node, client, goal):
    sent = client.send_goal_async(goal)
    rclpy.spin_until_future_complete(node, sent, timeout_sec=10.0)
    assert sent.done(), 'no answer to the goal'
    return sent.result()


def result_of(node, handle, timeout: float = 20.0):
    done = handle.get_result_async()
    rclpy.spin_until_future_complete(node, done, timeout_sec=timeout)
    assert done.done(), f'no result within {timeout} s'
    return done.result().status, done.result().result


def open_gripper(node, gripper):
    from control_msgs.action import GripperCommand
    goal = GripperCommand.Goal()
    goal.command.position, goal.command.max_effort = 0.04, 20.0
    return send_goal(node, gripper, goal)


def slow_arm_goal():
    """A FollowJointTrajectory goal of about 14 s of motion (joint 1 through 1.5 rad at 5 % speed)."""
    from control_msgs.action import FollowJointTrajectory
    from rad_ros.motion import trajectory_to_msg
    start = np.asarray(HOME[:7], dtype=float)
    target = start.copy()
    target[0] += 1.5
    goal = FollowJointTrajectory.Goal()
    goal.trajectory = trajectory_to_msg(retime([start, target], PANDA, 0.05).to_dict())
    return goal


def plan_reason(node) -> tuple[bool, str]:
    from rad_msgs.srv import PlanAssembly
    client = wait_for_service(node, PlanAssembly, 'plan_assembly', timeout=30.0)
    request = PlanAssembly.Request()
    request.scene_json = generate_scene(GeneratorConfig(grid=3), 1).dumps()
    response = call_service(node, client, request, timeout=60.0)
    return response.success, response.reason


@pytest.fixture
def managed(node_process, ros_node, tmp_path):
    """The twin and the assembly node started unconfigured (autostart false)."""
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    path = tmp_path / 'scene.json'
    path.write_text(scene.dumps())
    twin = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path), 'real_time_factor': 4.0,
                                                            'autostart': False}))
    assembly = node_process('rad_planner', 'assembly_node', *ros_args({'autostart': False}))
    return twin, assembly


def test_the_lifecycle_manager_brings_the_nodes_up_pauses_resumes_and_shuts_them_down(managed, node_process,
                                                                                        ros_node):
    from action_msgs.msg import GoalStatus
    from control_msgs.action import FollowJointTrajectory, GripperCommand
    twin, assembly = managed
    assert state_of(ros_node, 'twin') == 'unconfigured'
    assert state_of(ros_node, 'assembly') == 'unconfigured'
    arm = ActionClient(ros_node, FollowJointTrajectory, ARM_ACTION)
    gripper = ActionClient(ros_node, GripperCommand, GRIPPER_ACTION)
    assert not arm.wait_for_server(timeout_sec=1.0), 'an unconfigured twin offers its arm controller'

    manager = node_process('rad_planner', 'lifecycle_manager', *ros_args({'node_names': ['twin', 'assembly']}))
    assert spin_until(ros_node, lambda: state_of(ros_node, 'assembly') == 'active', timeout=60.0), \
        manager.output_tail()
    assert state_of(ros_node, 'twin') == 'active'
    assert arm.wait_for_server(timeout_sec=10.0) and gripper.wait_for_server(timeout_sec=10.0)
    handle = open_gripper(ros_node, gripper)
    assert handle.accepted
    assert result_of(ros_node, handle)[0] == GoalStatus.STATUS_SUCCEEDED

    # Pausing while the arm moves: the goal ends, aborted, the arm stopped; no new goals; no planning.
    handle = send_goal(ros_node, arm, slow_arm_goal())
    assert handle.accepted
    paused = trigger(ros_node, 'lifecycle_manager/pause')
    assert paused.success, paused.message
    assert 'twin inactive' in paused.message and 'assembly inactive' in paused.message
    status, result = result_of(ros_node, handle)
    assert status == GoalStatus.STATUS_ABORTED and 'deactivated' in result.error_string, result.error_string
    assert not open_gripper(ros_node, gripper).accepted
    ok, reason = plan_reason(ros_node)
    assert not ok and 'inactive, not active' in reason and 'activate' in reason, reason

    resumed = trigger(ros_node, 'lifecycle_manager/resume')
    assert resumed.success and state_of(ros_node, 'twin') == 'active', resumed.message
    handle = open_gripper(ros_node, gripper)
    assert handle.accepted and result_of(ros_node, handle)[0] == GoalStatus.STATUS_SUCCEEDED

    down = trigger(ros_node, 'lifecycle_manager/shutdown')
    assert down.success, down.message
    assert state_of(ros_node, 'twin') == 'unconfigured' and state_of(ros_node, 'assembly') == 'unconfigured'
    assert twin.is_running() and assembly.is_running()
    again = trigger(ros_node, 'lifecycle_manager/startup')     # configure works again after cleanup
    assert again.success and 'twin active' in again.message, again.message
    for proc in (manager, assembly, twin):
        assert proc.stop() == 0, proc.output_tail()


def test_a_refused_configure_names_the_reason_and_the_node_stays_up(node_process, ros_node):
    twin = node_process('rad_sim', 'twin_node', *ros_args({'faults_seed': -1, 'autostart': False}))
    assert not change(ros_node, 'twin', 'configure')
    assert state_of(ros_node, 'twin') == 'unconfigured'
    twin.wait_for_output('configure refused: faults_seed must be a non-negative integer', timeout=10.0)
    assert twin.is_running()
    manager = node_process('rad_planner', 'lifecycle_manager', *ros_args({'node_names': ['twin'], 'autostart': False}))
    answer = trigger(ros_node, 'lifecycle_manager/startup')
    assert not answer.success and 'twin refused to configure' in answer.message, answer.message
    assert manager.is_running()

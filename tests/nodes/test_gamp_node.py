"""The rad_gamp node's /plan_action service over real DDS."""

import math

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.cell.panda import ARM_JOINT_NAMES, HOME, LOWER, UPPER
from rad_core.cell.robot_model import PANDA
from rad_core.cell.trajectory import limit_violation
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.transforms import yaw_matrix, yaw_quaternion
from rad_ros.motion import pose_msg, trajectory_from_msg
from ros_harness import call_service, ros_args, wait_for_service


@pytest.fixture
def gamp(node_process, ros_node):
    from rad_msgs.srv import PlanAction
    proc = node_process('rad_gamp', 'gamp_node', *ros_args({'seed': 0}))
    client = wait_for_service(ros_node, PlanAction, 'plan_action', timeout=30.0)

    def plan(scene, block_id, unit, target, cell, rotation, start=(), execute=False, place=None, move_aside=False):
        req = PlanAction.Request(scene_json=scene.dumps(), start_positions=list(start), execute=execute,
                                 move_aside=move_aside)
        if place is not None:     # (position, quaternion): the anchor goes there, not to the cell
            req.place_at_pose, req.place_pose = True, pose_msg(*place)
        req.action.block_id, req.action.unit, req.action.target, req.action.rotation = block_id, unit, target, rotation
        req.action.cell.i, req.action.cell.j, req.action.cell.k = cell
        return call_service(ros_node, client, req, timeout=60.0)

    yield proc, plan
    assert proc.stop() == 0, proc.output_tail()


def first_action(scene):
    """A block of the allocation's first pose, put there by its anchor with no turn."""
    p = solve(scene).placements[0]
    block = next(b for b in scene.blocks if b.type == p.type)
    rotation = ((p.yaw - block.yaw) // 90) % 4
    return block.id, 0, p.target, p.cells[0], rotation


def test_plans_a_feasible_action_as_arm_trajectories_and_gripper_commands(gamp):
    proc, plan = gamp
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    r = plan(scene, *first_action(scene))
    assert r.success, r.reason
    assert r.failure == '' and r.planning_time_s > 0
    actions = [g.action for g in r.gripper]
    assert actions[-2:] == ['grasp', 'release'] and set(actions) <= {'close', 'open', 'grasp', 'release'}
    grasp = r.gripper[actions.index('grasp')]
    assert 0 < grasp.command.position < grasp.expected_position and grasp.command.max_effort > 0
    assert [g.before for g in r.gripper][-2:] == [1, 2] and len(r.trajectories) == 3
    q_prev = HOME[:7]
    for traj in r.trajectories:
        assert list(traj.joint_names) == list(ARM_JOINT_NAMES)      # no finger joints: those are the gripper's
        times = [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in traj.points]
        assert times[0] > 0 and all(b > a for a, b in zip(times, times[1:]))
        q = np.array([p.positions for p in traj.points])
        assert np.all(q >= LOWER[:7] - 1e-6) and np.all(q <= UPPER[:7] + 1e-6)
        assert all(len(p.velocities) == len(p.accelerations) == 7 for p in traj.points)
        assert list(traj.points[-1].velocities) == [0.0] * 7
        doc = trajectory_from_msg(traj)
        assert limit_violation(doc, q_prev, PANDA) == ''
        q_prev = q[-1]


@pytest.mark.parametrize('change,expected', [
    ({'block_id': 'nope'}, "unknown block id 'nope'"),
    ({'target': 'roof'}, "unknown target region 'roof'"),
    ({'cell': (9, 0, 0)}, 'outside target region'),
    ({'rotation': 7}, 'rotation 7'),
    ({'unit': 5}, 'is not a unit of block'),
    ({'start': [0.0] * 5}, 'start_positions needs 0, 7 or 9'),
    ({'start': [math.nan] * 9}, 'start_positions must be finite'),
    ({'start': [9.0] * 9}, 'outside the joint limits'),
])
def test_bad_requests_get_a_reason_and_the_node_keeps_serving(gamp, change, expected):
    proc, plan = gamp
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    block_id, unit, target, cell, rotation = first_action(scene)
    args = dict(block_id=block_id, unit=unit, target=target, cell=cell, rotation=rotation, start=())
    args.update(change)
    r = plan(scene, **args)
    assert not r.success and r.failure == 'invalid_request'
    assert expected in r.reason, r.reason
    assert plan(scene, block_id, unit, target, cell, rotation, start=list(HOME)).success
    assert proc.is_running()


def test_a_place_pose_puts_the_anchor_there_and_a_pose_no_scene_holds_is_refused(gamp):
    """Taking apart puts blocks back on the table, which is no grid: the anchor goes to place_pose."""
    from rad_core.sim.world import World
    proc, plan = gamp
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    block = scene.blocks[0]
    position = np.add(block.position, [0.0, -0.12, 0.0])
    yaw = (block.yaw + 90) % 360
    r = plan(scene, block.id, 0, 'nowhere', (99, 0, 0), 9, place=(position, yaw_quaternion(yaw)))
    assert r.success, r.reason
    assert [g.action for g in r.gripper][-2:] == ['grasp', 'release'] and len(r.trajectories) == 3
    # Where the release happens (the end of the carry), the fingertips are on the grasped unit at its new pose.
    offset = np.asarray(scene.block_types[block.type].offsets[r.grasp.unit], dtype=float) * scene.unit
    with World(scene) as world:
        q = np.concatenate([r.trajectories[1].points[-1].positions, [0.02, 0.02]])
        world.set_joint_positions(q)
        tip, _ = world.link_pose()
    assert np.linalg.norm(tip - (position + yaw_matrix(yaw) @ offset)) < 0.005
    for place, expected in (((position, (0.0, 0.38268343, 0.0, 0.92387953)), 'must be upright'),
                            ((position, yaw_quaternion(45)), 'not a multiple of 90'),
                            ((position + [0.0, 0.0, -0.02], yaw_quaternion(0)), 'into the table'),
                            (([3.0, 0.0, 0.025], yaw_quaternion(0)), 'outside the workspace')):
        r = plan(scene, block.id, 0, '', (0, 0, 0), 0, place=place)
        assert not r.success and r.failure == 'invalid_request' and expected in r.reason, r.reason
    assert proc.is_running()


def test_a_pick_blocked_by_a_neighbour_moves_it_aside_first_and_says_where(gamp):
    from rad_ros.motion import moved_aside_from_msgs

    from scenes import packed
    _, plan = gamp
    scene = packed()
    target = scene.targets[0]
    plain = plan(scene, 'b4', 0, target.name, tuple(target.filled[-1]), 0)    # b1 lies too close for the fingers
    assert not plain.success and plain.failure == 'grasp' and 'hits block b1' in plain.reason
    r = plan(scene, 'b4', 0, target.name, tuple(target.filled[-1]), 0, move_aside=True)
    assert r.success, r.reason
    [aside] = moved_aside_from_msgs(r.moved_aside_blocks, r.moved_aside_poses)
    assert aside['block'] == 'b1' and aside['position'][2] == pytest.approx(scene.block('b1').position[2])
    assert [g.action for g in r.gripper].count('grasp') == 2
    spread = generate_scene(GeneratorConfig(grid=3), 5)        # nothing in the way: nothing moved
    free = plan(spread, *first_action(spread), move_aside=True)
    assert free.success and list(free.moved_aside_blocks) == [] and list(free.moved_aside_poses) == []


def test_parameters_set_on_the_running_node_apply_to_the_next_plan_or_are_refused(gamp, ros_node):
    """speed_scale changes the next trajectory's duration; values out of range and parameters read only
    at start are refused, with the reason, and change nothing."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import DescribeParameters, SetParameters
    proc, plan = gamp
    setter = wait_for_service(ros_node, SetParameters, '/gamp/set_parameters', timeout=10.0)
    describe = wait_for_service(ros_node, DescribeParameters, '/gamp/describe_parameters', timeout=10.0)

    def set_param(name, value):
        v = (ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value) if isinstance(value, float)
             else ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value))
        r = call_service(ros_node, setter, SetParameters.Request(parameters=[Parameter(name=name, value=v)]))
        return r.results[0]

    def duration(r):
        last = [t.points[-1].time_from_start for t in r.trajectories]
        return sum(d.sec + d.nanosec * 1e-9 for d in last)

    (speed, robot), = [call_service(ros_node, describe, DescribeParameters.Request(
        names=['speed_scale', 'robot'])).descriptors]
    assert not speed.read_only and speed.floating_point_range[0].to_value == 1.0 and robot.read_only
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    action = first_action(scene)
    fast = plan(scene, *action)
    assert fast.success, fast.reason
    refused = set_param('speed_scale', 1.5)
    assert not refused.successful and 'range' in refused.reason.lower(), refused.reason
    refused = set_param('robot', 'fr3')
    assert not refused.successful and 'read-only' in refused.reason.lower(), refused.reason
    again = plan(scene, *action)
    assert abs(duration(again) - duration(fast)) < 1e-6        # nothing changed
    done = set_param('speed_scale', 0.35)
    assert done.successful, done.reason
    slow = plan(scene, *action)
    assert slow.success and duration(slow) > 1.1 * duration(fast), (duration(slow), duration(fast))
    assert proc.is_running()

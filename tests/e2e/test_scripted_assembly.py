"""A scripted assembly through the node graph over real DDS.

The test picks the order (allocation poses whose block would rest fully supported,
lowest first), the gamp node plans each action from the twin's current scene state
and sends the JointTrajectory to the twin, and the twin executes it. The result is
checked from the published motion-capture poses, not from any internal state.
"""

import json

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.gamp.planner import placement_pose
from rad_core.sequencing import supported_actions
from ros_harness import call_service, ros_args, spin_until, wait_for_service


def yaw_of(q) -> float:
    return float(np.degrees(np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2)))) % 360


@pytest.mark.parametrize('seed', [5, 8])
def test_twin_builds_the_allocation_from_trajectories_over_dds(node_process, ros_node, tmp_path, seed):
    from rad_msgs.msg import RigidBodies
    from rad_msgs.srv import GetSceneState, PlanAction
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    scene = generate_scene(GeneratorConfig(grid=4), seed)
    path = tmp_path / 'scene.json'
    path.write_text(scene.dumps())
    twin = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path), 'real_time_factor': 10.0}))
    gamp = node_process('rad_gamp', 'gamp_node')
    events, joints, bodies = [], [], []
    ros_node.create_subscription(String, 'twin/events', lambda m: events.append(json.loads(m.data)), 10)
    ros_node.create_subscription(JointState, 'joint_states', joints.append, 10)
    ros_node.create_subscription(RigidBodies, 'rigid_bodies', bodies.append, qos_profile_sensor_data)
    state_client = wait_for_service(ros_node, GetSceneState, 'get_scene_state', timeout=30.0)
    plan_client = wait_for_service(ros_node, PlanAction, 'plan_action', timeout=30.0)
    spin_until(ros_node, lambda: joints, timeout=10.0)

    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    guide = AllocationGuide(scene, solve(scene).placements)
    expected = {}
    while True:
        candidates = supported_actions(env, guide.allowed_actions(env.state))
        executed = False
        for action in candidates:
            block_id = scene.blocks[action.block].id
            state = call_service(ros_node, state_client, GetSceneState.Request(), timeout=10.0)
            assert state.success, state.reason
            now = Scene.loads(state.scene_json)
            request = PlanAction.Request(scene_json=state.scene_json, execute=True,
                                         start_positions=list(joints[-1].position))
            r, i, j, k = env.grid.region_of[action.cell], *env.grid.ijk[action.cell]
            request.action.block_id, request.action.unit = block_id, action.unit
            request.action.target, request.action.rotation = scene.targets[r].name, action.rotation
            request.action.cell.i, request.action.cell.j, request.action.cell.k = int(i), int(j), int(k)
            events.clear()
            result = call_service(ros_node, plan_client, request, timeout=60.0)
            if not result.success:
                continue
            # The gamp node sends the motion through the twin's actions: one 'done' per arm trajectory.
            n = len(result.trajectories)
            spin_until(ros_node, lambda: sum(e['event'] == 'done' for e in events) == n
                       or any(e['event'] == 'rejected' for e in events), timeout=90.0)
            assert [e['event'] for e in events].count('done') == n, events
            expected[block_id] = placement_pose(now, block_id, action.unit, env.grid.centres[action.cell],
                                                action.rotation)
            env.step(action)
            executed = True
            break
        if not executed:
            break
    print('placed', expected)
    assert len(expected) >= 2, 'the scripted sequence placed fewer than two blocks'

    bodies.clear()
    spin_until(ros_node, lambda: bodies, timeout=10.0)
    seen = {b.rigid_body_name: b.pose for b in bodies[-1].rigidbodies}
    for block_id, (position, yaw) in expected.items():
        p = seen[block_id].position
        assert np.allclose([p.x, p.y, p.z], position, atol=0.005), (block_id, [p.x, p.y, p.z], position)
        assert abs((yaw_of(seen[block_id].orientation) - yaw + 180) % 360 - 180) < 3.0
    # Blocks nobody moved are where the scene put them.
    for block in scene.blocks:
        if block.id not in expected:
            p = seen[block.id].position
            assert np.allclose([p.x, p.y, p.z], block.position, atol=0.005), block.id
    assert twin.stop() == 0, twin.output_tail()
    assert gamp.stop() == 0, gamp.output_tail()

"""The rad_viz viz_node over real DDS: the twin's topics and a plan end up in the .rrd."""

import json
import re
import subprocess
import time

import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from ros_harness import ros_args, spin_until


def rrd(command: str, path) -> subprocess.CompletedProcess:
    return subprocess.run(['rerun', 'rrd', command, str(path)], capture_output=True, text=True, timeout=60,
                          check=False)


def entities(path) -> dict[str, int]:
    """Entity path -> number of chunks, from `rerun rrd stats`."""
    out = rrd('stats', path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split('Num chunks per entity')[1].split('\n\n')[0].splitlines()
    return {line.rsplit(':', 1)[0]: int(line.rsplit(':', 1)[1]) for line in lines if line.startswith('/')}


def plan_json(scene) -> str:
    alloc = solve(scene, AllocationParams(time_limit_s=5.0))
    steps = [{'block': f'step{i}', 'type': p.type, 'target': p.target, 'yaw': p.yaw,
              'cells': [list(c) for c in p.cells]} for i, p in enumerate(alloc.placements)]
    return json.dumps({'allocation': alloc.to_dict(), 'steps': steps,
                       'timings': {'allocate': alloc.solve_time_s, 'sequence': 0.1}, 'predicted_coverage': 1.0})


@pytest.fixture
def scene_file(tmp_path):
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    path = tmp_path / 'scene.json'
    path.write_text(scene.dumps())
    return scene, path


def test_viz_records_robot_blocks_cells_plan_and_exits_cleanly(node_process, ros_node, tmp_path, scene_file):
    from rad_msgs.msg import RigidBodies
    from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
    from std_msgs.msg import String

    scene, path = scene_file
    recording = tmp_path / 'recording.rrd'
    twin = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path)}))
    viz = node_process('rad_viz', 'viz_node', *ros_args({'recording_path': str(recording), 'log_rate_hz': 20.0}))
    # Latched, like /plan_assembly's publisher: viz gets it whenever it starts.
    pub = ros_node.create_publisher(
        String, 'plan_json', QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    plan = plan_json(scene)
    pub.publish(String(data=plan))
    bodies = []
    ros_node.create_subscription(RigidBodies, 'rigid_bodies', bodies.append, qos_profile_sensor_data)
    viz.wait_for_output('viz ready', timeout=30.0)
    assert spin_until(ros_node, lambda: pub.get_subscription_count() > 0 and bodies, timeout=30.0)
    # The twin's latched /scene and the plan may reach viz some time after it is ready (slow under load).
    viz.wait_for_output('scene logged', timeout=30.0)
    viz.wait_for_output('plan logged', timeout=30.0)
    spin_until(ros_node, lambda: False, timeout=2.5)    # let it log joint states and motion capture
    assert viz.stop(timeout=15.0) == 0, viz.output_tail()
    assert twin.is_running(), twin.output_tail()

    verify = rrd('verify', recording)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    found = entities(recording)
    expected = {'/world/table', '/world/panda/base', '/world/panda/tf_static', '/plan/summary', '/plan/step_text',
                '/plan/timings/allocate', '/plan/predicted_coverage', '/world/plan/step'}
    expected |= {f'/world/panda/visual_geometries/{link}/visual_0' for link in
                 ('panda_link0', 'panda_link3', 'panda_link7', 'panda_hand', 'panda_rightfinger')}
    expected |= {f'/world/panda/joints/panda_joint{i}' for i in range(1, 8)}
    expected |= {f'/world/blocks/{b.id}' for b in scene.blocks}
    expected |= {f'/world/targets/{t.name}/{kind}' for t in scene.targets for kind in ('target_cells', 'other_cells')}
    placements = json.loads(plan)['allocation']['placements']
    assert placements
    expected |= {f'/world/plan/allocation/{i}' for i in range(len(placements))}
    assert expected <= set(found), sorted(expected - set(found))
    # Joint states and motion capture kept coming: many chunks per moving entity (batched by the SDK),
    # and the log says how many frames were logged, no more than log_rate_hz allows.
    counts = viz.wait_for_output(r'joint_states (\d+), rigid_bodies (\d+)', timeout=5.0)
    joint_frames, body_frames = int(counts.group(1)), int(counts.group(2))
    assert joint_frames >= 5 and body_frames >= 5, viz.output_tail()
    assert joint_frames <= 20 * 40 and body_frames <= 20 * 40    # never more than the rate allows in the run
    stats = rrd('print', recording)
    assert 'ros_time' in stats.stdout or 'ros_time' in rrd('stats', recording).stdout


def test_bad_plan_json_is_reported_and_the_node_keeps_running(node_process, ros_node, tmp_path, scene_file):
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String

    _, path = scene_file
    recording = tmp_path / 'recording.rrd'
    node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path)}))
    viz = node_process('rad_viz', 'viz_node', *ros_args({'recording_path': str(recording)}))
    pub = ros_node.create_publisher(
        String, 'plan_json', QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    viz.wait_for_output('viz ready', timeout=30.0)
    spin_until(ros_node, lambda: pub.get_subscription_count() > 0, timeout=15.0)
    pub.publish(String(data='{"steps": [{"block": "b0"}]}'))
    viz.wait_for_output(r'plan_json not shown: steps\[0\] lacks type', timeout=10.0)
    time.sleep(0.5)
    assert viz.is_running()
    assert viz.stop(timeout=15.0) == 0, viz.output_tail()
    assert rrd('verify', recording).returncode == 0
    assert '/world/plan/allocation/0' not in entities(recording)


def test_streams_live_to_a_loopback_rerun_server_and_survives_a_missing_one(node_process, process, tmp_path):
    import shutil
    import socket

    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    url = f'rerun+http://127.0.0.1:{port}/proxy'
    missing = node_process('rad_viz', 'viz_node', *ros_args({'recording_path': str(tmp_path / 'a.rrd'),
                                                             'connect_url': url}))
    missing.wait_for_output(r'connect_url .*nothing listens there', timeout=30.0)
    missing.wait_for_output(r'viz ready: recording', timeout=10.0)
    assert missing.stop(timeout=15.0) == 0, missing.output_tail()
    assert rrd('verify', tmp_path / 'a.rrd').returncode == 0

    server = process([shutil.which('rerun'), '--serve-grpc', '--bind', '127.0.0.1', '--port', str(port)], name='rerun')
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        try:
            socket.create_connection(('127.0.0.1', port), timeout=0.2).close()
            break
        except OSError:
            time.sleep(0.2)
    live = node_process('rad_viz', 'viz_node', *ros_args({'recording_path': str(tmp_path / 'b.rrd'),
                                                          'connect_url': url}))
    live.wait_for_output(r'viz ready: recording .*, live ' + re.escape(url), timeout=30.0)
    assert live.stop(timeout=15.0) == 0, live.output_tail()
    assert server.is_running()
    assert '/world/panda/visual_geometries/panda_hand/visual_0' in entities(tmp_path / 'b.rrd')


def test_markers_for_rviz_show_the_scene_within_5_s_then_the_plan_and_moved_blocks(node_process, ros_node,
                                                                                    scene_file):
    """markers_node: a latched MarkerArray of the target cells and every block in the base frame within 5 s
    of the twin's scene; the allocation's poses and the next step once a plan is published; a block moved
    in the twin is drawn where motion capture sees it."""
    from rad_msgs.srv import SetBlockPose
    from rad_ros.motion import pose_msg
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String
    from visualization_msgs.msg import Marker, MarkerArray
    from ros_harness import call_service, wait_for_service

    scene, path = scene_file
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    got = []
    ros_node.create_subscription(MarkerArray, 'markers', got.append, latched)
    markers = node_process('rad_viz', 'markers_node')
    markers.wait_for_output('markers ready', timeout=30.0)
    twin = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path)}))
    twin.wait_for_output(r'\[twin\]: active', timeout=30.0)
    t0 = time.monotonic()
    assert spin_until(ros_node, lambda: got, timeout=10.0)
    assert time.monotonic() - t0 < 5.0

    def by_ns(msg):
        out = {}
        for m in msg.markers:
            out.setdefault(m.ns, []).append(m)
        return out

    first = by_ns(got[-1])
    assert got[-1].markers[0].action == Marker.DELETEALL
    assert sum(len(m.points) for m in first['target']) == scene.num_target_cells
    assert len(first['blocks']) == len(scene.blocks) and 'allocation' not in first
    assert {m.header.frame_id for m in got[-1].markers} == {'world'}
    plan = json.loads(plan_json(scene))
    pub = ros_node.create_publisher(String, 'plan_json', latched)
    pub.publish(String(data=json.dumps(plan)))
    assert spin_until(ros_node, lambda: 'allocation' in by_ns(got[-1]), timeout=10.0)
    drawn = by_ns(got[-1])
    assert len(drawn['allocation']) == len(plan['steps']) and len(drawn['next_step']) == 1
    first_cell = plan['steps'][0]['cells'][0]
    region = scene.target(plan['steps'][0]['target'])
    centre = region.cell_center(tuple(first_cell), scene.unit)
    assert any(abs(p.x - centre[0]) + abs(p.y - centre[1]) + abs(p.z - centre[2]) < 1e-6
               for p in drawn['next_step'][0].points)
    # A block moved in the twin is drawn where motion capture then sees it.
    from rad_msgs.msg import RigidBodies
    from rclpy.qos import qos_profile_sensor_data
    seen = {}
    ros_node.create_subscription(RigidBodies, 'rigid_bodies',
                                 lambda m: seen.update({b.rigid_body_name: b.pose.position for b in m.rigidbodies}),
                                 qos_profile_sensor_data)
    block = scene.blocks[0]
    client = wait_for_service(ros_node, SetBlockPose, 'set_block_pose', timeout=10.0)
    moved = (block.position[0], block.position[1] - 0.05, block.position[2])
    r = call_service(ros_node, client, SetBlockPose.Request(block_id=block.id, pose=pose_msg(moved, (0, 0, 0, 1))))
    assert r.success, r.reason
    spin_until(ros_node, lambda: False, timeout=1.5)          # it settles; motion capture reports it
    at = seen[block.id]
    assert abs(at.y - block.position[1]) > 0.03                # it did move

    def drawn_there():
        blocks = by_ns(got[-1]).get('blocks', [])
        return any(abs(p.x - at.x) + abs(p.y - at.y) + abs(p.z - at.z) < 3e-3 for m in blocks for p in m.points)
    assert spin_until(ros_node, drawn_there, timeout=10.0)
    assert markers.is_running() and twin.is_running()

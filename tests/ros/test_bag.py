"""rad_ros.bag and `ros2 run rad_planner bag`: a run recorded as rosbag2-layout MCAP and replayed into RViz's
markers and Rerun, with nothing but the bag publishing."""

import json
import subprocess
from pathlib import Path

import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from ros_harness import executable_path, ros_args, spin_until, wait_for_plant

RUN_TOPICS = {'/scene', '/robot_description', '/plan_json', '/joint_states', '/rigid_bodies', '/tf'}
LATCHED_TOPICS = {'/scene', '/robot_description', '/plan_json', '/tf_static'}   # the twin's world -> panda_link0


def test_the_schema_of_a_nested_type_is_its_msg_then_each_dependency_once_as_rosbag2_writes_it():
    from ament_index_python.packages import get_package_share_directory
    from mcap_ros2._dynamic import generate_dynamic
    from rad_ros.bag import DELIMITER, message_definition
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    text = message_definition('sensor_msgs/msg/JointState')
    sections = text.split(f'\n{DELIMITER}\n')
    share = Path(get_package_share_directory('sensor_msgs'))
    assert sections[0] == (share / 'msg' / 'JointState.msg').read_text()
    assert [s.splitlines()[0] for s in sections[1:]] == ['MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert sections[1].split('\n', 1)[1] == (Path(get_package_share_directory('std_msgs')) / 'msg' /
                                             'Header.msg').read_text()
    # mcap_ros2 (what Foxglove's readers do) decodes real CDR with it.
    msg = JointState(name=['a', 'b'], position=[0.5, -1.0])
    msg.header.stamp.sec, msg.header.frame_id = 7, 'world'
    decoded = generate_dynamic('sensor_msgs/msg/JointState', text)['sensor_msgs/msg/JointState'](
        serialize_message(msg))
    assert (decoded.name, list(decoded.position), decoded.header.stamp.sec, decoded.header.frame_id) == \
        (['a', 'b'], [0.5, -1.0], 7, 'world')
    # A workspace type: every nested rad_msgs type once, none missing.
    scene = message_definition('rad_msgs/msg/Scene')
    headers = [line for line in scene.splitlines() if line.startswith('MSG: ')]
    assert len(headers) == len(set(headers)) and 'MSG: rad_msgs/Block' in headers
    generate_dynamic('rad_msgs/msg/Scene', scene)


def test_offered_qos_is_written_as_rosbag2_does_and_read_back_latched_or_best_effort():
    import yaml
    from rad_ros.bag import BagError, qos_profiles_yaml, replay_qos
    from rad_ros.qos import LATCHED
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy, qos_profile_sensor_data

    written = qos_profiles_yaml([LATCHED])
    entry = yaml.safe_load(written)[0]
    assert entry['history'] == 'keep_last' and entry['depth'] == 1
    assert (entry['reliability'], entry['durability'], entry['liveliness']) == ('reliable', 'transient_local',
                                                                               'system_default')
    assert entry['deadline'] == {'sec': 0, 'nsec': 0}
    latched = replay_qos(written, '/scene')
    assert latched.durability == DurabilityPolicy.TRANSIENT_LOCAL and latched.depth == 1
    sensor = replay_qos(qos_profiles_yaml([qos_profile_sensor_data]), '/rigid_bodies')
    assert sensor.reliability == ReliabilityPolicy.BEST_EFFORT
    # rosbag2 metadata version 8 and older: the rmw enums' numbers.
    old = replay_qos('- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n', '/scene')
    assert old.reliability == ReliabilityPolicy.RELIABLE and old.durability == DurabilityPolicy.TRANSIENT_LOCAL
    with pytest.raises(BagError, match="/scene: offered_qos_profiles has DurabilityPolicy 'sticky'"):
        replay_qos('- durability: sticky\n', '/scene')


def test_the_shipped_ros2_bag_qos_overrides_latch_exactly_the_latched_topics():
    import yaml
    from ament_index_python.packages import get_package_share_directory
    from rad_ros.bag import BAG_TOPICS

    path = Path(get_package_share_directory('rad_planner')) / 'config' / 'bag_qos_overrides.yaml'
    overrides = yaml.safe_load(path.read_text())
    assert set(overrides) == {'/' + t.name.lstrip('/') for t in BAG_TOPICS if t.latched}
    assert all(o == {'reliability': 'reliable', 'durability': 'transient_local', 'history': 'keep_last', 'depth': 1}
               for o in overrides.values())


def test_cli_errors_are_one_line_and_name_the_file(tmp_path):
    bag = str(executable_path('rad_planner', 'bag'))
    missing = subprocess.run([bag, 'info', str(tmp_path / 'nope.mcap')], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 1 and missing.stderr.strip() == f'bag: {tmp_path / "nope.mcap"}: no such bag file'
    (tmp_path / 'text.mcap').write_text('not a bag')
    foreign = subprocess.run([bag, 'play', str(tmp_path / 'text.mcap')], capture_output=True, text=True, timeout=60)
    assert foreign.returncode == 1 and 'text.mcap: not a readable MCAP file' in foreign.stderr, foreign.stderr
    assert len(foreign.stderr.strip().splitlines()) == 1


def plan_json(scene) -> str:
    """A plan as /plan_assembly publishes it: the allocation and one step per placement."""
    alloc = solve(scene, AllocationParams(time_limit_s=5.0))
    steps = [{'block': f'step{i}', 'type': p.type, 'target': p.target, 'yaw': p.yaw,
              'cells': [list(c) for c in p.cells]} for i, p in enumerate(alloc.placements)]
    return json.dumps({'allocation': alloc.to_dict(), 'steps': steps, 'timings': {}, 'predicted_coverage': 1.0})


def rrd_entities(path) -> set[str]:
    out = subprocess.run(['rerun', 'rrd', 'stats', str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split('Num chunks per entity')[1].split('\n\n')[0].splitlines()
    return {line.rsplit(':', 1)[0] for line in lines if line.startswith('/')}


def check_bag(path: Path, scene) -> None:
    """The file as `ros2 bag` reads it: rosbag2's layout, every run topic with messages, all decodable."""
    import yaml
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert reader.get_header().profile == 'ros2'
        channels = {c.topic: c for c in summary.channels.values()}
        assert RUN_TOPICS <= set(channels), sorted(channels)
        counts = summary.statistics.channel_message_counts
        assert all(counts[channels[t].id] > 0 for t in RUN_TOPICS)
        assert counts[channels['/joint_states'].id] >= 20            # 50 Hz for a few seconds
        for topic, channel in channels.items():
            schema = summary.schemas[channel.schema_id]
            assert (channel.message_encoding, schema.encoding) == ('cdr', 'ros2msg')
            assert '/msg/' in schema.name
            durability = yaml.safe_load(channel.metadata['offered_qos_profiles'])[0]['durability']
            assert (durability == 'transient_local') == (topic in LATCHED_TOPICS), (topic, durability)
        metadata = [m for m in reader.iter_metadata() if m.name == 'rosbag2']
        assert len(metadata) == 1
        bag_metadata = yaml.safe_load(metadata[0].metadata['serialized_metadata'])
        assert bag_metadata['version'] == 9 and bag_metadata['storage_identifier'] == 'mcap'
        assert bag_metadata['message_count'] == summary.statistics.message_count
        decoded = {}
        for _, channel, _, msg in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, msg)
    assert sorted(b.id for b in decoded['/scene'].blocks) == sorted(b.id for b in scene.blocks)
    assert json.loads(decoded['/plan_json'].data)['steps']


def test_a_recorded_run_replays_into_rviz_markers_and_rerun_with_no_twin(node_process, ros_node, tmp_path):
    """The twin's run (and a latched plan) recorded with `bag record` started after the latched topics were
    published; then, the twin gone, `bag play` alone feeds the markers node (RViz's MarkerArray) and the Rerun
    viz node."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String
    from visualization_msgs.msg import MarkerArray

    scene = generate_scene(GeneratorConfig(grid=3), 5)
    scene_path = tmp_path / 'scene.json'
    scene_path.write_text(scene.dumps())
    bag_path = tmp_path / 'run.mcap'
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)

    # Record: the twin and a latched plan are up before the recorder starts.
    twin = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(scene_path)}))
    plan_pub = ros_node.create_publisher(String, 'plan_json', latched)
    plan_pub.publish(String(data=plan_json(scene)))
    wait_for_plant(ros_node, timeout=30.0)
    recorder = node_process('rad_planner', 'bag', 'record', '-o', str(bag_path))
    recorder.wait_for_output('bag recording: ', timeout=30.0)
    for topic in sorted(RUN_TOPICS):
        recorder.wait_for_output(f'first message on {topic}\\n', timeout=20.0)
    spin_until(ros_node, lambda: False, timeout=2.0)
    assert recorder.stop(timeout=15.0) == 0, recorder.output_tail()
    recorded = recorder.wait_for_output(r'bag recorded: (\d+) messages', timeout=1.0)
    assert int(recorded.group(1)) > 0
    ros_node.destroy_publisher(plan_pub)
    assert twin.stop(timeout=15.0) == 0, twin.output_tail()
    check_bag(bag_path, scene)
    info = subprocess.run([str(executable_path('rad_planner', 'bag')), 'info', str(bag_path)],
                          capture_output=True, text=True, timeout=60)
    assert info.returncode == 0, info.stderr
    assert any(line.split()[:2] == ['/scene', 'rad_msgs/msg/Scene'] and line.endswith('latched')
               for line in info.stdout.splitlines()), info.stdout

    # Replay into RViz-ready markers and Rerun, nothing else publishing the scene.
    got = []
    ros_node.create_subscription(MarkerArray, 'markers', got.append, latched)
    rrd = tmp_path / 'replay.rrd'
    markers = node_process('rad_viz', 'markers_node')
    viz = node_process('rad_viz', 'viz_node', *ros_args({'recording_path': str(rrd)}))
    markers.wait_for_output('markers ready', timeout=30.0)
    viz.wait_for_output('viz ready', timeout=30.0)

    def drawn(ns):
        return got and sum(m.ns == ns for m in got[-1].markers)

    spin_until(ros_node, lambda: False, timeout=0.5)
    assert not drawn('blocks'), 'markers drew a scene before the replay: something else publishes /scene'
    player = node_process('rad_planner', 'bag', 'play', str(bag_path), '--delay', '1.0')
    assert spin_until(ros_node, lambda: drawn('blocks') == len(scene.blocks) and drawn('allocation'),
                      timeout=20.0), player.output_tail() + markers.output_tail()
    viz.wait_for_output('scene logged', timeout=20.0)
    viz.wait_for_output('plan logged', timeout=20.0)
    assert player.wait(timeout=20.0) == 0, player.output_tail()
    played = player.wait_for_output(r'bag played: (\d+) messages', timeout=1.0)
    assert int(played.group(1)) == int(recorded.group(1))
    assert viz.stop(timeout=15.0) == 0, viz.output_tail()
    frames = viz.wait_for_output(r'joint_states (\d+), rigid_bodies (\d+)', timeout=5.0)
    assert int(frames.group(1)) > 0 and int(frames.group(2)) > 0, viz.output_tail()
    entities = rrd_entities(rrd)
    expected = {f'/world/blocks/{b.id}' for b in scene.blocks} | {'/world/plan/allocation/0', '/plan/summary'}
    assert expected <= entities, sorted(expected - entities)
    assert markers.is_running()

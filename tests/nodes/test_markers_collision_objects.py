"""markers_node with collision_objects on, over real DDS: the twin's blocks reach /collision_object as MoveIt
2's move_group reads them (moveit_msgs/CollisionObject, reliable and volatile as its subscription)."""

import time

from rad_core.domain.generator import GeneratorConfig, generate_scene
from ros_harness import ros_args, spin_until


def test_each_block_arrives_as_one_collision_object_within_5_s_and_again_for_a_new_subscriber(
        node_process, ros_node, tmp_path):
    from moveit_msgs.msg import CollisionObject
    from rad_msgs.msg import Scene as SceneMsg
    from rad_ros.qos import LATCHED
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from shape_msgs.msg import SolidPrimitive

    scene = generate_scene(GeneratorConfig(grid=3), 5)
    path = tmp_path / 'scene.json'
    path.write_text(scene.dumps())
    expected = {f'rad/block/{b.id}': len(scene.block_types[b.type].offsets)
                for b in scene.blocks if not scene.in_feeder(b.id)}
    assert expected
    # move_group's subscription: rclcpp::ServicesQoS (reliable, volatile, depth 10).
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    got = {}
    ros_node.create_subscription(CollisionObject, '/collision_object', lambda m: got.setdefault(m.id, m), qos)
    markers = node_process('rad_viz', 'markers_node', *ros_args({'collision_objects': True}))
    markers.wait_for_output('collision objects on /collision_object', timeout=30.0)
    # Timed from the twin's scene, as the test sees it (latched /scene).
    scenes = []
    ros_node.create_subscription(SceneMsg, 'scene', lambda m: scenes.append(time.monotonic()), LATCHED)
    twin = node_process('rad_sim', 'twin_node', *ros_args({'scene_file': str(path)}))
    assert spin_until(ros_node, lambda: scenes, timeout=30.0), twin.output_tail()
    t0 = scenes[0]
    assert spin_until(ros_node, lambda: set(got) >= set(expected), timeout=10.0), (sorted(got), markers.output_tail())
    assert time.monotonic() - t0 < 5.0
    assert set(got) == set(expected)
    for oid, units in expected.items():
        obj = got[oid]
        assert obj.operation == CollisionObject.ADD and obj.header.frame_id == 'world'
        assert len(obj.primitives) == len(obj.primitive_poses) == units
        assert {p.type for p in obj.primitives} == {SolidPrimitive.BOX}
    # A subscriber that joins later (a restarted move_group) gets every object again.
    late = {}
    ros_node.create_subscription(CollisionObject, '/collision_object', lambda m: late.setdefault(m.id, m), qos)
    assert spin_until(ros_node, lambda: set(late) == set(expected), timeout=10.0), sorted(late)
    assert markers.is_running() and twin.is_running()

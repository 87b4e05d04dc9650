"""rad_ros.collision_objects: a scene's blocks as MoveIt collision objects, on message types alone (no DDS)."""

import math

import numpy as np
from moveit_msgs.msg import CollisionObject
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion
from rad_ros.collision_objects import OBJECT_PREFIX, block_objects, changes, object_id
from shape_msgs.msg import SolidPrimitive

from scenes import U, doc, scene


def world_boxes(obj):
    """(centre, size) of each box of an object, in the header's frame."""
    p, q = obj.pose.position, obj.pose.orientation
    turn = matrix_from_quaternion((q.x, q.y, q.z, q.w))
    out = []
    for prim, pose in zip(obj.primitives, obj.primitive_poses):
        local = np.array([pose.position.x, pose.position.y, pose.position.z])
        out.append((np.array([p.x, p.y, p.z]) + turn @ local, np.array(prim.dimensions)))
    return out


def test_one_object_per_block_one_unit_box_per_cube_in_the_base_frame():
    s = scene()
    objects = block_objects(s, 'panda_link0')
    assert list(objects) == [f'rad/block/{b.id}' for b in s.blocks] == [object_id(b.id) for b in s.blocks]
    for block in s.blocks:
        obj = objects[OBJECT_PREFIX + block.id]
        assert obj.id == OBJECT_PREFIX + block.id and obj.operation == CollisionObject.ADD
        assert obj.header.frame_id == 'panda_link0'
        assert len(obj.primitives) == len(obj.primitive_poses) == len(s.block_types[block.type].offsets)
        assert all(p.type == SolidPrimitive.BOX for p in obj.primitives)
        assert not (obj.meshes or obj.planes or obj.subframe_names)
        # The boxes fill the block's units exactly: full unit cubes (no clearance here) at the unit centres.
        got = sorted(tuple(np.round(c, 9)) for c, _ in world_boxes(obj))
        assert got == sorted(tuple(np.round(c, 9)) for c in s.unit_positions(block))
        assert all(np.allclose(size, U) for _, size in world_boxes(obj))
    turned = objects['rad/block/i0'].pose.orientation      # i0 lies at yaw 90
    assert np.allclose((turned.x, turned.y, turned.z, turned.w), yaw_quaternion(90))


def test_clearance_sets_the_outer_side_faces_back():
    s = Scene.from_dict({**doc(), 'clearance': 0.2})
    (centre, size), = world_boxes(block_objects(s, 'world')['rad/block/c0'])
    assert np.allclose(size, (0.8 * U, 0.8 * U, U)) and np.allclose(centre, s.block('c0').position)
    # I2 at yaw 90: its two units touch (the shared face is not set back), the outer ones are.
    boxes = world_boxes(block_objects(s, 'world')['rad/block/i0'])
    sizes = sorted(tuple(np.round(sz, 9)) for _, sz in boxes)
    assert sizes == [tuple(np.round((0.9 * U, 0.8 * U, U), 9))] * 2
    ys = sorted(c[1] for c, _ in boxes)
    assert math.isclose(ys[1] - ys[0], 0.9 * U)                # x of the block is y of the base frame


def test_a_pose_from_motion_capture_moves_the_whole_block():
    s = scene()
    q = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))     # knocked over: 90 degrees about y
    obj = block_objects(s, 'world', {'i0': ((0.1, 0.2, 0.3), q)})['rad/block/i0']
    centres = sorted(tuple(np.round(c, 9)) for c, _ in world_boxes(obj))
    assert centres == [(0.1, 0.2, round(0.3 - U, 9)), (0.1, 0.2, 0.3)]   # the bar now stands upright


def test_feeder_blocks_appear_only_where_motion_capture_sees_them():
    d = doc()
    d['blocks'] = d['blocks'] + [{'id': 'f0', 'type': 'cube'}, {'id': 'f1', 'type': 'cube'}]
    d['feeder'] = {'station': [0.3, -0.4], 'blocks': ['f0', 'f1']}
    s = Scene.from_dict(d)
    assert 'rad/block/f0' not in block_objects(s, 'world') and 'rad/block/f1' not in block_objects(s, 'world')
    seen = block_objects(s, 'world', {'f0': (s.block('f0').position, (0, 0, 0, 1))})
    assert 'rad/block/f0' in seen and 'rad/block/f1' not in seen


def test_changes_add_new_and_moved_objects_and_remove_those_of_gone_blocks():
    s = scene()
    first = block_objects(s, 'world')
    sent = changes({}, first, 'world')
    assert [o.id for o in sent] == list(first) and {o.operation for o in sent} == {CollisionObject.ADD}
    assert changes(first, block_objects(s, 'world'), 'world') == []           # nothing new: nothing sent
    c0 = s.block('c0').position
    jitter = block_objects(s, 'world', {'c0': ((c0[0] + 4e-4, c0[1], c0[2]), (0, 0, 0, 1))})
    assert changes(first, jitter, 'world') == []                            # motion-capture noise
    moved = block_objects(s, 'world', {'c0': ((c0[0] + 0.02, c0[1], c0[2]), (0, 0, 0, 1))})
    out = changes(first, moved, 'world')
    assert [(o.id, o.operation) for o in out] == [('rad/block/c0', CollisionObject.ADD)]
    assert math.isclose(out[0].pose.position.x, c0[0] + 0.02)
    # c1 left the scene (placed blocks are renamed, swept away, ...): its object is removed.
    fewer = Scene.from_dict(doc(blocks=[b for b in doc()['blocks'] if b['id'] != 'c1']))
    out = changes(first, block_objects(fewer, 'world'), 'world')
    assert [(o.id, o.operation) for o in out] == [('rad/block/c1', CollisionObject.REMOVE)]
    assert out[0].header.frame_id == 'world' and not out[0].primitives

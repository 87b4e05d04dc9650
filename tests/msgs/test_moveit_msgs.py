"""moveit_msgs and object_recognition_msgs (ros_ws/src subsets, or a system install) match upstream's Jazzy definitions.

The expected fields, constants and RIHS01 type hashes below come from moveit/moveit_msgs,
branch `ros2`, tag 2.6.0 (commit 55f802fe3ac4, the release in Jazzy), msg/CollisionObject.msg,
and wg-perception/object_recognition_msgs, branch `ros2`, 2.0.0 (commit c31772fc3f21),
msg/ObjectType.msg. The hashes were taken from a build of those two files, verbatim, against
the Jazzy common_interfaces (std_msgs, geometry_msgs, shape_msgs): a type's RIHS01 hash covers
only its own fields and the types it refers to, so the rest of upstream's packages does not enter
it. move_group compares type hashes, so a drift in any field, type, constant or field order would
make it ignore the blocks rad publishes on /collision_object.
Message types alone: no rclpy.init, no DDS.
"""

import pytest
from interfaces import installed_type_hashes, rosidl_constants
from moveit_msgs.msg import CollisionObject
from object_recognition_msgs.msg import ObjectType

POSES = 'sequence<geometry_msgs/Pose>'

# (type, fields in declaration order) exactly as upstream declares them.
FIELDS = [
    (CollisionObject, [
        ('header', 'std_msgs/Header'),
        ('pose', 'geometry_msgs/Pose'),
        ('id', 'string'),
        ('type', 'object_recognition_msgs/ObjectType'),
        ('primitives', 'sequence<shape_msgs/SolidPrimitive>'), ('primitive_poses', POSES),
        ('meshes', 'sequence<shape_msgs/Mesh>'), ('mesh_poses', POSES),
        ('planes', 'sequence<shape_msgs/Plane>'), ('plane_poses', POSES),
        ('subframe_names', 'sequence<string>'), ('subframe_poses', POSES),
        ('operation', 'octet'),
    ]),
    (ObjectType, [('key', 'string'), ('db', 'string')]),
]

CONSTANTS = [
    # `byte` constants: rosidl's Python gives them as one-byte bytes.
    (CollisionObject, {'ADD': b'\x00', 'REMOVE': b'\x01', 'APPEND': b'\x02', 'MOVE': b'\x03'}),
    (ObjectType, {}),
]

UPSTREAM_HASHES = {
    ('moveit_msgs', 'msg/CollisionObject'): {
        'moveit_msgs/msg/CollisionObject': 'RIHS01_74b0acd6d56be032bf4f764b2c2633f50588b5fb2bd71e97206c59052747cf7e',
        'object_recognition_msgs/msg/ObjectType':
            'RIHS01_5eb3ee3976403366d7c50d7dbee8bec96b3bced1e752674a7194a35841632134',
        # shape_msgs as Jazzy's common_interfaces define it.
        'shape_msgs/msg/SolidPrimitive': 'RIHS01_2802a15190aadc3f496584df4b0b4c5824d8a0b31aaef839faa75bc34dda38ac',
    },
    ('object_recognition_msgs', 'msg/ObjectType'): {
        'object_recognition_msgs/msg/ObjectType':
            'RIHS01_5eb3ee3976403366d7c50d7dbee8bec96b3bced1e752674a7194a35841632134',
    },
}


@pytest.mark.parametrize('cls, fields', FIELDS, ids=[cls.__name__ for cls, _ in FIELDS])
def test_fields_match_upstream_in_name_type_and_order(cls, fields):
    assert list(cls.get_fields_and_field_types().items()) == fields


@pytest.mark.parametrize('cls, constants', CONSTANTS, ids=[cls.__name__ for cls, _ in CONSTANTS])
def test_constants_match_upstream(cls, constants):
    assert rosidl_constants(cls) == constants


def test_upstream_declares_no_default_values():
    obj = CollisionObject()
    assert obj.operation == CollisionObject.ADD == b'\x00'
    assert (obj.id, obj.type.key, obj.type.db) == ('', '', '')
    assert not (obj.primitives or obj.meshes or obj.planes or obj.subframe_names)


@pytest.mark.parametrize('package, interface', sorted(UPSTREAM_HASHES), ids='/'.join)
def test_type_hashes_match_upstream_jazzy(package, interface):
    hashes = installed_type_hashes(package, interface)
    expected = UPSTREAM_HASHES[package, interface]
    assert {name: hashes.get(name) for name in expected} == expected

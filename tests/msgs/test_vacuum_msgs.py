"""franka_vacuum_gripper's actions (ros_ws/src, or a system install) are franka_ros's, field for field.

Upstream: frankaemika/franka_ros, franka_vacuum_gripper/action/{Vacuum,DropOff,Stop}.action
(commit 4684af760b6d). ROS 1 has no type hashes to compare; the fields, their types and their
order are the contract. Message types alone: no rclpy.init, no DDS.
"""

import pytest
from franka_vacuum_gripper.action import DropOff, Stop, Vacuum

FIELDS = [
    (Vacuum.Goal, [('vacuum', 'int8'), ('timeout', 'int8')]),
    (Vacuum.Result, [('success', 'boolean'), ('error', 'string')]),
    (Vacuum.Feedback, []),
    (DropOff.Goal, [('timeout', 'int8')]),
    (DropOff.Result, [('success', 'boolean'), ('error', 'string')]),
    (DropOff.Feedback, []),
    (Stop.Goal, []),
    (Stop.Result, [('success', 'boolean'), ('error', 'string')]),
    (Stop.Feedback, []),
]


def _fields(msg_type) -> list[tuple[str, str]]:
    # A message without fields gets one placeholder member from rosidl; upstream has none.
    fields = msg_type.get_fields_and_field_types().items()
    return [(k, v) for k, v in fields if k != 'structure_needs_at_least_one_member']


@pytest.mark.parametrize('msg_type, fields', FIELDS, ids=[f'{t.__module__}.{t.__name__}' for t, _ in FIELDS])
def test_fields_types_and_order_are_upstreams(msg_type, fields):
    assert _fields(msg_type) == fields


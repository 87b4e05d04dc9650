"""control_msgs (ros_ws/src/control_msgs, or a system install) matches upstream's Jazzy definitions.

The expected fields, constants and RIHS01 type hashes below come from
ros-controls/control_msgs, branch `jazzy`, tag 5.8.0 (commit f901df2662f2),
control_msgs/{action,msg}/*; the hashes were taken from a build of that full upstream
package. Jazzy peers compare type hashes, so a drift in any field, type, default or field
order here would make rad unable to talk to ros2_controllers and franka_ros2.
Message types alone: no rclpy.init, no DDS.
"""

import pytest
from interfaces import installed_type_hashes, rosidl_constants
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg
from control_msgs.msg import JointComponentTolerance, JointTolerance

TRAJ_POINT = 'trajectory_msgs/JointTrajectoryPoint'
MULTI_DOF_POINT = 'trajectory_msgs/MultiDOFJointTrajectoryPoint'
GRIPPER_STATE = [('position', 'double'), ('effort', 'double'), ('stalled', 'boolean'), ('reached_goal', 'boolean')]

# (type, fields in declaration order) exactly as upstream declares them.
FIELDS = [
    (FollowJointTrajectory.Goal, [
        ('trajectory', 'trajectory_msgs/JointTrajectory'),
        ('multi_dof_trajectory', 'trajectory_msgs/MultiDOFJointTrajectory'),
        ('path_tolerance', 'sequence<control_msgs/JointTolerance>'),
        ('component_path_tolerance', 'sequence<control_msgs/JointComponentTolerance>'),
        ('goal_tolerance', 'sequence<control_msgs/JointTolerance>'),
        ('component_goal_tolerance', 'sequence<control_msgs/JointComponentTolerance>'),
        ('goal_time_tolerance', 'builtin_interfaces/Duration'),
    ]),
    (FollowJointTrajectory.Result, [('error_code', 'int32'), ('error_string', 'string')]),
    # Jazzy's feedback has no `index`/`multi_dof_index` (those came with control_msgs 6, master).
    (FollowJointTrajectory.Feedback, [
        ('header', 'std_msgs/Header'),
        ('joint_names', 'sequence<string>'),
        ('desired', TRAJ_POINT), ('actual', TRAJ_POINT), ('error', TRAJ_POINT),
        ('multi_dof_joint_names', 'sequence<string>'),
        ('multi_dof_desired', MULTI_DOF_POINT), ('multi_dof_actual', MULTI_DOF_POINT),
        ('multi_dof_error', MULTI_DOF_POINT),
    ]),
    (GripperCommand.Goal, [('command', 'control_msgs/GripperCommand')]),
    (GripperCommand.Result, GRIPPER_STATE),
    (GripperCommand.Feedback, GRIPPER_STATE),
    (GripperCommandMsg, [('position', 'double'), ('max_effort', 'double')]),
    (JointTolerance, [('name', 'string'), ('position', 'double'), ('velocity', 'double'),
                      ('acceleration', 'double')]),
    (JointComponentTolerance, [('joint_name', 'string'), ('component', 'uint16'), ('position', 'double'),
                               ('velocity', 'double'), ('acceleration', 'double')]),
]

CONSTANTS = [
    (FollowJointTrajectory.Result, {'SUCCESSFUL': 0, 'INVALID_GOAL': -1, 'INVALID_JOINTS': -2,
                                    'OLD_HEADER_TIMESTAMP': -3, 'PATH_TOLERANCE_VIOLATED': -4,
                                    'GOAL_TOLERANCE_VIOLATED': -5}),
    (JointComponentTolerance, {'X_AXIS': 1, 'Y_AXIS': 2, 'Z_AXIS': 3, 'TRANSLATION': 4, 'ROTATION': 5}),
    (FollowJointTrajectory.Goal, {}), (FollowJointTrajectory.Feedback, {}),
    (GripperCommand.Goal, {}), (GripperCommand.Result, {}), (GripperCommand.Feedback, {}),
    (GripperCommandMsg, {}), (JointTolerance, {}),
]

# RIHS01 hashes of upstream control_msgs 5.8.0 (jazzy), against the Jazzy common_interfaces.
UPSTREAM_HASHES = {
    'action/FollowJointTrajectory': {
        'control_msgs/action/FollowJointTrajectory':
            'RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6',
        'control_msgs/action/FollowJointTrajectory_Goal':
            'RIHS01_8a9060704b269608f5a340934cc26e66869dd14bdac29e2e7fd9ec8b9882d205',
        'control_msgs/action/FollowJointTrajectory_Result':
            'RIHS01_8002e99ed2c14c6faa522f2a93c26d744c5982f254f9e98ff9c6f19789bdb220',
        'control_msgs/action/FollowJointTrajectory_Feedback':
            'RIHS01_3fd0aaecf71725121ae1ff7f01098a5e0da581e672be18a6b2c286cb43d96b49',
    },
    'action/GripperCommand': {
        'control_msgs/action/GripperCommand':
            'RIHS01_e17c0e644eccf14bea84a0a93e0977182872c2eb7873ca6694900059b46dbc84',
        'control_msgs/action/GripperCommand_Goal':
            'RIHS01_607d9f41eb241e1922e90f02125e87ae6bfb78f7f64a71dc92630263d01f8b6d',
        'control_msgs/action/GripperCommand_Result':
            'RIHS01_bf512d5aa6a0e4fe4d8be22b2ec4a1973c3d250fa1f65e47450322c25c45c0a0',
        'control_msgs/action/GripperCommand_Feedback':
            'RIHS01_8f7c520077bab528bb9161ee3b83c81eee1f8aecadb8922ce82c79d667a819c4',
    },
    'msg/GripperCommand': {
        'control_msgs/msg/GripperCommand': 'RIHS01_57eb8f326c9889ca8bb34ead82cc94cc09bf6bc5c3b6c09546dca3a00b589890',
    },
    'msg/JointTolerance': {
        'control_msgs/msg/JointTolerance': 'RIHS01_c254f9cece0f3b733017b6990fd46d1326e25242d6b8844398c97d9a88e7d648',
    },
    'msg/JointComponentTolerance': {
        'control_msgs/msg/JointComponentTolerance':
            'RIHS01_739ea7566931944d33830fa10f1bf5e7a7fbdc3172bce7a7eaac642bd6e3ffa4',
    },
}


@pytest.mark.parametrize('cls, fields', FIELDS, ids=[cls.__name__ for cls, _ in FIELDS])
def test_fields_match_upstream_in_name_type_and_order(cls, fields):
    assert list(cls.get_fields_and_field_types().items()) == fields


@pytest.mark.parametrize('cls, constants', CONSTANTS, ids=[cls.__name__ for cls, _ in CONSTANTS])
def test_constants_match_upstream(cls, constants):
    assert rosidl_constants(cls) == constants


def test_upstream_declares_no_default_values():
    assert FollowJointTrajectory.Result().error_code == FollowJointTrajectory.Result.SUCCESSFUL == 0
    assert FollowJointTrajectory.Result().error_string == ''
    assert JointComponentTolerance().component == 0
    command = GripperCommand.Goal().command
    assert (command.position, command.max_effort) == (0.0, 0.0)
    result = GripperCommand.Result()
    assert (result.position, result.effort, result.stalled, result.reached_goal) == (0.0, 0.0, False, False)


@pytest.mark.parametrize('interface', sorted(UPSTREAM_HASHES))
def test_type_hashes_match_upstream_jazzy(interface):
    hashes = installed_type_hashes('control_msgs', interface)
    assert {name: hashes.get(name) for name in UPSTREAM_HASHES[interface]} == UPSTREAM_HASHES[interface]

"""tf2_msgs and mocap4r2_msgs (ros_ws/src, or a system install) match upstream's Jazzy definitions.

The expected fields, constants and RIHS01 type hashes below come from
ros2/geometry2 tf2_msgs, branch `jazzy`, 0.36.4 (commit 646342c6164e), and
MOCAP4ROS2-Project/mocap4r2_msgs as released for Jazzy (0.1.0: the messages of
branch `rolling`, commit 58db978e415f, plus srv/CreateRigidBody); the message
hashes were taken from a build of those upstream packages. Jazzy peers compare
type hashes, so a drift in any field, type, constant or field order would make rad
unable to read a mocap4r2 driver or to be read by RViz and tf2_ros on /tf_static.
Message types alone: no rclpy.init, no DDS.
"""

import pytest
from interfaces import installed_type_hashes, rosidl_constants
from mocap4r2_msgs.msg import ImusInfo, Marker, Markers, RigidBodies, RigidBody
from mocap4r2_msgs.srv import CreateRigidBody
from tf2_msgs.action import LookupTransform
from tf2_msgs.msg import TF2Error, TFMessage
from tf2_msgs.srv import FrameGraph

FIELDS = [
    (Marker, [('id_type', 'int8'), ('marker_index', 'int32'), ('marker_name', 'string'),
              ('translation', 'geometry_msgs/Point')]),
    (Markers, [('header', 'std_msgs/Header'), ('frame_number', 'uint32'),
               ('markers', 'sequence<mocap4r2_msgs/Marker>')]),
    (RigidBody, [('rigid_body_name', 'string'), ('markers', 'sequence<mocap4r2_msgs/Marker>'),
                 ('pose', 'geometry_msgs/Pose')]),
    (RigidBodies, [('header', 'std_msgs/Header'), ('frame_number', 'uint32'),
                   ('rigidbodies', 'sequence<mocap4r2_msgs/RigidBody>')]),
    (ImusInfo, [('sensor_ids', 'sequence<string>'), ('battery_level', 'float'), ('temperature', 'float')]),
    (CreateRigidBody.Request, [('rigid_body_name', 'string'), ('link_parent', 'string'),
                               ('markers', 'sequence<int32>')]),
    (CreateRigidBody.Response, [('success', 'boolean')]),
    (TFMessage, [('transforms', 'sequence<geometry_msgs/TransformStamped>')]),
    (TF2Error, [('error', 'uint8'), ('error_string', 'string')]),
    (FrameGraph.Request, []),
    (FrameGraph.Response, [('frame_yaml', 'string')]),
    (LookupTransform.Goal, [('target_frame', 'string'), ('source_frame', 'string'),
                            ('source_time', 'builtin_interfaces/Time'), ('timeout', 'builtin_interfaces/Duration'),
                            ('target_time', 'builtin_interfaces/Time'), ('fixed_frame', 'string'),
                            ('advanced', 'boolean')]),
    (LookupTransform.Result, [('transform', 'geometry_msgs/TransformStamped'), ('error', 'tf2_msgs/TF2Error')]),
    (LookupTransform.Feedback, []),
]

CONSTANTS = [
    (Marker, {'USE_NAME': 0, 'USE_INDEX': 1, 'USE_BOTH': 2}),
    (TF2Error, {'NO_ERROR': 0, 'LOOKUP_ERROR': 1, 'CONNECTIVITY_ERROR': 2, 'EXTRAPOLATION_ERROR': 3,
                'INVALID_ARGUMENT_ERROR': 4, 'TIMEOUT_ERROR': 5, 'TRANSFORM_ERROR': 6}),
    (RigidBody, {}), (RigidBodies, {}), (Markers, {}), (ImusInfo, {}), (TFMessage, {}),
]

# RIHS01 hashes of the upstream packages (built from upstream's own files), against Jazzy's
# common_interfaces. CreateRigidBody is not in the upstream commit built (it came with 0.1.0):
# its field layout is checked above.
UPSTREAM_HASHES = {
    ('mocap4r2_msgs', 'msg/Marker'): {
        'mocap4r2_msgs/msg/Marker': 'RIHS01_0cadb14b00eb93dfd5d1b774f04f13efc0c2e08a3bee1abbaef9f67f6b10b943'},
    ('mocap4r2_msgs', 'msg/Markers'): {
        'mocap4r2_msgs/msg/Markers': 'RIHS01_36a59e85fa0dcebed1f0a91d748ca17e259b187f779e725af5c6701e8a03054a'},
    ('mocap4r2_msgs', 'msg/RigidBody'): {
        'mocap4r2_msgs/msg/RigidBody': 'RIHS01_7a1bca552c93a8da4f09083ef4327410b6687a95fe14db29292c4619166f5e66'},
    ('mocap4r2_msgs', 'msg/RigidBodies'): {
        'mocap4r2_msgs/msg/RigidBodies': 'RIHS01_1f2d74f2a1706c59639a2349b7be91e9e4d751fad6fc3048c59d8f1f0576ea70'},
    ('mocap4r2_msgs', 'msg/ImusInfo'): {
        'mocap4r2_msgs/msg/ImusInfo': 'RIHS01_532cba15d4d622a0b479ad4d659ec94939194e5051f595446def3b0fc6761b24'},
    ('tf2_msgs', 'msg/TFMessage'): {
        'tf2_msgs/msg/TFMessage': 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'},
    ('tf2_msgs', 'msg/TF2Error'): {
        'tf2_msgs/msg/TF2Error': 'RIHS01_db2485e7d6a0ec75bf087e058ee45df682acc3a621ca7780503d10aac141809a'},
    ('tf2_msgs', 'srv/FrameGraph'): {
        'tf2_msgs/srv/FrameGraph': 'RIHS01_0d1fbc6222c018ba5f33822904a2fdd4063705289956d3fdde07cd8c50fe8067',
        'tf2_msgs/srv/FrameGraph_Request': 'RIHS01_4cc565da6b64726d0b0be1ce20f3a3a695679b841a79abfca2fcdc94f562b08d',
        'tf2_msgs/srv/FrameGraph_Response':
            'RIHS01_e33d5473ce0fac04c66203779f2b719a9de0f8388b248852d3a47a019e62e36d'},
    ('tf2_msgs', 'action/LookupTransform'): {
        'tf2_msgs/action/LookupTransform': 'RIHS01_0b8adf6bc0b5958879e3265b41a457e03558fe523890a81252c70eba97a82c5d',
        'tf2_msgs/action/LookupTransform_Goal':
            'RIHS01_815efc294ad17c813c6043cdde781ff55810d49da02ed07f9237dcd20e88d498',
        'tf2_msgs/action/LookupTransform_Result':
            'RIHS01_061d4423af5352ff5314c8effef8faab133991a78f1b2bcd1fecabad80871225',
        'tf2_msgs/action/LookupTransform_Feedback':
            'RIHS01_2da0b02f990f04404ab8c98a2a68cf5bbc773ae747f96911f2d55499cfb51542'},
}


@pytest.mark.parametrize('cls, fields', FIELDS, ids=[f'{cls.__module__.split(".")[0]}.{cls.__name__}'
                                                     for cls, _ in FIELDS])
def test_fields_match_upstream_in_name_type_and_order(cls, fields):
    assert list(cls.get_fields_and_field_types().items()) == fields


@pytest.mark.parametrize('cls, constants', CONSTANTS, ids=[cls.__name__ for cls, _ in CONSTANTS])
def test_constants_match_upstream(cls, constants):
    assert rosidl_constants(cls) == constants


def test_upstream_declares_no_default_values():
    marker = Marker()
    assert (marker.id_type, marker.marker_index, marker.marker_name) == (0, 0, '')
    body = RigidBody()
    assert body.rigid_body_name == '' and list(body.markers) == [] and body.pose.orientation.w == 1.0
    assert RigidBodies().frame_number == 0 and TF2Error().error == TF2Error.NO_ERROR
    assert LookupTransform.Goal().advanced is False


@pytest.mark.parametrize('package, interface', sorted(UPSTREAM_HASHES))
def test_type_hashes_match_upstream_jazzy(package, interface):
    hashes = installed_type_hashes(package, interface)
    expected = UPSTREAM_HASHES[(package, interface)]
    assert {name: hashes.get(name) for name in expected} == expected


# ---- rad_ros.mocap_input's conversions (message types only) --------------------------------

def test_driver_messages_convert_to_rigid_bodies_and_the_calibration_to_tf_static():
    from geometry_msgs.msg import PoseStamped
    from rad_core.cell.mocap_input import FrameTransform, MocapFrames
    from rad_core.domain.errors import RadError
    from rad_ros.mocap_input import bodies_from_mocap4r2, body_from_pose_stamped, body_topic, calibration_tf
    from rad_ros.motion import pose_msg
    msg = RigidBodies(frame_number=7)
    msg.rigidbodies = [RigidBody(rigid_body_name='Block_3', pose=pose_msg((1.0, 2.0, 3.0), (0.0, 0.0, 0.6, 0.8)))]
    (body,) = bodies_from_mocap4r2(msg)
    assert (body.name, body.position, body.quaternion, body.tracking_valid) == \
        ('Block_3', [1.0, 2.0, 3.0], [0.0, 0.0, 0.6, 0.8], True)
    pose = PoseStamped(pose=pose_msg((0.5, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0)))
    assert body_from_pose_stamped('b1', pose).position == [0.5, 0.0, 0.1]
    assert body_topic('/natnet_ros2/{body}/pose', 'Block_3') == '/natnet_ros2/Block_3/pose'
    with pytest.raises(RadError, match="must contain '{body}'"):
        body_topic('/natnet_ros2/pose', 'Block_3')
    frames = MocapFrames('base', 'optitrack', FrameTransform((0.1, 0.2, 0.3), (0.0, 0.0, 0.6, 0.8)))
    (t,) = calibration_tf(frames, pose.header.stamp).transforms
    assert (t.header.frame_id, t.child_frame_id) == ('base', 'optitrack')
    assert [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z] == [0.1, 0.2, 0.3]
    assert [t.transform.rotation.z, t.transform.rotation.w] == pytest.approx([0.6, 0.8])

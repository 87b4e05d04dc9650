"""ros2 launch rad_planner franka.launch.py [params_file:=...] [use_twin:=true] [robot:=fr3|panda]
[namespace:=...] [log_level:=debug]

rad next to franka_ros2 (full ROS 2 Jazzy installs). use_twin:=false (the default) starts every
node but the twin: franka_ros2 serves the arm's FollowJointTrajectory and the hand's
GripperCommand actions and /joint_states. use_twin:=true adds the twin, which serves the same
actions under the profile's names, for a dry run of the same profile in simulation (the
assembly node is then told that gripper results are per finger, as the twin reports them, and that
motion capture is the twin's, in the base frame). Every node's frame_id is the profile's `base`,
franka_description's root: the calibration base -> mocap frame and the blocks hang from that one tree.
robot (panda or fr3; '' = the parameter file's) overrides `robot` of the twin, gamp and assembly.
collision_objects:=true puts the blocks into MoveIt's planning scene (/collision_object), where
franka's MoveIt launch runs move_group. The managed nodes (assembly, and the twin with use_twin)
start unconfigured; rad's lifecycle manager brings them up.
Without ros2 launch: graph --params <franka.yaml> [--no-twin] [-p node.param:=value ...].
"""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.parameter_descriptions import ParameterValue
from rad_ros.launching import arguments, node

NODES = (('rad_sim', 'twin_node', 'twin'), ('rad_planner', 'allocation_node', 'allocation'),
         ('rad_gamp', 'gamp_node', 'gamp'), ('rad_planner', 'sequencer_node', 'sequencer'),
         ('rad_planner', 'assembly_node', 'assembly'), ('rad_viz', 'viz_node', 'viz'),
         ('rad_viz', 'markers_node', 'markers'))
ROBOT_NODES = ('twin', 'gamp', 'assembly')   # the nodes with a `robot` parameter
MANAGED = ('twin', 'assembly')               # lifecycle nodes, in bring-up order


def _nodes(context):
    use_twin = LaunchConfiguration('use_twin').perform(context).strip().lower() in ('true', '1', 'yes')
    robot = LaunchConfiguration('robot').perform(context).strip()
    nodes = []
    for pkg, exe, name in NODES:
        if name == 'twin' and not use_twin:
            continue
        overrides = {}
        if robot and name in ROBOT_NODES:
            overrides['robot'] = robot
        if name == 'assembly' and use_twin:
            overrides['gripper_result_is_width'] = False   # the twin reports per finger
            # The twin's motion capture: rad_msgs/RigidBodies in the base frame itself, no calibration.
            overrides.update(mocap_driver='rad', mocap_input='', mocap_topic='', pose_topic='', mocap_frame='',
                             mocap_in_base_frame=True)
        if name in MANAGED:
            overrides['autostart'] = False
        if name == 'markers':
            overrides['collision_objects'] = ParameterValue(LaunchConfiguration('collision_objects'), value_type=bool)
        nodes.append(node(pkg, exe, name, overrides or None))
    managed = [name for name in MANAGED if use_twin or name != 'twin']
    return nodes + [node('rad_planner', 'lifecycle_manager', 'lifecycle_manager', {'node_names': managed})]


def generate_launch_description():
    default = get_package_share_directory('rad_planner') + '/config/franka.yaml'
    return LaunchDescription(arguments(default) + [
        DeclareLaunchArgument('use_twin', default_value='false',
                              description='true: start the twin in place of franka_ros2 (simulation)'),
        DeclareLaunchArgument('collision_objects', default_value='false',
                              description="true: the blocks as CollisionObjects in MoveIt's planning scene"),
        DeclareLaunchArgument('robot', default_value='',
                              description="panda or fr3 for the twin, gamp and assembly ('' = the parameter file's)"),
        OpaqueFunction(function=_nodes),
    ])

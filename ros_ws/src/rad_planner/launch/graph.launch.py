"""ros2 launch rad_planner graph.launch.py [params_file:=...] [namespace:=...] [use_sim_time:=true]
[log_level:=debug] [rviz:=true] [effector:=suction] (full ROS 2 Jazzy installs).

The whole graph with the twin, robot_state_publisher (the twin's URDF, so TF has the robot) and,
with rviz:=true, RViz with rad_viz's config (robot, block frames, /markers). The same graph `graph`
starts on machines without ros2 launch. use_sim_time:=true also makes the twin publish /clock.
The managed nodes (the twin and the assembly node) start unconfigured and rad's lifecycle manager
brings them up in order, as nav2's launch files do; `ros2 service call /lifecycle_manager/pause
std_srvs/srv/Trigger` stops them (and a running goal), `resume` starts them again.
"""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from rad_ros.launching import arguments, node

NODES = (('rad_sim', 'twin_node', 'twin'), ('rad_planner', 'allocation_node', 'allocation'),
         ('rad_gamp', 'gamp_node', 'gamp'), ('rad_planner', 'sequencer_node', 'sequencer'),
         ('rad_planner', 'assembly_node', 'assembly'), ('rad_viz', 'viz_node', 'viz'),
         ('rad_viz', 'markers_node', 'markers'))
MANAGED = ('twin', 'assembly')      # lifecycle nodes, in bring-up order


def robot_state_publisher(context):
    from rad_sim.twin_node import robot_description
    effector = LaunchConfiguration('effector').perform(context)
    return [node('robot_state_publisher', 'robot_state_publisher', 'robot_state_publisher',
                 {'robot_description': ParameterValue(robot_description(effector), value_type=str)})]


def generate_launch_description():
    default = get_package_share_directory('rad_planner') + '/config/graph.yaml'
    rviz = get_package_share_directory('rad_viz') + '/config/rad.rviz'
    # The twin publishes /clock where the graph runs on simulated time; robot_state_publisher publishes
    # the robot description, so the twin does not.
    twin = {'publish_clock': ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool),
            'publish_robot_description': False, 'autostart': False}
    managed = {'twin': twin, 'assembly': {'autostart': False}}
    return LaunchDescription(
        arguments(default)
        + [DeclareLaunchArgument('rviz', default_value='false', description='start RViz with rad.rviz'),
           DeclareLaunchArgument('effector', default_value='hand', description="the twin's URDF: hand or suction")]
        + [node(pkg, exe, name, managed.get(name)) for pkg, exe, name in NODES]
        + [node('rad_planner', 'lifecycle_manager', 'lifecycle_manager', {'node_names': list(MANAGED)}),
           OpaqueFunction(function=robot_state_publisher),
           Node(package='rviz2', executable='rviz2', name='rviz2', arguments=['-d', rviz], output='screen',
                condition=IfCondition(LaunchConfiguration('rviz')))])

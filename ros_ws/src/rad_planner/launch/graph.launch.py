"""ros2 launch rad_planner graph.launch.py [params_file:=...] (full ROS 2 Jazzy installs).

The same graph `graph` starts on machines without ros2 launch.
"""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

NODES = (('rad_sim', 'twin_node', 'twin'), ('rad_planner', 'allocation_node', 'allocation'),
         ('rad_gamp', 'gamp_node', 'gamp'), ('rad_planner', 'sequencer_node', 'sequencer'),
         ('rad_planner', 'assembly_node', 'assembly'), ('rad_viz', 'viz_node', 'viz'))


def generate_launch_description():
    params = LaunchConfiguration('params_file')
    default = get_package_share_directory('rad_planner') + '/config/graph.yaml'
    return LaunchDescription([DeclareLaunchArgument('params_file', default_value=default)] + [
        Node(package=pkg, executable=exe, name=name, parameters=[params], output='screen')
        for pkg, exe, name in NODES])

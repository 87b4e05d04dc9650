"""ros2 launch rad_viz viz.launch.py [params_file:=...] (full ROS 2 Jazzy installs)."""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    default = get_package_share_directory('rad_viz') + '/config/viz.yaml'
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default),
        Node(package='rad_viz', executable='viz_node', name='viz',
             parameters=[LaunchConfiguration('params_file')], output='screen'),
    ])

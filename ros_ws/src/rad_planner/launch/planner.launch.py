"""ros2 launch rad_planner planner.launch.py [params_file:=...]

For a full ROS 2 Jazzy install (launch is not available from PyPI; on the wheel
set-up use scripts/ros2run per node).
"""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    default_params = get_package_share_directory('rad_planner') + '/config/planner.yaml'
    params = LaunchConfiguration('params_file')
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default_params),
        Node(package='rad_planner', executable='allocation_node', name='allocation',
             parameters=[params], output='screen'),
        Node(package='rad_planner', executable='sequencer_node', name='sequencer',
             parameters=[params], output='screen'),
    ])

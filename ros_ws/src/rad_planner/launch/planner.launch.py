"""ros2 launch rad_planner planner.launch.py [params_file:=...] [namespace:=...] [use_sim_time:=true] [log_level:=debug]

For a full ROS 2 Jazzy install (launch is not available from PyPI; on the wheel
set-up use scripts/ros2run per node)."""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from rad_ros.launching import arguments, node


def generate_launch_description():
    default = get_package_share_directory('rad_planner') + '/config/planner.yaml'
    return LaunchDescription(arguments(default) + [
        node('rad_planner', 'allocation_node', 'allocation'),
        node('rad_planner', 'sequencer_node', 'sequencer'),
    ])

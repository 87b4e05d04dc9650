"""ros2 launch rad_sim twin.launch.py [params_file:=...] [namespace:=...] [use_sim_time:=true] [log_level:=debug]
(full ROS 2 Jazzy installs)."""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from rad_ros.launching import arguments, node


def generate_launch_description():
    default = get_package_share_directory('rad_sim') + '/config/twin.yaml'
    return LaunchDescription(arguments(default) + [
        node('rad_sim', 'twin_node', 'twin'),
    ])

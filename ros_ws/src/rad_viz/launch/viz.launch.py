"""ros2 launch rad_viz viz.launch.py [params_file:=...] [namespace:=...] [use_sim_time:=true] [log_level:=debug]
(full ROS 2 Jazzy installs): the Rerun visualizer and the markers for RViz."""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from rad_ros.launching import arguments, node


def generate_launch_description():
    default = get_package_share_directory('rad_viz') + '/config/viz.yaml'
    return LaunchDescription(arguments(default) + [
        node('rad_viz', 'viz_node', 'viz'),
        node('rad_viz', 'markers_node', 'markers'),
    ])

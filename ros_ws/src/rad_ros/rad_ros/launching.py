"""What rad's launch files share: the arguments a ROS 2 lab expects, and nodes that honour them.

Every launch file of rad declares `params_file`, `namespace`, `use_sim_time` and `log_level`
(`arguments`), and starts its nodes with `node` (in the namespace, on simulated time where asked,
at the log level). Needs a full ROS 2 install (launch and launch_ros are not on PyPI; on the wheel
set-up, `graph` and scripts/ros2run start the same nodes).
"""

from __future__ import annotations


def arguments(params_default: str) -> list:
    """The launch arguments every rad launch file takes."""
    from launch.actions import DeclareLaunchArgument
    return [DeclareLaunchArgument('params_file', default_value=params_default,
                                  description='parameter file (each node reads its own section)'),
            DeclareLaunchArgument('namespace', default_value='', description='namespace of every node'),
            DeclareLaunchArgument('use_sim_time', default_value='false',
                                  description='follow /clock (the twin publishes it with publish_clock:=true)'),
            DeclareLaunchArgument('log_level', default_value='info', description='debug, info, warn, error')]


def node(package: str, executable: str, name: str, extra: dict | None = None, **kw):
    """A launch_ros Node with the shared arguments applied; extra: parameters on top of the file's."""
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue
    sim_time = {'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)}
    return Node(package=package, executable=executable, name=name, namespace=LaunchConfiguration('namespace'),
                parameters=[LaunchConfiguration('params_file'), sim_time, *([extra] if extra else [])],
                arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')], output='screen', **kw)

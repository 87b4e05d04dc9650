#!/usr/bin/env bash
# Source ROS and the rad workspace, then run the given command.
set -e
source /opt/ros/jazzy/setup.bash
source /rad/ros_ws/install/setup.bash
exec "$@"

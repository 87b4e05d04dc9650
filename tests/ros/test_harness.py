"""The node-process harness itself: path resolution, stop semantics, argument building."""

import sys

import pytest
import ros_harness as harness

IGNORES_SIGINT = ('import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); '
                  "print('up', flush=True); time.sleep(60)")


def test_missing_executable_names_the_fix():
    with pytest.raises(FileNotFoundError, match='scripts/setup.sh'):
        harness.executable_path('rad_no_such_package', 'no_such_node')


def test_stop_kills_a_process_that_ignores_sigint(process):
    proc = process([sys.executable, '-c', IGNORES_SIGINT], name='stubborn')
    proc.wait_for_output('up', timeout=10)
    assert proc.stop(timeout=0.5) == -9
    assert proc.killed and 'killed after SIGINT timed out' in proc.output_tail()


def test_stop_reports_a_clean_exit_and_output(process):
    proc = process([sys.executable, '-c', "print('hello')"], name='short')
    assert proc.wait(timeout=10) == 0
    assert proc.stop() == 0  # already exited: stop() only reports the code
    assert proc.stdout() == 'hello\n'


def test_ros_args():
    assert harness.ros_args({'time_limit_s': 2.0, 'verbose': True}, {'allocate': 'alloc2'}) == [
        '--ros-args', '-p', 'time_limit_s:=2.0', '-p', 'verbose:=true', '-r', 'allocate:=alloc2']

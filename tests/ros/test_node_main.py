"""rad_ros.node_main.run_node: a stop request is a clean exit, other errors are not."""

import subprocess
import sys

import pytest

NODE = '''
import os, signal, sys, time
from rclpy.node import Node
from rad_ros.node_main import run_node

class Faulty(Node):
    def __init__(self):
        super().__init__('faulty')
        self.create_timer(0.2, self.tick)

    def tick(self):
        if sys.argv[1] == 'interrupted':
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(2)
            except KeyboardInterrupt:
                # What pybind11 does when the interrupt lands inside rclpy's C++ code.
                raise RuntimeError('Unable to convert call argument') from None
        raise RuntimeError('a real bug')

sys.exit(run_node(Faulty))
'''


@pytest.mark.parametrize('mode,code', [('interrupted', 0), ('bug', 1)])
def test_errors_after_a_stop_request_are_a_clean_exit_and_bugs_are_not(mode, code):
    r = subprocess.run([sys.executable, '-c', NODE, mode], capture_output=True, text=True, timeout=60)
    assert r.returncode == code, r.stderr[-2000:]
    if code:
        assert 'a real bug' in r.stderr


BUSY = '''
import sys, time
from pathlib import Path
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
from rad_ros.node_main import run_node

class Busy(Node):
    def __init__(self):
        super().__init__('busy')
        self.pub = self.create_publisher(String, 'busy_out', 1)
        self.timer = self.create_timer(0.1, self.work)

    def work(self):
        self.timer.cancel()
        Path(sys.argv[2]).write_text('started')
        time.sleep(float(sys.argv[1]))
        self.pub.publish(String(data='done'))       # fails if the node was destroyed under it
        Path(sys.argv[2]).write_text('finished')

sys.exit(run_node(Busy, executor_factory=lambda: MultiThreadedExecutor(num_threads=2)))
'''


@pytest.mark.parametrize('work_s', [1.5, 60.0])
def test_a_stop_waits_for_callbacks_in_flight_or_leaves_without_teardown(work_s, tmp_path):
    """The node is destroyed only once the executor's callbacks are done; one that does not end
    in SETTLE_S does not keep the process alive."""
    import os
    import signal
    import time
    marker = tmp_path / 'state'
    p = subprocess.Popen([sys.executable, '-c', BUSY, str(work_s), str(marker)], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while not marker.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert marker.exists(), 'the callback never started'
    start = time.monotonic()
    os.kill(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=20)
    assert p.returncode == 0, err[-2000:]
    assert 'terminate called' not in err and 'Traceback' not in err, err[-2000:]
    if work_s < 3:
        assert marker.read_text() == 'finished'
    else:
        assert marker.read_text() == 'started'
        assert 'callbacks still running' in err
        assert time.monotonic() - start < 10

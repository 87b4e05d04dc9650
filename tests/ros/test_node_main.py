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

"""The one main() every rad node uses (the Jazzy pattern, hardened).

SIGTERM and SIGINT both raise KeyboardInterrupt: a node spinning an executor
otherwise sometimes ignores the first SIGTERM (see ENVIRONMENT.md). When that
interrupt lands inside rclpy's C++ code (say, while a message is converted),
pybind11 turns it into another exception (seen: a RuntimeError from
take_message); once a stop has been asked for, such an error is part of the
shutdown, not a crash, and the node still exits 0.

A node that cannot start for a reason a user can fix (a RadError from its
constructor: a bad parameter, a checkpoint that does not load) says so in one line
on stderr and exits 1, without a traceback.
"""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException

from rad_core.errors import RadError


def run_node(node_factory, args=None, executor_factory=None) -> int:
    stop_requested = threading.Event()

    def interrupt(signum, frame):
        stop_requested.set()
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = node_factory()
        except RadError as e:
            print(f'{Path(sys.argv[0]).name}: cannot start: {e}', file=sys.stderr, flush=True)
            return 1
        if executor_factory is None:
            rclpy.spin(node)
        else:
            executor = executor_factory()
            executor.add_node(node)
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not stop_requested.is_set():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main_for(node_factory):
    """A console-script entry point for a node class."""
    def main(args=None):
        sys.exit(run_node(node_factory, args))
    return main

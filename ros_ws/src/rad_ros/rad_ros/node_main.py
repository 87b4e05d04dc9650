"""The one main() every rad node uses (the Jazzy pattern, hardened).

SIGTERM and SIGINT both raise KeyboardInterrupt: a node spinning an executor
otherwise sometimes ignores the first SIGTERM (see ENVIRONMENT.md).
"""

from __future__ import annotations

import signal
import sys

import rclpy
from rclpy.executors import ExternalShutdownException


def run_node(node_factory, args=None, executor_factory=None) -> int:
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        if executor_factory is None:
            rclpy.spin(node)
        else:
            executor = executor_factory()
            executor.add_node(node)
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
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

"""The one main() every rad node uses (the Jazzy pattern, hardened).

Stopping. SIGTERM and SIGINT both raise KeyboardInterrupt in the main thread,
and rclpy's own signal handlers are off (`SignalHandlerOptions.NO`): those shut
the context down the moment a signal lands, under any callback still running
in an executor's worker thread (seen: "publisher's context is invalid", and
now and then the process aborting with "terminate called without an active
exception", exit -6). The executor spins in short `spin_once` steps so the
Python handler runs within `TICK_S`. After the stop, the executor's work is
waited for (up to `SETTLE_S`: this rclpy's `Executor.shutdown(timeout_sec)`
never waits, its wait sits behind its own shutdown flag), and only then are the
node and the context torn down. When callbacks are still busy after that, the
process leaves at once with its exit code, without tearing down what they use.

When the interrupt lands inside rclpy's C++ code (say, while a message is
converted), pybind11 turns it into another exception (seen: a RuntimeError from
take_message); once a stop has been asked for, such an error is part of the
shutdown, not a crash, and the node still exits 0.

A managed node (`rad_ros.lifecycle.ManagedNode`) with `autostart` true is configured and activated
here, before the executor spins. A node that cannot start for a reason a user can fix (a RadError
from its constructor or its configure: a bad parameter, a checkpoint that does not load) says so in
one line on stderr and exits 1, without a traceback.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

import rclpy
from rad_core.domain.errors import RadError
from rad_ros.lifecycle import ManagedNode
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

TICK_S = 0.2
SETTLE_S = 3.0


def settle(executor, timeout_s: float = SETTLE_S) -> bool:
    """Stop `executor` and wait until no callback runs in it; False when some still do after
    `timeout_s` s."""
    executor.shutdown(timeout_sec=0)
    tracker = getattr(executor, '_work_tracker', None)   # private; the public wait is broken here
    return tracker is None or tracker.wait(timeout_s)


def run_node(node_factory, args=None, executor_factory=None) -> int:
    stop_requested = threading.Event()

    def interrupt(signum, frame):
        stop_requested.set()
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = None
    try:
        try:
            node = node_factory()
            if isinstance(node, ManagedNode) and node.get_parameter('autostart').value:
                node.bring_up()
        except (RadError, ParameterException) as e:    # ParameterException: a value outside its range
            print(f'{Path(sys.argv[0]).name}: cannot start: {e}', file=sys.stderr, flush=True)
            return 1
        executor = (executor_factory or SingleThreadedExecutor)()
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=TICK_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not stop_requested.is_set():
            raise
    finally:
        if executor is not None and not settle(executor):
            print(f'{Path(sys.argv[0]).name}: callbacks still running {SETTLE_S:.0f} s after the stop; '
                  'leaving without teardown', file=sys.stderr, flush=True)
            sys.stdout.flush()
            os._exit(0 if stop_requested.is_set() else 1)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main_for(node_factory):
    """A console-script entry point for a node class."""
    def main(args=None):
        sys.exit(run_node(node_factory, args))
    return main

"""One goal at a time on the arm.

The assembly node serves /execute_assembly and /take_apart on a multi-threaded executor; each goal
drives the same arm and hand. A goal takes the `ArmLock` as it starts and gives it back when it
ends, however it ends. A goal that finds it taken ends at once, aborted, its result's reason naming
the goal that holds the arm. ROS 2's goal response carries no reason, so such a goal is accepted
and aborted rather than rejected: the client reads why in the result, as with every other failure.
"""

from __future__ import annotations

import threading
import time
from typing import Callable


def goal_name(goal_handle) -> str:
    """A goal's id as ROS 2 tools print it (the UUID's hex)."""
    return bytes(goal_handle.goal_id.uuid).hex()


class ArmLock:
    """Which goal drives the arm now, if any."""

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self._lock = threading.Lock()
        self._holder: tuple[str, str, float] | None = None
        self._clock = clock

    def take(self, action: str, goal_id: str) -> str:
        """'' when this goal now drives the arm; otherwise why not (which goal does, since when)."""
        with self._lock:
            if self._holder is not None:
                name, holder, since = self._holder
                return (f'the arm is busy: {name} goal {holder} has driven it for {self._clock() - since:.1f} s; '
                        f'one goal at a time (cancel that goal or wait for its result)')
            self._holder = (action, goal_id, self._clock())
            return ''

    def give(self, goal_id: str) -> None:
        """The goal that took the arm is done with it."""
        with self._lock:
            if self._holder is not None and self._holder[1] == goal_id:
                self._holder = None

    def serve(self, node, action: str, result_type, run: Callable, refusal: Callable[[], str] = lambda: ''):
        """An action server's execute callback: `run(goal_handle)` while this goal holds the arm;
        a goal that finds it taken, or arrives while `refusal()` gives a reason (the node is not
        active), ends at once, aborted, the reason in its result."""
        def callback(goal_handle):
            goal_id = goal_name(goal_handle)
            busy = refusal() or self.take(action, goal_id)
            if busy:
                node.get_logger().warning(f'{action.lstrip("/")} goal {goal_id} refused: {busy}')
                goal_handle.abort()
                return result_type(success=False, reason=busy)
            try:
                return run(goal_handle)
            finally:
                self.give(goal_id)
        return callback

    def wait_free(self, timeout_s: float) -> bool:
        """Wait until no goal drives the arm; False when one still does after `timeout_s`."""
        end = self._clock() + timeout_s
        while self.holder:
            if self._clock() > end:
                return False
            time.sleep(0.05)
        return True

    @property
    def holder(self) -> str:
        """'<action> goal <id>' of the goal driving the arm, '' when none does."""
        with self._lock:
            return '' if self._holder is None else f'{self._holder[0]} goal {self._holder[1]}'

"""/diagnostics as ROS 2's diagnostic tools read it (rqt_robot_monitor, diagnostic_aggregator).

A node calls `Checks` once a second: each check is a name and a function returning (level,
message, values); a check that raises reports ERROR with what it raised. The statuses go out
together as one `diagnostic_msgs/DiagnosticArray` on the absolute topic /diagnostics, each named
'<node>: <check>' with the node's fully qualified name as hardware_id, as diagnostic_updater does.
"""

from __future__ import annotations

from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)

Check = Callable[[], tuple[bytes, str, dict]]


class Checks:
    """The node's checks, published on /diagnostics every `period_s`."""

    def __init__(self, node, checks: dict[str, Check], period_s: float = 1.0, callback_group=None):
        self.node, self.checks = node, checks
        self.pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.timer = node.create_timer(period_s, self.publish, callback_group=callback_group)

    def statuses(self) -> list[DiagnosticStatus]:
        out = []
        for name, check in self.checks.items():
            try:
                level, message, values = check()
            except Exception as e:  # noqa: BLE001 - a check that fails is an error to report, not to die of
                level, message, values = ERROR, f'{type(e).__name__}: {e}', {}
            out.append(DiagnosticStatus(level=level, name=f'{self.node.get_name()}: {name}', message=message,
                                        hardware_id=self.node.get_fully_qualified_name(),
                                        values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()]))
        return out

    def publish(self) -> None:
        msg = DiagnosticArray(status=self.statuses())
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(msg)


def answers(what: str, ready: Callable[[], bool]) -> Check:
    """A check that a service or action server is there to answer."""
    def check():
        return (OK, f'{what} answers', {}) if ready() else (ERROR, f'no {what}: is its node running?', {})
    return check

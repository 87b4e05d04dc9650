"""Managed (lifecycle) nodes, as ros2_control's controllers and nav2's servers are.

A `ManagedNode` goes through the ROS 2 node lifecycle (unconfigured, inactive, active, finalized) by
the standard `lifecycle_msgs` services (`<node>/change_state`, `<node>/get_state`, ...), so
`ros2 lifecycle set`, nav2's lifecycle manager or rad's own (`rad_planner.lifecycle_manager`) drive it:

- configure: parameters read and checked, the node's state built, its publishers, subscriptions,
  services and action servers created. A RadError refuses the transition; the reason is logged and
  kept in `transition_error`.
- activate: the node does its work (a subclass's `activate`).
- deactivate: the work stops; what runs ends cleanly (a subclass's `deactivate`).
- cleanup: back to unconfigured (a subclass's `cleanup`).

While not active, action goals are refused as joint_trajectory_controller refuses them when it is not
running, and services answer with `inactive_reason()`: the servers stay in the graph, so a client
learns why instead of waiting for a server that is not there.

The `autostart` parameter (read-only, default true) makes the node configure and activate itself as
it starts (`ros2 run` brings up a working node); false leaves it unconfigured for a lifecycle manager.
"""

from __future__ import annotations

import threading
import traceback

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from rad_core.domain.errors import RadError
from rad_ros.params import Param, declare

AUTOSTART = Param('autostart', True, 'configure and activate as the node starts; false waits for a '
                  'lifecycle manager or `ros2 lifecycle set <node> configure`')

DONE = {'configure': 'configured', 'activate': 'active', 'deactivate': 'inactive', 'cleanup': 'cleaned up'}


class ManagedNode(LifecycleNode):
    """A lifecycle node whose transitions call `configure`, `activate`, `deactivate`, `cleanup`
    (override them; a RadError refuses the transition with its message)."""

    def __init__(self, node_name: str, **kwargs):
        super().__init__(node_name, **kwargs)
        declare(self, [AUTOSTART])
        self.transition_error = ''
        self._active = threading.Event()
        self._owned: list = []

    def own(self, entity):
        """Record an endpoint configure created (publisher, subscription, service, timer, action server
        or client), for `drop_owned`; returns it."""
        self._owned.append(entity)
        return entity

    def drop_owned(self) -> None:
        """Destroy every endpoint `own` recorded, newest first (what cleanup does)."""
        by_node = ((Publisher, self.destroy_publisher), (Subscription, self.destroy_subscription),
                   (Service, self.destroy_service), (Timer, self.destroy_timer))
        while self._owned:
            entity = self._owned.pop()
            for kind, destroy in by_node:
                if isinstance(entity, kind):
                    destroy(entity)
                    break
            else:
                entity.destroy()      # rclpy.action's ActionServer and ActionClient destroy themselves

    # ---- what a subclass does in each transition --------------------------------------
    def configure(self) -> None:
        """Read the parameters, build the node's state and its endpoints."""

    def activate(self) -> None:
        """Start the work."""

    def deactivate(self) -> None:
        """Stop the work; whatever runs ends cleanly."""

    def cleanup(self) -> None:
        """Drop what configure built (by default, the endpoints it `own`ed)."""
        self.drop_owned()

    # ---- state --------------------------------------------------------------------------------
    @property
    def is_active(self) -> bool:
        return self._active.is_set()

    def lifecycle_state(self) -> str:
        """'unconfigured', 'inactive', 'active' or 'finalized' (a transition's label while one runs)."""
        return self._state_machine.current_state[1]

    def inactive_reason(self) -> str:
        """Why a request is refused while the node is not active."""
        name = self.get_fully_qualified_name()
        return (f'{name} is {self.lifecycle_state()}, not active: activate it (ros2 lifecycle set {name} activate, '
                'or its lifecycle manager)')

    def bring_up(self) -> None:
        """Configure, then activate; RadError with the reason when either is refused."""
        for what, trigger in (('configure', self.trigger_configure), ('activate', self.trigger_activate)):
            self.transition_error = ''
            if trigger() != TransitionCallbackReturn.SUCCESS:
                raise RadError(self.transition_error or f'{what} failed (see the log)')

    # ---- rclpy's transition callbacks -------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._transition('configure', self.configure)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = self._transition('activate', self.activate)
        if result == TransitionCallbackReturn.SUCCESS:
            self._active.set()
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active.clear()
        return self._transition('deactivate', self.deactivate)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._transition('cleanup', self.cleanup)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self._active.is_set():
            self._active.clear()
            self._transition('deactivate', self.deactivate)
        return TransitionCallbackReturn.SUCCESS

    def _transition(self, what: str, step) -> TransitionCallbackReturn:
        try:
            step()
        except RadError as e:
            self.transition_error = str(e)
            self.get_logger().error(f'{what} refused: {e}')
            return TransitionCallbackReturn.FAILURE
        except Exception as e:  # noqa: BLE001 - a failed transition is reported, the node stays up
            self.transition_error = f'{type(e).__name__}: {e}'
            self.get_logger().error(f'{what} failed: {traceback.format_exc()}')
            return TransitionCallbackReturn.ERROR
        self.get_logger().info(DONE[what])
        return TransitionCallbackReturn.SUCCESS

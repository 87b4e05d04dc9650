"""lifecycle_manager: brings managed nodes up and down in order, as nav2's lifecycle manager does.

Parameters:
  node_names           the managed nodes, in bring-up order (names relative to this node's namespace,
                       or absolute); default ['twin', 'assembly']
  autostart            configure and activate them all as this node starts (default true)
  transition_timeout_s how long one node's lifecycle service may take to appear and to answer (10 s)

  srv  ~/startup   std_srvs/Trigger: configure (where unconfigured) and activate each node, in order
  srv  ~/pause     std_srvs/Trigger: deactivate each active node, in reverse order
  srv  ~/resume    std_srvs/Trigger: activate each inactive node, in order
  srv  ~/shutdown  std_srvs/Trigger: deactivate and clean up each node, in reverse order (unconfigured)
  pub  /diagnostics  each managed node's state, each second (its answer to get_state)

Each call goes through the standard lifecycle services (<node>/get_state, <node>/change_state), so the
nodes may be rad's (rad_ros.lifecycle.ManagedNode) or any other managed node, a real-cell bridge
included. A transition a node refuses stops the sequence there; the answer names the node, the
transition and, where the node is one of rad's, points to its log for the reason. There is no bond
(nav2's heartbeat): a node that dies is seen on /diagnostics, not acted upon.
"""

from __future__ import annotations

import threading

from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rad_core.domain.errors import RadError
from rad_ros.diagnostics import ERROR, OK, WARN, Checks
from rad_ros.node_main import run_node
from rad_ros.params import Param, declare
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_srvs.srv import Trigger

PARAMS = [
    Param('node_names', ['twin', 'assembly'], 'the managed nodes, in bring-up order'),
    Param('autostart', True, 'configure and activate every node as the manager starts'),
    Param('transition_timeout_s', 10.0, 'how long a node\'s lifecycle service may take to appear and answer',
          range=(0.1, 600.0)),
]

CONFIGURE, ACTIVATE, DEACTIVATE, CLEANUP = (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE,
                                            Transition.TRANSITION_DEACTIVATE, Transition.TRANSITION_CLEANUP)
LABELS = {CONFIGURE: ('configure', 'configured'), ACTIVATE: ('activate', 'activated'),
          DEACTIVATE: ('deactivate', 'deactivated'), CLEANUP: ('cleanup', 'cleaned up')}
# What each command does from each state a node can be in: the transitions, in order.
PLANS = {
    'startup': {State.PRIMARY_STATE_UNCONFIGURED: (CONFIGURE, ACTIVATE), State.PRIMARY_STATE_INACTIVE: (ACTIVATE,)},
    'pause': {State.PRIMARY_STATE_ACTIVE: (DEACTIVATE,)},
    'resume': {State.PRIMARY_STATE_INACTIVE: (ACTIVATE,)},
    'shutdown': {State.PRIMARY_STATE_ACTIVE: (DEACTIVATE, CLEANUP), State.PRIMARY_STATE_INACTIVE: (CLEANUP,)},
}


class LifecycleManager(Node):
    def __init__(self):
        super().__init__('lifecycle_manager')
        declare(self, PARAMS)
        names = self.get_parameter('node_names').value
        if not names or not all(isinstance(n, str) and n for n in names):
            raise RadError(f'node_names must list the managed nodes, got {names!r}')
        self.names = list(names)
        self.timeout = float(self.get_parameter('transition_timeout_s').value)
        self.group = ReentrantCallbackGroup()
        self.clients_ = {n: (self.create_client(GetState, f'{n}/get_state', callback_group=self.group),
                             self.create_client(ChangeState, f'{n}/change_state', callback_group=self.group))
                         for n in self.names}
        self.busy = threading.Lock()           # one command at a time
        self.states: dict[str, str] = {n: 'unknown' for n in self.names}
        for command in PLANS:
            self.create_service(Trigger, f'~/{command}', self._service(command), callback_group=self.group)
        Checks(self, {n: self._health(n) for n in self.names}, callback_group=self.group)
        if self.get_parameter('autostart').value:
            self.started = threading.Event()
            self.start_timer = self.create_timer(0.1, self._autostart, callback_group=self.group)
        self.get_logger().info(f'managing {", ".join(self.names)}')

    def _autostart(self) -> None:
        if self.started.is_set():
            return
        self.started.set()
        self.start_timer.cancel()
        ok, message = self.run('startup')
        (self.get_logger().info if ok else self.get_logger().error)(f'autostart: {message}')

    def _service(self, command: str):
        def callback(request, response):
            response.success, response.message = self.run(command)
            return response
        return callback

    def run(self, command: str) -> tuple[bool, str]:
        """Take every node through `command`'s transitions; (success, what happened or why not)."""
        if not self.busy.acquire(blocking=False):
            return False, 'another lifecycle command is running'
        try:
            order = self.names if command in ('startup', 'resume') else self.names[::-1]
            for name in order:
                state = self.get_state(name)
                for transition in PLANS[command].get(state.id, ()):
                    self.change_state(name, transition)
                self.states[name] = self.get_state(name).label
            return True, f'{command}: ' + ', '.join(f'{n} {self.states[n]}' for n in self.names)
        except RadError as e:
            return False, f'{command} stopped: {e}'
        finally:
            self.busy.release()

    def get_state(self, name: str) -> State:
        client = self.clients_[name][0]
        return self._call(name, client, GetState.Request(), 'get_state').current_state

    def change_state(self, name: str, transition: int) -> None:
        request = ChangeState.Request()
        request.transition.id = transition
        label, done = LABELS[transition]
        if not self._call(name, self.clients_[name][1], request, 'change_state').success:
            raise RadError(f'{name} refused to {label} (its log says why)')
        self.get_logger().info(f'{name} {done}')

    def _call(self, name: str, client, request, what: str):
        if not client.wait_for_service(timeout_sec=self.timeout):
            raise RadError(f'{name} offers no {what} service within {self.timeout:g} s: is it running, '
                           'and a managed node?')
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _: done.set())
        if not done.wait(self.timeout):
            client.remove_pending_request(future)
            raise RadError(f'{name} did not answer {what} within {self.timeout:g} s')
        return future.result()

    def _health(self, name: str):
        """The node's state as it last answered (asked again each time, without waiting)."""
        client = self.clients_[name][0]

        def update(future):
            if future.result() is not None:
                self.states[name] = future.result().current_state.label

        def check():
            if not client.service_is_ready():
                self.states[name] = 'unknown'
                return ERROR, 'not running (no lifecycle services)', {}
            client.call_async(GetState.Request()).add_done_callback(update)
            state = self.states[name]
            return (OK if state == 'active' else WARN), state, {}
        return check


def main(args=None):
    raise SystemExit(run_node(LifecycleManager, args, executor_factory=lambda: MultiThreadedExecutor(num_threads=4)))

"""A Franka cell as the planners see it: the arm controller's and the hand's actions.

`ActionPlant` sends a step's commands the way ROS 2 users drive a franka_ros2 cell:
arm trajectories as `control_msgs/action/FollowJointTrajectory` goals to
``<arm_controller>/follow_joint_trajectory`` (the robot model's 7 arm joints, with
path and goal tolerances and goal_time_tolerance), gripper commands as
`control_msgs/action/GripperCommand` goals to ``<gripper_action>``, or with the vacuum gripper
(``vacuum_ns`` given) its commands as franka_vacuum_gripper Vacuum and DropOff goals to
``<vacuum_ns>/vacuum`` and ``<vacuum_ns>/dropoff`` (franka_ros's action names; each result's success and
error are checked, an aborted goal read as its result). The controller's
answer decides, and every failure names the action and the controller's words: a
rejected goal or an INVALID_* result raises `TrajectoryRejected` (the arm did not
move), a tolerance violation, a goal the server cancelled or one that did not end
in time (cancelled here) `TrajectoryAborted` (the arm stopped somewhere on the path);
the execute loop backs out and replans from either. A gripper goal rejected,
cancelled by its server or not answered in time raises `GripperFailed`; what an
answered one did is judged by `rad_core.cell.motion.gripper_problem`. `cancelled()`
turning true while a goal runs cancels it (the controller stops the arm) and raises
RadError('cancelled'), which ends the run.

The node given must be spun by an executor on another thread (the calls here block
until the futures complete).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable

from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import JointTolerance
from franka_vacuum_gripper.action import DropOff, Vacuum
from rad_core.cell.motion import VACUUM_ACTIONS, GripperFailed, GripperResult
from rad_core.cell.motion import GripperCommand as GripperStep
from rad_core.cell.panda import FINGER_OPEN
from rad_core.cell.robot_model import RobotModel
from rad_core.cell.trajectory import (
    GOAL_TOLERANCE_VIOLATED,
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    Trajectory,
    TrajectoryAborted,
    TrajectoryRejected,
)
from rad_core.domain.errors import RadError
from rclpy.action import ActionClient as _ActionClient

from rad_ros.motion import s_to_duration, trajectory_to_msg


class ActionClient(_ActionClient):
    """rclpy's ActionClient, safe to send from one thread while an executor spins it on another.

    rclpy 7.1 (Jazzy) registers a request's future only after the request is sent; when the
    executor's thread takes the answer in between, the answer is dropped ("Ignoring unexpected
    goal response") and the goal never completes (ros2/rclpy#1123, fixed upstream by a lock).
    Here sending and registering, and taking answers, hold one lock.
    """

    def __init__(self, *args, **kwargs):
        self._send_lock = threading.RLock()
        super().__init__(*args, **kwargs)

    def take_data(self):
        with self._send_lock:
            return super().take_data()

    def send_goal_async(self, *args, **kwargs):
        with self._send_lock:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, goal_handle):
        with self._send_lock:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle):
        with self._send_lock:
            return super()._get_result_async(goal_handle)


ERROR_NAMES = {0: 'SUCCESSFUL', -1: 'INVALID_GOAL', -2: 'INVALID_JOINTS', -3: 'OLD_HEADER_TIMESTAMP',
               -4: 'PATH_TOLERANCE_VIOLATED', -5: 'GOAL_TOLERANCE_VIOLATED'}


class ActionPlant:
    """move_arm / move_gripper over the two actions (see the module docstring)."""

    def __init__(self, node, model: RobotModel, arm_controller: str, gripper_action: str, *,
                 path_tolerance: float = 0.05, goal_tolerance: float = 0.01, goal_time_tolerance: float = 1.0,
                 gripper_result_is_width: bool = False, server_timeout_s: float = 5.0,
                 timeout_factor: float = 3.0, cancelled: Callable[[], bool] = lambda: False, vacuum_ns: str = ''):
        self.model = model
        self.arm_name = f'{arm_controller.rstrip("/")}/follow_joint_trajectory'
        self.gripper_name = gripper_action
        self.arm = ActionClient(node, FollowJointTrajectory, self.arm_name)
        self.vacuum = {}
        if vacuum_ns:       # the vacuum gripper in the hand's place: no GripperCommand action to talk to
            ns = vacuum_ns.rstrip('/')
            self.vacuum = {'vacuum': (ActionClient(node, Vacuum, f'{ns}/vacuum'), f'{ns}/vacuum'),
                           'drop_off': (ActionClient(node, DropOff, f'{ns}/dropoff'), f'{ns}/dropoff')}
        else:
            self.gripper = ActionClient(node, GripperCommand, gripper_action)
        self.path_tolerance, self.goal_tolerance = path_tolerance, goal_tolerance
        self.goal_time_tolerance = goal_time_tolerance
        self.gripper_result_is_width = gripper_result_is_width
        self.server_timeout_s, self.timeout_factor = server_timeout_s, timeout_factor
        self.cancelled = cancelled

    def move_arm(self, trajectory: Trajectory | dict, frame_id: str = '') -> None:
        traj = trajectory if isinstance(trajectory, Trajectory) else Trajectory.from_dict(trajectory)
        goal = FollowJointTrajectory.Goal()
        goal.trajectory = trajectory_to_msg(traj.to_dict(), frame_id)
        names = list(traj.joint_names)
        goal.path_tolerance = [JointTolerance(name=n, position=self.path_tolerance) for n in names]
        goal.goal_tolerance = [JointTolerance(name=n, position=self.goal_tolerance) for n in names]
        goal.goal_time_tolerance = s_to_duration(self.goal_time_tolerance)
        wait = traj.duration * self.timeout_factor + self.goal_time_tolerance + 10.0
        try:
            result = self._run(self.arm, self.arm_name, goal, wait, 'the arm controller')
        except _Refused as e:
            raise TrajectoryRejected(INVALID_GOAL, str(e)) from None     # it never started: the arm did not move
        except _Dropped as e:
            raise TrajectoryAborted(PATH_TOLERANCE_VIOLATED, str(e)) from None   # stopped somewhere on the path
        code = int(result.error_code)
        if code != FollowJointTrajectory.Result.SUCCESSFUL:
            why = (f'the arm controller ({self.arm_name}) failed the trajectory: '
                   f'{ERROR_NAMES.get(code, "error")} ({code}): {result.error_string or "no reason given"}')
            if code in (PATH_TOLERANCE_VIOLATED, GOAL_TOLERANCE_VIOLATED):
                raise TrajectoryAborted(code, why)     # it moved and stopped: the arm is somewhere on the path
            if code in ERROR_NAMES:
                raise TrajectoryRejected(code, why)    # INVALID_GOAL, INVALID_JOINTS, OLD_HEADER_TIMESTAMP
            raise RadError(why)

    def move_gripper(self, command: GripperStep) -> GripperResult:
        if command.action in VACUUM_ACTIONS:
            return self._move_vacuum(command)
        if self.vacuum:
            raise RadError(f'a {command.action!r} gripper command, but this cell carries the vacuum gripper')
        goal = GripperCommand.Goal()
        goal.command.position, goal.command.max_effort = float(command.position), float(command.max_effort)
        travel = 0.08 / 0.05      # the whole stroke at a slow hand's speed
        try:
            result = self._run(self.gripper, self.gripper_name, goal, travel * self.timeout_factor + 10.0,
                               'the gripper', accept_aborted=True)
        except (_Refused, _Dropped) as e:
            raise GripperFailed(str(e)) from None
        position = float(result.position) / (2.0 if self.gripper_result_is_width else 1.0)
        return GripperResult(position, float(result.effort), bool(result.stalled), bool(result.reached_goal))

    def _move_vacuum(self, command: GripperStep) -> GripperResult:
        """A Vacuum or DropOff goal; its result's success as reached_goal, its error text as error."""
        if not self.vacuum:
            raise RadError(f'a {command.action!r} command, but this cell has no vacuum gripper (vacuum_ns)')
        client, name = self.vacuum[command.action]
        if command.action == 'vacuum':
            goal = Vacuum.Goal(vacuum=int(command.vacuum), timeout=int(command.timeout_ms))
        else:
            goal = DropOff.Goal(timeout=int(command.timeout_ms))
        try:
            result = self._run(client, name, goal, command.timeout_ms / 1000.0 * self.timeout_factor + 10.0,
                               'the vacuum gripper', accept_aborted=True)
        except (_Refused, _Dropped) as e:
            raise GripperFailed(str(e)) from None
        return GripperResult(FINGER_OPEN, reached_goal=bool(result.success), error=str(result.error))

    def _run(self, client, name, goal, timeout_s, what, accept_aborted=False):
        if not client.wait_for_server(timeout_sec=self.server_timeout_s):
            raise RadError(f'{what} action {name} is not available (is the controller running?)')
        handle = _wait(client.send_goal_async(goal), self.server_timeout_s)
        if handle is None:
            raise RadError(f'{what} ({name}) did not answer the goal within {self.server_timeout_s:g} s')
        if not handle.accepted:
            raise _Refused(f'{what} ({name}) rejected the goal (its log says why)')
        future = handle.get_result_async()
        deadline = time.monotonic() + timeout_s
        while not future.done():
            if self.cancelled():
                _wait(handle.cancel_goal_async(), self.server_timeout_s)
                _wait(future, self.server_timeout_s)
                raise RadError('cancelled')
            if time.monotonic() > deadline:
                _wait(handle.cancel_goal_async(), self.server_timeout_s)
                raise _Dropped(f'{what} ({name}) did not finish within {timeout_s:.1f} s; the goal was cancelled')
            time.sleep(0.01)
        wrapped = future.result()
        if wrapped.status == GoalStatus.STATUS_CANCELED:
            raise _Dropped(f'{what} ({name}) cancelled the goal')
        if wrapped.status != GoalStatus.STATUS_SUCCEEDED and not accept_aborted and \
                int(getattr(wrapped.result, 'error_code', 0)) == 0:
            raise _Dropped(f'{what} ({name}) aborted the goal without an error code')
        return wrapped.result


class _Refused(RadError):
    """The action server rejected the goal: nothing moved."""


class _Dropped(RadError):
    """The goal ended without a result to judge (cancelled by its server, aborted with no code, no answer
    in time): it may have moved partway."""


def _wait(future, timeout_s: float):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout_s if math.isfinite(timeout_s) else None):
        return None
    return future.result()

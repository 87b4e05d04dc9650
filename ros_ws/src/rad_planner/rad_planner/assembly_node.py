"""/plan_assembly and /execute_assembly: the assembly planner and executor of the node graph.

It knows the world only through the graph: the scene from the request or, if the
request has none, registered from motion capture against the task (`task_file`
parameter, else the latched `scene` topic); the robot from
`joint_states`; allocation from `/allocate`; the order from the sequencer node
(`/sequence`, asked at every step for a ranking of the next actions); motions from
`/plan_action`. How is the `agent` parameter's (`rad_core.sequencing.decide.agents`, `default` like the
sequencer node's; `rad_core.sequencing.agent.agent_plan.plan_for_agent`, what `rad eval` and the
benchmarks run in process): the first allocation with its support rule; verified, the
first ranked action GAMP finds feasible is taken (unverified: the first ranked only); when
nothing can be built next while allocated poses remain and it re-allocates, it re-solves
through `/allocate` (no-goods excluded, at most `max_reallocations`). So the twin
can be replaced by a real cell, and the policy by another, without touching this node.
A sequencer that is down or does not answer within `sequencer_timeout_s` fails the
request with a reason naming it.

  srv  plan_assembly     rad_msgs/PlanAssembly
  act  execute_assembly  rad_msgs/ExecuteAssembly: plan, execute step by step through the
                         arm controller's FollowJointTrajectory action (<arm_controller>/
                         follow_joint_trajectory) and the hand's GripperCommand action
                         (<gripper_action>), re-register after each step, replan on deviation
                         or a failed grasp (the loop is rad_core.sequencing.execution.execute; this node
                         supplies the plant: rad_ros.plant.ActionPlant); cancelling it cancels
                         the running goal and the arm stops. After a fault, blocks no scene can
                         express (fallen over, pushed off their cells) are set aside as lost and
                         the plan is repaired from the rest (rad_core.cell.mocap.register_world)
  act  take_apart        rad_msgs/TakeApart: the structure back onto the table, each motion verified
                         (rad_planner.take_apart, rad_core.sequencing.execution.disassembly)
                         One goal of the two at a time drives the arm: a goal sent while another
                         runs ends at once, aborted, its reason naming that goal (rad_ros.arm_lock)
  pub  plan_json         std_msgs/String (latched): the latest plan, for the visualizer
  pub  /tf_static        tf2_msgs/TFMessage (latched): the calibration frame_id -> mocap_frame, when
                         motion capture reports in a frame of its own
  pub  /diagnostics      diagnostic_msgs/DiagnosticArray, each second: joint states' freshness, motion
                         capture tracking, which goal drives the arm, and whether the arm controller, the
                         gripper, the sequencer, GAMP and the allocation answer (rad_ros.diagnostics)
  cli  <feeder_service>  rad_msgs/PresentBlock (default feeder/present, the twin's): before each pick of a
                         block from the scene's feeder, the feeder presents it at its station
  sub  motion capture    as mocap_driver publishes it (rad_ros.mocap_input.DRIVERS; mocap_input, mocap_topic,
                         pose_topic and mocap_frame override its settings): rad_msgs/RigidBodies ('rad', the
                         twin's), mocap4r2_msgs/RigidBodies ('mocap4r2_optitrack': /rigid_bodies, bodies
                         named by Motive ID, frame 'map'), one geometry_msgs/PoseStamped per body
                         ('natnet_ros2': /natnet_ros2/{body}/pose, 'vrpn_mocap': /vrpn_mocap/{body}/pose,
                         frame 'world'), or fiducial tags' transforms camera -> tag on /tf ('fiducial_tags')

Motion capture (rad_core.cell.mocap_input): poses arrive in mocap_frame ('' = the driver's frame; the
twin's: frame_id) and are taken into frame_id by the calibration mocap_to_base_translation / _quaternion
(p_base = R p + t; a camera's from `rad calibrate --hand-eye`); a message in another frame is refused,
naming both. Motion capture whose frame cannot be told from frame_id (mocap_frame '' or equal to it) or
that has no calibration is refused, naming both frames and the fix, unless mocap_in_base_frame says it
reports in frame_id itself (the twin): the node logs it at configure, /diagnostics reports it and every
registration fails with it, while plans from a request's scene go on. Bodies are named by block id unless
body_map_file maps them ({bodies: {NAME: {block: ID, pivot: [x, y, z]}}, ignore: [NAME]}, the
pivot's offset from the anchor unit's centre in the block frame; mocap4r2's numeric names as 1: or
'1':); ignore_bodies lists more to skip; any other body is skipped and reported once. A block
whose body is momentarily not seen (tracking_valid false, missing from a frame) is waited for, up to
lost_timeout_s; one lost for longer fails the request naming it. table_z is the table top's height in frame_id.
mocap_noise (m) and mocap_yaw_noise_deg (deg), the tracker's noise as a standard deviation,
widen the registration tolerances and the deviation check to 5 and 6 sigma, so that noise
alone is not taken for a fault.

The robot's state comes from joint_states by name (the model's arm and finger joints,
parameters robot and joint_prefix): a missing joint, a latest message that arrived longer than
stale_after_s ago (this computer's monotonic clock), or a stamp off this node's clock by more than
stale_after_s and clock_skew_tolerance_s allow fails the request with that reason, saying when the stamps
look like another clock (simulated time, unsynchronised computers) and the fix (require_joint_states;
false plans from home when no joint states are heard, and says so in the log).
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
import time

import numpy as np
import rclpy
from rad_core.cell import panda
from rad_core.cell.mocap import Registration, RegistrationConfig, register_scene, register_world
from rad_core.cell.mocap_input import BodyMap, MocapFrames, MocapTracker, wait_for_bodies
from rad_core.cell.robot_model import robot_model
from rad_core.cell.trajectory import limit_violation
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.cell.panda import FINGER_OPEN, check_effector
from rad_core.sequencing.agent.agent_plan import IMPROVE_TIME_S, effector_solvers, plan_for_agent
from rad_core.sequencing.decide.agents import parse
from rad_core.sequencing.decide.sequencer import Ranking
from rad_core.sequencing.execution.execute import ExecuteConfig, execute_assembly
from rad_core.sequencing.planning.plan import MotionPlan
from rad_core.sequencing.planning.reallocation import reallocation_support
from control_msgs.action import FollowJointTrajectory, GripperCommand
from franka_vacuum_gripper.action import Vacuum
from rad_msgs.action import ExecuteAssembly
from rad_msgs.msg import Scene as SceneMsg
from rad_msgs.srv import Allocate, PlanAction, PlanAssembly, PresentBlock, Sequence
from rad_ros.arm_lock import ArmLock
from rad_ros.diagnostics import ERROR, OK, WARN, Checks, answers
from rad_ros.conversions import (
    allocation_from_response,
    placement_to_msg,
    scene_from_msg,
    scene_from_request,
    scene_msg_is_empty,
)
from rad_ros.lifecycle import ManagedNode
from rad_ros.mocap_input import MocapInput, calibration_tf, resolve_driver
from rad_ros.motion import motion_from_msgs, moved_aside_from_msgs
from rad_ros.node_main import run_node
from rad_ros.params import Param, declare
from rad_ros.plan_msgs import fill_plan_response, plan_json
from rad_ros.plant import ActionPlant
from rad_ros.qos import LATCHED
from rad_ros.sequencer_msgs import action_to_msg, ranking_from_response, sequence_request
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from rad_planner.take_apart import serve_take_apart


# /plan_assembly's anytime deadline when a request leaves time_limit_s at 0: no improvement of the first
# complete plan starts after it, and an answer that needs no longer first plan comes within it plus 10 %
# (2.5 s). The first plan itself has time_limit_s. A request's own time_limit_s is a hard deadline.
ANYTIME_DEADLINE_S = 2.25
# How long deactivate waits for a stopped goal to end (the arm stops within a control step; the goal
# then waits for motion capture to settle and re-registers).
DEACTIVATE_WAIT_S = 15.0
# The share of a request's time limit kept back from the planner (see plan_assembly_callback).
DEADLINE_MARGIN = 0.05



# Read for each request (dynamic: `ros2 param set` applies to the next one), or when the node configures
# (read-only: set them in the parameter file or on the command line).
PARAMS = [
    Param('time_limit_s', 120.0, "a request's time limit when it gives none (s)", True, (0.1, 3600.0)),
    Param('anytime_deadline_s', ANYTIME_DEADLINE_S, 'no improvement of a first plan starts after this (s), when a '
          'request gives no time limit', True, (0.01, 600.0)),
    Param('allocation_time_limit_s', 10.0, "CP-SAT's time limit per allocation (s)", True, (0.1, 600.0)),
    Param('seed', 0, 'seed of the planner', True, (0, 2 ** 31 - 1)),
    Param('task_file', '', "the task scene (JSON); '' = the latched scene topic"),
    Param('service_timeout_s', 60.0, 'how long a call to GAMP or the allocation may take (s)', True, (0.1, 3600.0)),
    Param('stale_after_s', 2.0, 'joint states and motion capture older than this are stale (s)', False, (0.01, 60.0)),
    Param('settle_s', 0.5, 'wait after a placement before registering (s)', True, (0.0, 30.0)),
    Param('position_tol', 0.005, 'a placed block further than this from its pose is a deviation (m)', True,
          (0.0001, 0.1)),
    Param('max_replans', 3, 'replans per execution', True, (0, 100)),
    Param('step_timeout_factor', 3.0, "a motion may take this times its planned duration", True, (1.0, 100.0)),
    Param('frame_id', 'world', "the robot's base frame"),
    Param('sequencer_timeout_s', 20.0, 'how long /sequence may take (s)', True, (0.1, 600.0)),
    Param('agent', 'default', 'the agent whose verification, re-allocation and support this node runs'),
    Param('max_reallocations', 10, 're-allocations per plan when nothing can be built next', True, (0, 1000)),
    Param('improve_time_s', IMPROVE_TIME_S, 'time for improving a first complete plan (s)', True, (0.0, 3600.0)),
    Param('robot', 'panda', 'panda or fr3'),
    Param('joint_prefix', '', "joint names' prefix ('' = the robot's)"),
    Param('arm_controller', 'joint_trajectory_controller', "the arm controller's name (its follow_joint_trajectory)"),
    Param('gripper_action', 'franka_gripper/gripper_action', "the hand's GripperCommand action"),
    Param('gripper_result_is_width', False, "the gripper's result position is the width between the fingers "
          '(franka_gripper), not per finger', True),
    Param('path_tolerance', 0.05, 'path tolerance sent with each arm goal (rad)', True, (0.0, 1.0)),
    Param('goal_tolerance', 0.01, 'goal tolerance sent with each arm goal (rad)', True, (0.0, 1.0)),
    Param('goal_time_tolerance', 1.0, 'goal time tolerance sent with each arm goal (s)', True, (0.0, 60.0)),
    Param('require_joint_states', True, 'false: plan from home when no joint states are heard', True),
    Param('mocap_driver', 'rad', 'the motion-capture driver, which sets the input, topics and frame below: '
          'rad (the twin), mocap4r2_optitrack, natnet_ros2, vrpn_mocap or fiducial_tags'),
    Param('mocap_input', '', "motion capture's message: rad, mocap4r2, pose_stamped or tf ('' = the driver's)"),
    Param('mocap_topic', '', "the rigid bodies topic (rad, mocap4r2) or the transforms' (tf) ('' = the driver's)"),
    Param('pose_topic', '', "one PoseStamped per body, {body} replaced (pose_stamped) ('' = the driver's)"),
    Param('mocap_frame', '', "the frame motion capture reports in ('' = the driver's; the twin's: frame_id)"),
    Param('mocap_in_base_frame', False, 'motion capture reports in frame_id itself (the twin): no calibration; '
          'false: a mocap_frame of its own and its calibration are needed'),
    Param('clock_skew_tolerance_s', 0.5, "how far the robot computer's clock may be off this node's before "
          "joint states' stamps are refused (s)", False, (0.0, 60.0)),
    Param('body_map_file', '', 'YAML mapping body names to blocks and pivots'),
    Param('table_z', 0.0, "the table top's height in frame_id (m)"),
    Param('lost_timeout_s', 2.0, 'how long a block that is not seen is waited for (s)', False, (0.0, 600.0)),
    Param('mocap_noise', 0.0, "the tracker's position noise, standard deviation (m)", False, (0.0, 0.05)),
    Param('mocap_yaw_noise_deg', 0.0, "the tracker's yaw noise, standard deviation (deg)", False, (0.0, 45.0)),
    Param('feeder_service', 'feeder/present', "the feeder's PresentBlock service"),
    Param('effector', 'hand', 'hand or suction'),
    Param('vacuum_ns', 'franka_vacuum_gripper', "the vacuum gripper's namespace (effector suction)"),
    Param('mocap_to_base_translation', [0.0, 0.0, 0.0], 'calibration: p_base = R p_mocap + t, t (m)', any_type=True),
    Param('mocap_to_base_quaternion', [0.0, 0.0, 0.0, 1.0], 'calibration: R as a quaternion [x, y, z, w]',
          any_type=True),
    Param('ignore_bodies', [], 'motion-capture bodies to skip', any_type=True),
]

class AssemblyNode(ManagedNode):
    """The planner and executor as a managed node: configure reads the parameters and opens its
    clients, servers and subscriptions; only while active does /plan_assembly plan and do
    /execute_assembly and /take_apart goals drive the arm (otherwise each answers with the reason);
    deactivate stops a running goal (the arm stops where it is) and waits for it to end."""

    def __init__(self):
        super().__init__('assembly')
        declare(self, PARAMS)
        self.io = None
        self.halting = threading.Event()   # set while deactivate stops the running goal

    def configure(self) -> None:
        self.model = robot_model(str(self.param('robot')), str(self.param('joint_prefix')))
        check_effector(str(self.param('effector')))     # a bad effector stops the node here with the reason
        # The agent's parts this node runs (verification, re-allocation, the allocation's support);
        # a learned scorer without an explicit support reads it from its model file here, once.
        self.agent = parse(str(self.param('agent')))
        self.support = self.agent.resolved_support()
        if int(self.param('max_reallocations')) < 0:
            raise RadError(f'max_reallocations must be >= 0, got {self.param("max_reallocations")}')
        self.lock = threading.Lock()
        self.joints: tuple[float, JointState] | None = None
        self.task: Scene | None = None
        path = self.get_parameter('task_file').value
        if path:
            self.task = Scene.load(path)
        self.mocap_source = resolve_driver(str(self.param('mocap_driver')), str(self.param('mocap_input')),
                                           str(self.param('mocap_topic')), str(self.param('pose_topic')),
                                           str(self.param('mocap_frame')))
        self.frames = MocapFrames.from_params(self.param('frame_id'), self.mocap_source.frame,
                                              self.param('mocap_to_base_translation'),
                                              self.param('mocap_to_base_quaternion'),
                                              bool(self.param('mocap_in_base_frame')))
        if self.frames.refusal:     # plans from a request's scene need no motion capture: the node comes up
            self.get_logger().error(self.frames.refusal)
        ignore = self.param('ignore_bodies') or []
        if isinstance(ignore, str) or not all(isinstance(n, str) for n in ignore):
            raise RadError(f'ignore_bodies must be a list of body names, got {ignore!r}')
        self.body_map = BodyMap.from_params(str(self.param('body_map_file')), ignore)
        self.registration = RegistrationConfig(table_z=_number(self.param('table_z'), 'table_z'))
        # The tracker's noise (std dev): registration tolerances and the deviation check widen with it.
        self.noise = (_number(self.param('mocap_noise'), 'mocap_noise'),
                      _number(self.param('mocap_yaw_noise_deg'), 'mocap_yaw_noise_deg'))
        if min(self.noise) < 0:
            raise RadError(f'mocap_noise and mocap_yaw_noise_deg must be >= 0, got {self.noise}')
        RegistrationConfig.for_noise(*self.noise, 0.05)   # refuses noise no 5 cm block lattice can take
        self.tracker = MocapTracker(self.frames, _number(self.param('lost_timeout_s'), 'lost_timeout_s'),
                                    fresh_s=_number(self.param('stale_after_s'), 'stale_after_s'))
        # Requests block while they wait for other services and for the robot, so
        # what they wait on (service responses, joint states, motion capture) is
        # handled by a node of its own with its own thread: however many requests
        # are in flight, nothing they depend on can be starved of a thread.
        self.io = rclpy.create_node('assembly_io', namespace=self.get_namespace(), context=self.context)
        self.allocate_client = self.io.create_client(Allocate, 'allocate')
        self.plan_client = self.io.create_client(PlanAction, 'plan_action')
        self.feeder_client = self.io.create_client(PresentBlock, str(self.param('feeder_service')))
        self.sequence_client = self.io.create_client(Sequence, 'sequence')
        self.io.create_subscription(JointState, 'joint_states', self.joint_states_callback, 10)
        self.mocap = MocapInput(self.io, self.tracker, self.mocap_source)
        if self.task is not None:
            self.watch_bodies(self.task)
        self.io.create_subscription(SceneMsg, 'scene', self.scene_callback, LATCHED)
        checks = self.health_checks()
        self.io_executor = SingleThreadedExecutor(context=self.context)
        self.io_executor.add_node(self.io)
        self.io_stop = threading.Event()
        self.io_thread = threading.Thread(target=self.spin_io, daemon=True)
        self.io_thread.start()
        group = ReentrantCallbackGroup()
        self.arm_lock = ArmLock()         # /execute_assembly and /take_apart: one goal at a time
        self.plan_pub = self.own(self.create_publisher(String, 'plan_json', LATCHED))
        if self.frames.calibrated:
            self.tf_static_pub = self.own(self.create_publisher(TFMessage, '/tf_static', LATCHED))
            self.tf_static_pub.publish(calibration_tf(self.frames, self.get_clock().now().to_msg()))
        self.own(self.create_service(PlanAssembly, 'plan_assembly', self.plan_assembly_callback, callback_group=group))
        self.own(ActionServer(self, ExecuteAssembly, 'execute_assembly',
                              self.arm_lock.serve(self, '/execute_assembly', ExecuteAssembly.Result, self._execute,
                                                  self.refusal),
                              goal_callback=lambda goal: GoalResponse.ACCEPT,
                              cancel_callback=lambda goal: CancelResponse.ACCEPT,
                              callback_group=group))
        self.own(serve_take_apart(self))
        self.diagnostics = Checks(self, checks)
        self.own(self.diagnostics.pub)
        self.own(self.diagnostics.timer)
        self.get_logger().info('assembly planner configured')

    def deactivate(self) -> None:
        """A goal that drives the arm is stopped (as a cancel stops it) and waited for."""
        if not self.arm_lock.holder:
            return
        self.get_logger().warning(f'deactivating: stopping {self.arm_lock.holder}')
        self.halting.set()
        try:
            if not self.arm_lock.wait_free(DEACTIVATE_WAIT_S):
                self.get_logger().error(f'{self.arm_lock.holder} still runs {DEACTIVATE_WAIT_S:g} s after the stop')
        finally:
            self.halting.clear()

    def cleanup(self) -> None:
        self.stop_io()
        super().cleanup()

    def refusal(self) -> str:
        """Why a goal or request cannot run now ('' while active)."""
        return '' if self.is_active else self.inactive_reason()

    def stop_requested(self, goal_handle) -> bool:
        """The goal was cancelled, or the node is being deactivated."""
        return goal_handle.is_cancel_requested or self.halting.is_set()

    def ended_why(self, goal_handle, reason: str) -> str:
        """A goal's result reason, saying so where deactivate stopped it (not a cancel)."""
        if self.halting.is_set() and not goal_handle.is_cancel_requested:
            return f'the assembly node was deactivated: {reason}'
        return reason

    def health_checks(self) -> dict:
        """What /diagnostics reports each second: the robot's state, motion capture, the arm, and each
        node and controller this one asks (`rad_ros.diagnostics`)."""
        controller = f'{str(self.param("arm_controller")).rstrip("/")}/follow_joint_trajectory'
        arm = ActionClient(self.io, FollowJointTrajectory, controller)
        if self.param('effector') == 'suction':
            name = f'{str(self.param("vacuum_ns")).rstrip("/")}/vacuum'
            gripper = ('vacuum gripper', answers(f'vacuum gripper ({name})',
                                                 ActionClient(self.io, Vacuum, name).server_is_ready))
        else:
            name = str(self.param('gripper_action'))
            gripper = ('gripper', answers(f'gripper ({name})',
                                          ActionClient(self.io, GripperCommand, name).server_is_ready))
        return {'lifecycle': lambda: ((OK if self.is_active else WARN), self.lifecycle_state(), {}),
                'joint states': self.joint_health, 'motion capture': self.mocap_health,
                'arm': lambda: (OK, f'driven by {self.arm_lock.holder}' if self.arm_lock.holder else 'idle', {}),
                'arm controller': answers(f'arm controller ({controller})', arm.server_is_ready),
                gripper[0]: gripper[1],
                'sequencer': answers('sequencer (/sequence)', self.sequence_client.service_is_ready),
                'grasp and motion planning': answers('GAMP (/plan_action)', self.plan_client.service_is_ready),
                'allocation': answers('allocation (/allocate)', self.allocate_client.service_is_ready)}

    def joint_health(self):
        try:
            joints = self.current_joints()
        except RadError as e:
            return ERROR, str(e), {}
        return OK, 'fresh', {'joints': len(joints)}

    def mocap_health(self):
        if self.frames.refusal:
            return ERROR, self.frames.refusal, {}
        with self.tracker.lock:
            last, bodies = self.tracker.last_message, len(self.tracker.tracks)
        if last is None:
            return WARN, 'no motion capture heard yet (plans from a request\'s scene need none)', {}
        age = self.tracker.clock() - last
        if age > self.tracker.lost_timeout_s:
            return ERROR, f'no motion capture for {age:.1f} s', {'bodies': bodies}
        return OK, f'{bodies} bodies tracked', {'bodies': bodies, 'age_s': round(age, 3)}

    def spin_io(self):
        # spin_once in a loop rather than spin: this rclpy's Executor.shutdown destroys the wait's
        # guard condition without waiting for spin to return, so the thread is stopped and joined
        # first, and only then is its executor shut down.
        try:
            while not self.io_stop.is_set() and self.context.ok():
                self.io_executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            pass

    def stop_io(self) -> None:
        if self.io is None:
            return
        self.io_stop.set()
        self.io_thread.join(timeout=2.0)
        self.io_executor.shutdown(timeout_sec=0)
        self.io.destroy_node()
        self.io = None

    def destroy_node(self):
        self.stop_io()
        super().destroy_node()

    def param(self, name):
        return self.get_parameter(name).value

    # ---- what the graph tells us ------------------------------------------------
    def joint_states_callback(self, msg: JointState) -> None:
        with self.lock:
            self.joints = (time.monotonic(), msg)

    def scene_callback(self, msg: SceneMsg) -> None:
        if not self.param('task_file'):
            try:
                self.task = scene_from_msg(msg)
            except RadError as e:
                self.get_logger().warning(f'ignoring an invalid scene on /scene: {e}')
                return
            try:
                self.watch_bodies(self.task)
            except RadError as e:   # said again by every request that registers against this task
                self.get_logger().warning(f'the body map does not fit the task on /scene: {e}')

    def watch_bodies(self, task: Scene):
        """The task's bodies by name (pose_stamped subscribes to each one's topic); RadError when the
        body map does not fit the task."""
        resolved = self.body_map.resolve({b.id: b.type for b in task.blocks})
        self.mocap.watch(resolved.by_body)
        return resolved

    def fresh(self, entry, what: str):
        """The message of `entry` (arrival time, message); RadError when none arrived or the latest arrived
        longer than stale_after_s ago (by this computer's monotonic clock: the staleness check)."""
        stale = float(self.param('stale_after_s'))
        if entry is None:
            raise RadError(f'no {what} received: is the robot (or the twin) running?')
        age = time.monotonic() - entry[0]
        if age > stale:
            raise RadError(f'no {what} for {age:.1f} s: is the robot (or the twin) running?')
        return entry[1]

    def current_joints(self) -> np.ndarray:
        """The model's 7 arm and 2 finger joints from joint_states, by name; RadError when a joint is
        missing, the latest message arrived too long ago, or its stamp is off this node's clock by more
        than stale_after_s and clock_skew_tolerance_s allow (saying when it looks like another clock)."""
        with self.lock:
            entry = self.joints
            msg = self.fresh(entry, '/joint_states')
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        why = stamp_problem('/joint_states', stamp, self.get_clock().now().nanoseconds * 1e-9,
                            float(self.param('stale_after_s')), float(self.param('clock_skew_tolerance_s')),
                            bool(self.get_parameter('use_sim_time').value), time.monotonic() - entry[0])
        if why:
            raise RadError(why)
        # The vacuum gripper has no joints: its fingers' places in the joint vector stay open.
        suction = self.param('effector') == 'suction'
        names = self.model.arm_joint_names + (() if suction else self.model.finger_joint_names)
        by_name = dict(zip(msg.name, msg.position))
        missing = [n for n in names if n not in by_name]
        if missing:
            raise RadError(f'/joint_states lacks {", ".join(missing)} (robot {self.model.name}, '
                           f'joint_prefix {self.model.prefix!r}); it has {", ".join(msg.name) or "no joints"}')
        return np.array([by_name[n] for n in names] + ([FINGER_OPEN, FINGER_OPEN] if suction else []))

    def registered_scene(self) -> Scene:
        """The task's blocks where motion capture sees them; RadError for a block no scene can express."""
        return register_scene(*self._bodies_and_config())

    def registered_world(self) -> Registration:
        """As `registered_scene`, but blocks no scene can express (fallen over, pushed off their cells) are
        set aside with the reason (`register_world`): what execution re-plans from after a fault."""
        return register_world(*self._bodies_and_config())

    def _bodies_and_config(self):
        if self.task is None:
            raise RadError('no scene in the request and no task known: set the task_file parameter '
                           'or publish the task on /scene')
        if self.frames.refusal:
            raise RadError(self.frames.refusal)
        task = self.task
        resolved = self.watch_bodies(task)
        bodies = wait_for_bodies(self.tracker, resolved, warn=self.get_logger().warning,
                                 optional=frozenset(task.feeder.blocks) if task.feeder is not None else frozenset())
        config = RegistrationConfig.for_noise(*self.noise, task.unit, **{
            **dataclasses.asdict(self.registration), 'body_map': resolved.registration_map})
        return bodies, task, config

    def scene_of(self, msg: SceneMsg, text: str) -> tuple[Scene, bool]:
        """The scene a request carries, or the registered one (and True) when it has none."""
        if scene_msg_is_empty(msg) and not text.strip():
            return self.registered_scene(), True
        return scene_from_request(msg, text), False

    # ---- the three backends plan_assembly needs, over DDS ------------------------------
    def call(self, client, request, timeout: float | None = None, what: str = ''):
        timeout = float(self.param('service_timeout_s')) if timeout is None else timeout
        what = what or f'service {client.srv_name}'
        if not client.wait_for_service(timeout_sec=min(timeout, 5.0)):
            raise RadError(f'{what} is not available')
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            client.remove_pending_request(future)
            raise RadError(f'{what} did not answer within {timeout:g} s')
        return future.result()

    def present_block(self, block_id: str) -> None:
        """The cell's feeder presents a block at its station (`feeder_service`); RadError with its reason."""
        response = self.call(self.feeder_client, PresentBlock.Request(block_id=block_id),
                             what=f'the feeder (service {self.feeder_client.srv_name})')
        if not response.success:
            raise RadError(f'the feeder did not present block {block_id}: {response.reason}')

    def rank(self, scene: Scene, placements, start, scorer_only: bool = False) -> Ranking:
        timeout = float(self.param('sequencer_timeout_s'))
        if not timeout > 0:
            raise RadError(f'the sequencer_timeout_s parameter must be positive, got {timeout}')
        response = self.call(self.sequence_client, sequence_request(scene, placements, start, scorer_only=scorer_only),
                             timeout, f'the sequencer node (service {self.sequence_client.srv_name})')
        return ranking_from_response(response)

    def quick_rank(self, scene: Scene, placements, start) -> Ranking:
        """The sequencer's scorer alone, without its search (anytime planning's first plan)."""
        return self.rank(scene, placements, start, scorer_only=True)

    def allocate(self, scene: Scene, exclude=(), time_limit_s: float | None = None, support: str | None = None):
        """/allocate for a scene state; exclude: no-goods (re-allocation)."""
        limit = float(self.param('allocation_time_limit_s')) if time_limit_s is None \
            else min(float(time_limit_s), float(self.param('allocation_time_limit_s')))
        request = Allocate.Request(scene_json=scene.dumps(), time_limit_s=max(limit, 1e-3),
                                   support=support or self.support, effector=str(self.param('effector')))
        request.exclude = [placement_to_msg(p) for p in exclude]
        response = self.call(self.allocate_client, request)
        if response.status == 'INVALID_REQUEST':
            raise RadError(response.reason)
        return allocation_from_response(response)

    def reallocate(self, scene: Scene, exclude, time_limit_s: float | None = None):
        """The re-solve on stall: the stable allocation (every new block can rest on something), arm-aware
        when the agent's allocation is (`reallocation_support`)."""
        return self.allocate(scene, exclude, time_limit_s, support=reallocation_support(self.support))

    def plan_motion(self, scene: Scene, action, start, move_aside: bool = False, set_down: bool = False) -> MotionPlan:
        request = self.plan_action_request(scene, start)
        request.action = action_to_msg(action)
        request.move_aside = bool(move_aside)
        request.set_down = bool(set_down)
        return self.ask_plan_action(request, start)

    @staticmethod
    def plan_action_request(scene: Scene, start) -> PlanAction.Request:
        return PlanAction.Request(scene_json=scene.dumps(),
                                  start_positions=[] if start is None else [float(v) for v in start])

    def ask_plan_action(self, request: PlanAction.Request, start) -> MotionPlan:
        """/plan_action's answer as a MotionPlan; RadError for a request it calls invalid or for a trajectory
        the robot would refuse (checked against the model's limits from `start`)."""
        response = self.call(self.plan_client, request)
        if response.failure in ('invalid_request', 'error'):
            raise RadError(f'plan_action: {response.reason}')
        if not response.success:
            return MotionPlan(False, response.failure, response.reason, seconds=response.planning_time_s)
        motion = motion_from_msgs(response.trajectories, response.gripper)
        start_q = panda.HOME if start is None else np.asarray(start, dtype=float)
        for k, traj in enumerate(motion['trajectories']):
            why = limit_violation(traj, start_q, self.model)
            if why:
                raise RadError(f'plan_action answered a trajectory the {self.model.name} would refuse '
                               f'(trajectory {k}): {why}')
            start_q = np.asarray(traj['points'][-1]['positions'])
        grasp = (response.grasp.unit, response.grasp.yaw_deg, max(1, response.grasp.span))
        return MotionPlan(True, '', response.reason if response.drop > 0 else '', grasp, motion,
                          moved_aside_from_msgs(response.moved_aside_blocks, response.moved_aside_poses),
                          seconds=response.planning_time_s, drop=float(response.drop))

    def plan(self, scene: Scene, time_limit: float, start, improve_until: float | None = None):
        plan = plan_for_agent(self.agent, scene, self.allocate, self.plan_motion, self.rank, self.reallocate,
                              support=self.support, seed=int(self.param('seed')), start=start,
                              time_limit_s=time_limit, max_reallocations=int(self.param('max_reallocations')),
                              quick_rank=self.quick_rank, improve_time_s=float(self.param('improve_time_s')),
                              improve_until_s=improve_until, solvers=effector_solvers(str(self.param('effector'))))
        self.plan_pub.publish(String(data=json.dumps(plan_json(plan))))
        return plan

    def time_limit(self, requested: float) -> float:
        if not math.isfinite(requested) or requested < 0:
            raise RadError(f'time_limit_s must be 0 (node default) or positive, got {requested}')
        limit = requested or float(self.param('time_limit_s'))
        if not limit > 0:
            raise RadError(f'the time_limit_s parameter must be positive, got {limit}')
        return limit

    def start_joints(self, requested):
        if len(requested):
            return list(requested)
        # A request right after start-up may come before the joint_states subscription has matched the
        # robot's publisher: wait up to stale_after_s for the first message before judging.
        deadline = time.monotonic() + float(self.param('stale_after_s'))
        while self.joints is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if not self.param('require_joint_states'):
            try:
                return self.current_joints()
            except RadError as e:
                self.get_logger().warning(f'planning from home (require_joint_states is false): {e}')
                return None
        return self.current_joints()

    def plant(self, cancelled) -> ActionPlant:
        return ActionPlant(self.io, self.model, str(self.param('arm_controller')), str(self.param('gripper_action')),
                           vacuum_ns=str(self.param('vacuum_ns')) if self.param('effector') == 'suction' else '',
                           path_tolerance=float(self.param('path_tolerance')),
                           goal_tolerance=float(self.param('goal_tolerance')),
                           goal_time_tolerance=float(self.param('goal_time_tolerance')),
                           gripper_result_is_width=bool(self.param('gripper_result_is_width')),
                           timeout_factor=float(self.param('step_timeout_factor')), cancelled=cancelled)

    # ---- /plan_assembly ------------------------------------------------------------
    def plan_assembly_callback(self, request, response):
        t0 = time.perf_counter()
        refused = self.refusal()
        if refused:
            response.success, response.reason = False, refused
            return response
        try:
            limit = self.time_limit(request.time_limit_s)
            # No limit asked for: the first complete plan, improved until the anytime deadline.
            anytime = None if request.time_limit_s else float(self.param('anytime_deadline_s'))
            if anytime is not None and not anytime > 0:
                raise RadError(f'the anytime_deadline_s parameter must be positive, got {anytime}')
            scene, registered = self.scene_of(request.scene, request.scene_json)
            registration = time.perf_counter() - t0 if registered else 0.0
            start = self.start_joints(request.start_positions)
            # The request's limit holds from its arrival: the planner gets what registration left of it,
            # less a margin for what runs past the planner's deadline (a GAMP or CP-SAT call under way
            # ends first) and for the response.
            spent = time.perf_counter() - t0
            budget = max(1e-3, (1.0 - DEADLINE_MARGIN) * limit - spent)
            until = None if anytime is None else max(1e-3, (1.0 - DEADLINE_MARGIN) * anytime - spent)
            plan = self.plan(scene, budget, start, until)
        except RadError as e:
            response.success, response.reason = False, str(e)
            self.get_logger().warning(f'plan_assembly refused: {e}')
            return response
        except Exception as e:  # noqa: BLE001 - a service must answer, never die
            self.get_logger().error(f'plan_assembly failed: {type(e).__name__}: {e}')
            response.success, response.reason = False, f'internal error: {e}'
            return response
        timings = dict(plan.timings, registration=registration, total=time.perf_counter() - t0)
        fill_plan_response(response, plan, timings, self.param('frame_id'))
        made_by = plan.anytime[-1]['plan'] if plan.anytime else 'plan'
        self.get_logger().info(f'planned {len(plan.steps)} steps, coverage {plan.predicted_coverage:.2f} '
                               f'in {timings["total"]:.2f} s, the best plan by the {made_by} stage'
                               + (f': {plan.reason}' if plan.reason else ''))
        return response

    # ---- /execute_assembly -------------------------------------------------------------
    def _execute(self, goal_handle):
        """Glue for rad_core.sequencing.execution.execute: the plant is the arm controller's and the hand's
        actions, joint states and motion capture; feedback and cancel go through the goal handle."""
        goal = goal_handle.request
        result = ExecuteAssembly.Result()
        t0 = time.perf_counter()
        feedback = ExecuteAssembly.Feedback()

        def report(step, planned, block, phase, message):
            feedback.step, feedback.steps_planned, feedback.block_id = step, planned, block
            feedback.phase, feedback.message = phase, message
            goal_handle.publish_feedback(feedback)

        try:
            limit = self.time_limit(goal.time_limit_s)
            scene, _ = self.scene_of(goal.scene, goal.scene_json)
            config = ExecuteConfig(float(self.param('settle_s')), float(self.param('position_tol')),
                                   int(self.param('max_replans')), bool(goal.replan), mocap_noise=self.noise[0])
            plant = self.plant(lambda: self.stop_requested(goal_handle))
            run = execute_assembly(scene, lambda current, start: self.plan(current, limit, start),
                                   plant.move_arm, plant.move_gripper,
                                   self.registered_world, config, joints=lambda: self.start_joints([]),
                                   cancelled=lambda: self.stop_requested(goal_handle), report=report,
                                   plan_motion=self.plan_motion, present=self.present_block)
        except RadError as e:
            result.success, result.reason = False, str(e)
            report(0, 0, '', 'done', result.reason)
            goal_handle.abort()
            return result
        except Exception as e:  # noqa: BLE001 - an action must answer, never die
            self.get_logger().error(f'execute_assembly failed: {type(e).__name__}: {e}')
            result.success, result.reason = False, f'internal error: {e}'
            report(0, 0, '', 'done', result.reason)
            goal_handle.abort()
            return result
        result.success, result.replans = run.success, run.replans
        result.reason = self.ended_why(goal_handle, run.reason)
        result.steps_executed = len(run.steps)
        result.coverage = run.coverage
        result.result_json = json.dumps(run.document({'total': time.perf_counter() - t0}))
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            (goal_handle.succeed if result.success else goal_handle.abort)()
        return result


# Stamps before this (2001-09-09) are not wall-clock time: a simulator's /clock counts from its start.
WALL_CLOCK_SINCE_S = 1e9
# Stamps further than this from the node's clock come from another clock, not from a late message.
OTHER_CLOCK_S = 60.0
SYNC = ('synchronise the computers\' clocks (chrony against the robot PC or a common NTP server, PTP where '
        'available: docs/real-cell.md)')


def _span(seconds: float) -> str:
    for unit, size in (('years', 365.25 * 86400), ('days', 86400), ('h', 3600), ('min', 60)):
        if seconds >= 2 * size:
            return f'{seconds / size:.1f} {unit}'
    return f'{seconds:.1f} s'


def stamp_problem(what: str, stamp: float, now: float, stale_s: float, skew_s: float, sim_time: bool,
                  arrived_s: float = 0.0) -> str:
    """Why a message stamped `stamp` cannot be taken at `now` (this node's clock, s), or '' when it can.

    A stamp may lag the node's clock by up to stale_s + skew_s and lead it by up to skew_s (the robot
    computer's clock a little off). Further off, the reason says whether the stamp looks like another clock
    (simulated time, or minutes to years away: unsynchronised computers) and what fixes it."""
    if stamp == 0.0:
        return f'{what} carries no stamp (header.stamp is 0): its publisher must stamp it'
    behind = now - stamp
    if -skew_s <= behind <= stale_s + skew_s:
        return ''
    if stamp < WALL_CLOCK_SINCE_S <= now and not sim_time:
        return (f'{what} is stale by this node\'s clock: it is stamped {stamp:.1f} s, which looks like simulated '
                'time (a simulator\'s /clock) while this node runs on the wall clock: start every node with '
                'use_sim_time:=true (graph --sim-time), or stamp with the wall clock')
    if sim_time and stamp >= WALL_CLOCK_SINCE_S > now:
        return (f'{what} is stamped with wall-clock time but this node uses simulated time (use_sim_time, now '
                f'{now:.1f} s): set use_sim_time:=false where the robot publishes on its own clock, or run the '
                'simulator that publishes /clock')
    limit = f'stale_after_s {stale_s:g} + clock_skew_tolerance_s {skew_s:g}' if behind > 0 \
        else f'clock_skew_tolerance_s {skew_s:g}'
    if abs(behind) > OTHER_CLOCK_S:
        side = 'behind' if behind > 0 else 'ahead of'
        return (f'{what} is stamped {_span(abs(behind))} {side} this node\'s clock ({limit}) though it arrived '
                f'{arrived_s:.2f} s ago: its publisher runs on another clock. ' + SYNC
                + ('; this node uses simulated time: every node needs the same /clock' if sim_time
                   else '; a simulator that publishes /clock needs use_sim_time:=true on every node'))
    if behind > 0:
        return (f'{what} is stale: its stamp is {behind:.1f} s old ({limit}) though it arrived {arrived_s:.2f} s '
                'ago: the robot computer\'s clock is behind this one\'s, or its messages are delayed. ' + SYNC
                + '; a simulator that publishes /clock needs use_sim_time:=true on every node')
    return (f'{what} is stamped {-behind:.1f} s ahead of this node\'s clock ({limit}): the robot computer\'s '
            'clock runs ahead. ' + SYNC)


def _number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RadError(f'{name} must be a finite number, got {value!r}')
    return float(value)


def main(args=None):
    raise SystemExit(run_node(AssemblyNode, args, executor_factory=lambda: MultiThreadedExecutor(num_threads=8)))

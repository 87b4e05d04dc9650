"""/plan_assembly and /execute_assembly: the assembly planner and executor of the node graph.

It knows the world only through the graph: the scene from the request or, if the
request has none, registered from motion capture (`rigid_bodies`) against the task
(`task_file` parameter, else the latched `scene` topic); the robot from
`joint_states`; allocation from `/allocate`; the order from the sequencer node
(`/sequence`, asked at every step for a ranking of the next actions); motions from
`/plan_action` (the first ranked action GAMP finds feasible is taken). When nothing
can be built next while allocated poses remain, it re-allocates through `/allocate`
(no-goods excluded, parameters `reallocate`, `max_reallocations`; the first
allocation's mode is `allocation_support`, 'stable' by default). So the twin
can be replaced by a real cell, and the policy by another, without touching this node.
A sequencer that is down or does not answer within `sequencer_timeout_s` fails the
request with a reason naming it.

  srv  plan_assembly     rad_msgs/PlanAssembly
  act  execute_assembly  rad_msgs/ExecuteAssembly: plan, execute step by step via the
                         trajectory topic, re-register after each step, replan on deviation
                         (the loop is rad_core.sequencing.execute; this node supplies the plant)
  pub  plan_json         std_msgs/String (latched): the latest plan, for the visualizer
  pub  joint_trajectory_controller/joint_trajectory  the steps' trajectories
"""

from __future__ import annotations

import json
import math
import threading
import time

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
import rclpy
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory

from rad_core.errors import RadError
from rad_core.scene import Scene
from rad_core.sequencing.execute import ExecuteConfig, execute_assembly
from rad_core.sequencing.plan import MotionPlan, plan_assembly
from rad_core.sequencing.reallocation import ReallocationConfig
from rad_core.sequencing.sequencer import Ranking
from rad_core.sim import panda
from rad_core.sim.mocap import RegistrationConfig, RigidBodyPose, body_map_for, register_scene
from rad_msgs.action import ExecuteAssembly
from rad_msgs.msg import RigidBodies, Scene as SceneMsg
from rad_msgs.srv import Allocate, PlanAction, PlanAssembly, Sequence
from rad_ros.conversions import (allocation_from_response, placement_to_msg, scene_from_msg, scene_from_request,
                                 scene_msg_is_empty)
from rad_ros.node_main import run_node
from rad_ros.plan_msgs import fill_plan_response, plan_json
from rad_ros.sequencer_msgs import action_to_msg, ranking_from_response, sequence_request
from rad_ros.motion import pose_from_msg, trajectory_from_msg, trajectory_to_msg
from rad_ros.qos import LATCHED


class AssemblyNode(Node):
    def __init__(self):
        super().__init__('assembly')
        for name, value in (('time_limit_s', 120.0), ('allocation_time_limit_s', 10.0), ('seed', 0),
                            ('task_file', ''), ('service_timeout_s', 60.0), ('stale_after_s', 2.0),
                            ('settle_s', 0.5), ('position_tol', 0.005), ('max_replans', 3),
                            ('step_timeout_factor', 3.0), ('frame_id', 'world'), ('sequencer_timeout_s', 20.0),
                            ('allocation_support', 'stable'), ('reallocate', True), ('max_reallocations', 10)):
            self.declare_parameter(name, value)
        self.lock = threading.Lock()
        self.joints: tuple[float, JointState] | None = None
        self.bodies = None
        self.task: Scene | None = None
        path = self.get_parameter('task_file').value
        if path:
            self.task = Scene.load(path)
        # Requests block while they wait for other services and for the robot, so
        # what they wait on (service responses, joint states, motion capture) is
        # handled by a node of its own with its own thread: however many requests
        # are in flight, nothing they depend on can be starved of a thread.
        self.io = rclpy.create_node('assembly_io', namespace=self.get_namespace(), context=self.context)
        self.allocate_client = self.io.create_client(Allocate, 'allocate')
        self.plan_client = self.io.create_client(PlanAction, 'plan_action')
        self.sequence_client = self.io.create_client(Sequence, 'sequence')
        self.io.create_subscription(JointState, 'joint_states', self.joint_states_callback, 10)
        self.io.create_subscription(RigidBodies, 'rigid_bodies', self.rigid_bodies_callback, qos_profile_sensor_data)
        self.io.create_subscription(SceneMsg, 'scene', self.scene_callback, LATCHED)
        self.io_executor = SingleThreadedExecutor(context=self.context)
        self.io_executor.add_node(self.io)
        self.io_thread = threading.Thread(target=self.io_executor.spin, daemon=True)
        self.io_thread.start()
        group = ReentrantCallbackGroup()
        self.trajectory_pub = self.create_publisher(JointTrajectory, 'joint_trajectory_controller/joint_trajectory', 10)
        self.plan_pub = self.create_publisher(String, 'plan_json', LATCHED)
        self.create_service(PlanAssembly, 'plan_assembly', self.plan_assembly_callback, callback_group=group)
        self.action_server = ActionServer(self, ExecuteAssembly, 'execute_assembly', self.execute_callback,
                                          goal_callback=lambda goal: GoalResponse.ACCEPT,
                                          cancel_callback=lambda goal: CancelResponse.ACCEPT,
                                          callback_group=group)
        self.get_logger().info('assembly planner ready')

    def destroy_node(self):
        self.io_executor.shutdown(timeout_sec=2.0)
        self.io.destroy_node()
        super().destroy_node()

    def param(self, name):
        return self.get_parameter(name).value

    # ---- what the graph tells us ------------------------------------------------
    def joint_states_callback(self, msg: JointState) -> None:
        with self.lock:
            self.joints = (time.monotonic(), msg)

    def rigid_bodies_callback(self, msg) -> None:
        with self.lock:
            self.bodies = (time.monotonic(), msg)

    def scene_callback(self, msg: SceneMsg) -> None:
        if not self.param('task_file'):
            try:
                self.task = scene_from_msg(msg)
            except RadError as e:
                self.get_logger().warning(f'ignoring an invalid scene on /scene: {e}')

    def fresh(self, entry, what: str):
        stale = float(self.param('stale_after_s'))
        if entry is None:
            raise RadError(f'no {what} received: is the robot (or the twin) running?')
        age = time.monotonic() - entry[0]
        if age > stale:
            raise RadError(f'no {what} for {age:.1f} s: is the robot (or the twin) running?')
        return entry[1]

    def current_joints(self) -> np.ndarray:
        with self.lock:
            msg = self.fresh(self.joints, '/joint_states')
        by_name = dict(zip(msg.name, msg.position))
        missing = [n for n in panda.JOINT_NAMES if n not in by_name]
        if missing:
            raise RadError(f'/joint_states lacks {", ".join(missing)}')
        return np.array([by_name[n] for n in panda.JOINT_NAMES])

    def registered_scene(self) -> Scene:
        if self.task is None:
            raise RadError('no scene in the request and no task known: set the task_file parameter '
                           'or publish the task on /scene')
        with self.lock:
            msg = self.fresh(self.bodies, 'motion capture on /rigid_bodies')
        bodies = [RigidBodyPose(b.rigid_body_name, *pose_from_msg(b.pose), b.tracking_valid)
                  for b in msg.rigidbodies]
        return register_scene(bodies, self.task, RegistrationConfig(body_map=body_map_for(self.task)))

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

    def rank(self, scene: Scene, placements, start) -> Ranking:
        timeout = float(self.param('sequencer_timeout_s'))
        if not timeout > 0:
            raise RadError(f'the sequencer_timeout_s parameter must be positive, got {timeout}')
        response = self.call(self.sequence_client, sequence_request(scene, placements, start), timeout,
                             f'the sequencer node (service {self.sequence_client.srv_name})')
        return ranking_from_response(response)

    def allocate(self, scene: Scene, exclude=(), time_limit_s: float | None = None, support: str | None = None):
        """/allocate for a scene state; exclude: no-goods (re-allocation)."""
        limit = float(self.param('allocation_time_limit_s')) if time_limit_s is None \
            else min(float(time_limit_s), float(self.param('allocation_time_limit_s')))
        request = Allocate.Request(scene_json=scene.dumps(), time_limit_s=max(limit, 1e-3),
                                   support=support or str(self.param('allocation_support')))
        request.exclude = [placement_to_msg(p) for p in exclude]
        response = self.call(self.allocate_client, request)
        if response.status == 'INVALID_REQUEST':
            raise RadError(response.reason)
        return allocation_from_response(response)

    def reallocate(self, scene: Scene, exclude, time_limit_s: float | None = None):
        """The re-solve on stall: always the stable allocation (every new block can rest on something)."""
        return self.allocate(scene, exclude, time_limit_s, support='stable')

    def plan_motion(self, scene: Scene, action, start) -> MotionPlan:
        request = PlanAction.Request(scene_json=scene.dumps(),
                                     start_positions=[] if start is None else [float(v) for v in start])
        request.action = action_to_msg(action)
        response = self.call(self.plan_client, request)
        if response.failure in ('invalid_request', 'error'):
            raise RadError(f'plan_action: {response.reason}')
        if not response.success:
            return MotionPlan(False, response.failure, response.reason)
        return MotionPlan(True, '', '', (response.grasp.unit, response.grasp.yaw_deg),
                          trajectory_from_msg(response.trajectory))

    def plan(self, scene: Scene, time_limit: float, start):
        reallocation = None
        if self.param('reallocate'):
            reallocation = ReallocationConfig(max_reallocations=int(self.param('max_reallocations')))
            reallocation.validate()
        plan = plan_assembly(scene, self.allocate, self.plan_motion, self.rank, seed=int(self.param('seed')),
                             start=start, time_limit_s=time_limit,
                             reallocate=self.reallocate if reallocation is not None else None,
                             reallocation=reallocation)
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
        try:
            return self.current_joints()
        except RadError:
            return None   # no robot heard from: plan from home

    # ---- /plan_assembly ------------------------------------------------------------
    def plan_assembly_callback(self, request, response):
        t0 = time.perf_counter()
        try:
            limit = self.time_limit(request.time_limit_s)
            scene, registered = self.scene_of(request.scene, request.scene_json)
            registration = time.perf_counter() - t0 if registered else 0.0
            plan = self.plan(scene, limit, self.start_joints(request.start_positions))
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
        self.get_logger().info(f'planned {len(plan.steps)} steps, coverage {plan.predicted_coverage:.2f} '
                               f'in {timings["total"]:.2f} s' + (f': {plan.reason}' if plan.reason else ''))
        return response

    # ---- /execute_assembly -------------------------------------------------------------
    def execute_callback(self, goal_handle):
        """Glue for rad_core.sequencing.execute: the plant is the trajectory topic, joint states
        and motion capture; feedback and cancel go through the goal handle."""
        goal = goal_handle.request
        result = ExecuteAssembly.Result()
        t0 = time.perf_counter()
        feedback = ExecuteAssembly.Feedback()

        def report(step, planned, block, phase, message):
            feedback.step, feedback.steps_planned, feedback.block_id = step, planned, block
            feedback.phase, feedback.message = phase, message
            goal_handle.publish_feedback(feedback)

        def send(trajectory: dict) -> None:
            self.trajectory_pub.publish(trajectory_to_msg(trajectory, self.param('frame_id')))
            self.wait_until_done(trajectory)

        try:
            limit = self.time_limit(goal.time_limit_s)
            scene, _ = self.scene_of(goal.scene, goal.scene_json)
            config = ExecuteConfig(float(self.param('settle_s')), float(self.param('position_tol')),
                                   int(self.param('max_replans')), bool(goal.replan))
            run = execute_assembly(scene, lambda current, start: self.plan(current, limit, start), send,
                                   self.registered_scene, config, joints=lambda: self.start_joints([]),
                                   cancelled=lambda: goal_handle.is_cancel_requested, report=report)
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
        result.success, result.reason, result.replans = run.success, run.reason, run.replans
        result.steps_executed = len(run.steps)
        result.coverage = run.coverage
        result.result_json = json.dumps(run.document({'total': time.perf_counter() - t0}))
        (goal_handle.succeed if result.success else goal_handle.abort)()
        return result

    def wait_until_done(self, trajectory: dict) -> None:
        """Until the robot rests at the trajectory's last point; fails if the robot
        goes quiet (joint states stop) or takes far longer than the trajectory."""
        final = np.asarray(trajectory['points'][-1]['positions'])
        names = list(trajectory['joint_names'])
        duration = float(trajectory['points'][-1]['time_from_start'])
        deadline = time.monotonic() + duration * float(self.param('step_timeout_factor')) + 10.0
        index = [panda.JOINT_NAMES.index(n) for n in names]
        while True:
            q = self.current_joints()
            with self.lock:
                velocity = np.asarray(self.joints[1].velocity) if self.joints[1].velocity else np.zeros(9)
            if np.all(np.abs(q[index] - final) < 0.01) and np.all(np.abs(velocity) < 0.02):
                return
            if time.monotonic() > deadline:
                raise RadError(f'the robot did not reach the end of the step within {duration:.1f} s x '
                               f'{self.param("step_timeout_factor")} + 10 s')
            time.sleep(0.05)


def main(args=None):
    raise SystemExit(run_node(AssemblyNode, args, executor_factory=lambda: MultiThreadedExecutor(num_threads=8)))

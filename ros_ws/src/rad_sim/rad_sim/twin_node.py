"""The digital twin as a plant node: it behaves like the real cell does.

Endpoints (relative names, so namespaces and remaps work); <arm_controller> and
<gripper_action> are parameters, named as on a franka_ros2 cell:
  act  <arm_controller>/follow_joint_trajectory  control_msgs/FollowJointTrajectory: the
       robot model's 7 arm joints only; a goal a Franka would refuse (joint names, points,
       the interpolated motion over its limits at 1 kHz, a jump from where the arm is) is
       aborted at once with the controller's error code and a reason; path and goal
       tolerances are honoured; cancel stops the arm where it is
  act  <gripper_action>                control_msgs/GripperCommand: position per finger (m),
       closing is a grasp with max_effort (N); the result reports where the fingers stopped
       (effector 'hand', the default)
  act  <vacuum_ns>/vacuum, <vacuum_ns>/dropoff, <vacuum_ns>/stop   franka_vacuum_gripper's Vacuum,
       DropOff and Stop, as franka_ros's franka_vacuum_gripper node serves libfranka's VacuumGripper
       (effector 'suction', in place of the hand): a vacuum seals on the flat top face under the cup
       or fails with the reason; each result says success and an error text
  sub  <arm_controller>/joint_trajectory  trajectory_msgs/JointTrajectory (the controller's
       topic interface, no feedback; checked the same way, a refusal only logged)
  pub  joint_states                    sensor_msgs/JointState (the model's arm and finger joints; the
                                       arm's only with the vacuum gripper), publish_rate_hz
  pub  <mocap_prefix>/<body>/pose      geometry_msgs/PoseStamped per block (sensor-data QoS); a
                                       dropped body is not published
  pub  rigid_bodies                    rad_msgs/RigidBodies, all bodies + frame number; a dropped
                                       body has tracking_valid false and its last reported pose
  pub  scene                           rad_msgs/Scene, latched: the scene last loaded
  pub  robot_description               std_msgs/String, latched: the URDF simulated (meshes as file://
                                       URIs), for RViz (robot 'panda'; publish_robot_description)
  pub  /tf                             tf2_msgs/TFMessage: frame_id -> block/<id>, each block's true pose
                                       (its anchor unit's centre), at 10 Hz
  pub  /tf_static                      tf2_msgs/TFMessage, latched: frame_id -> <prefix>_link0 (the robot's
                                       root link; publish_base_tf), so the robot, the blocks and motion
                                       capture make one tree from the base frame
  pub  ~/events                        std_msgs/String: accepted / rejected (with the reason) / done
  pub  /clock                          rosgraph_msgs/Clock: the simulated time from 0, each tick, where
                                       publish_clock is true; every stamp above is then simulated time,
                                       and the graph's nodes run with use_sim_time:=true
  srv  load_scene                      rad_msgs/LoadScene
  srv  reset                           std_srvs/Trigger: back to the scene last loaded
  srv  get_scene_state                 rad_msgs/GetSceneState: the scene as it is now
  srv  set_block_pose                  rad_msgs/SetBlockPose: move one block (a disturbance)
  srv  feeder/present                  rad_msgs/PresentBlock: the scene's feeder presents a block at its
                                       station (a block it presented and the robot did not take goes
                                       back); motion capture sees a feeder's blocks only when presented

Motion capture is published as a motion-capture system would: in `mocap_frame`
(stamped so; '' = frame_id, poses already in the robot base frame: the assembly node is then told
so with mocap_in_base_frame: true), the twin's
base-frame poses taken through the inverse of the calibration p_base = R(q) p_mocap + t
(`mocap_to_base_translation`, `mocap_to_base_quaternion` [x, y, z, w]).

The faults of a real cell (`rad_core.sim.faults`): `faults` is 'none', 'realistic'
or a JSON/YAML file of FaultConfig fields, `faults_seed` their seed (a file's own
seed wins). A dropped frame is a tick with no motion-capture publication (joint
states still go out); every injected slip, miss, nudge and placement error is
also published on ~/events ({'event': 'fault', ...}).

Physics runs all the time at real_time_factor x wall time (the simulated time /clock gives), in
the timer callback, so service calls and trajectories interleave with it on one thread; the
action goals are coroutines on that thread that wait for the twin to finish them.
"""

from __future__ import annotations

import json
import math
import re
import time

import numpy as np
from control_msgs.action import FollowJointTrajectory, GripperCommand
from franka_vacuum_gripper.action import DropOff, Stop, Vacuum
from geometry_msgs.msg import PoseStamped, TransformStamped
from rad_core.cell.mocap import RigidBodyPose
from rad_core.cell.motion import GripperCommand as GripperStep
from rad_core.cell.motion import GripperResult
from rad_core.cell.panda import FINGER_OPEN, urdf_path
from rad_core.cell.trajectory import TrajectoryRejected
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion
from rad_core.sim.faults import FaultConfig
from rad_core.sim.twin import BLOCK_PLAY, VACUUM_BUILD_UP_S, Tolerances, Twin, TwinConfig, twin_world_config
from rad_core.sim.workspace import Workspace
from rad_core.sim.world import World, WorldConfig
from rad_msgs.msg import RigidBodies
from rad_msgs.msg import Scene as SceneMsg
from rad_msgs.srv import GetSceneState, LoadScene, PresentBlock, SetBlockPose
from rad_ros.conversions import scene_from_request, scene_to_msg
from rad_ros.lifecycle import ManagedNode
from rad_ros.params import Param, declare, on_set
from rad_ros.motion import duration_to_s, pose_from_msg, pose_stamped, rigid_bodies_msg, trajectory_from_msg
from rad_ros.node_main import main_for
from rad_ros.qos import LATCHED
from builtin_interfaces.msg import Time
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.qos import qos_profile_sensor_data
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory


TF_RATE_HZ = 10.0
"""How often each block's transform goes out on /tf (at most the publish rate)."""


def robot_description(effector: str, prefix: str = 'panda') -> str:
    """The URDF the twin simulates, its meshes as file:// URIs (what RViz's robot model resolves), its
    links and joints named with `prefix` (the robot model's: 'fr3' names them fr3_link0, fr3_joint1, ...,
    as joint_states does)."""
    text = urdf_path(effector).read_text()
    if prefix != 'panda':
        text = re.sub(r'\b(name|link|joint)="panda_', rf'\1="{prefix}_', text)
    return re.sub(r'filename="(/[^"]+)"', r'filename="file://\1"', text)


def base_tf(frame_id: str, root_link: str, stamp) -> TFMessage:
    """/tf_static's frame_id -> the robot's root link: the twin's robot stands at frame_id's origin, so the
    robot's links (robot_state_publisher), the blocks and motion capture hang from one tree, as
    franka_description's base -> <arm_id>_link0 does on the cell."""
    t = TransformStamped(child_frame_id=root_link)
    t.header.frame_id, t.header.stamp = frame_id, stamp
    t.transform.rotation.w = 1.0
    return TFMessage(transforms=[t])


def block_tf(bodies, frame_id: str, stamp) -> TFMessage:
    """Each block's true pose as a transform frame_id -> block/<id> (anchor unit's centre)."""
    out = TFMessage()
    for b in bodies:
        t = TransformStamped(child_frame_id=f'block/{b.name}')
        t.header.frame_id, t.header.stamp = frame_id, stamp
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, b.position)
        (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
         t.transform.rotation.w) = map(float, b.quaternion)
        out.transforms.append(t)
    return out



# Read when the twin configures (read-only), but for real_time_factor, which applies at once.
PARAMS = [
    Param('scene_file', '', "the scene loaded at configure ('' = none: call load_scene)"),
    Param('publish_rate_hz', 50.0, 'how often joint states and motion capture go out', range=(1.0, 1000.0)),
    Param('real_time_factor', 1.0, 'simulated seconds per wall-clock second; applies at once', True, (0.01, 100.0)),
    Param('publish_robot_description', True, 'publish the URDF on robot_description (off where '
          'robot_state_publisher does)'),
    Param('publish_clock', False, 'publish /clock from the simulated time and stamp everything with it (run '
          'every node of the graph with use_sim_time:=true)'),
    Param('frame_id', 'world', "the robot's base frame"),
    Param('publish_base_tf', True, "publish frame_id -> the robot's root link (<prefix>_link0) on /tf_static: one "
          'TF tree for the robot, the blocks and motion capture'),
    Param('mocap_prefix', 'mocap', 'motion capture publishes <mocap_prefix>/<body>/pose'),
    Param('robot', 'panda', 'panda or fr3: joint names and limits'),
    Param('joint_prefix', '', "joint names' prefix ('' = the robot's)"),
    Param('arm_controller', 'joint_trajectory_controller', "the arm controller's name"),
    Param('gripper_action', 'franka_gripper/gripper_action', "the hand's GripperCommand action"),
    Param('effector', 'hand', 'hand, or suction (the vacuum gripper)'),
    Param('vacuum_ns', 'franka_vacuum_gripper', "the vacuum gripper's namespace"),
    Param('faults', 'none', "the cell's faults: none, realistic, or a JSON/YAML file of FaultConfig fields"),
    Param('faults_seed', 0, 'seed of the faults (a file\'s own seed wins)'),
    Param('block_play', BLOCK_PLAY, 'play per side face, as a fraction of a unit', range=(0.0, 0.2)),
    Param('mocap_frame', '', "motion capture's frame ('' = frame_id)"),
    Param('mocap_to_base_translation', [0.0, 0.0, 0.0], 'calibration: p_base = R p_mocap + t, t (m)', any_type=True),
    Param('mocap_to_base_quaternion', [0.0, 0.0, 0.0, 1.0], 'calibration: R as a quaternion [x, y, z, w]',
          any_type=True),
]

class TwinNode(ManagedNode):
    """The twin as a managed node: configure builds the world and its endpoints (and loads
    scene_file); active, physics runs and state is published; inactive, the world stands still,
    nothing is published, arm and gripper goals are rejected (as joint_trajectory_controller rejects
    them when it is not running) and the services still answer (a paused simulator can be set up)."""

    def __init__(self):
        super().__init__('twin')
        declare(self, PARAMS)
        on_set(self, self.apply)
        self.world = None
        self.arm_done: Future | None = None       # completed by the timer when the running trajectory ends
        self.gripper_done: Future | None = None
        self.wakers: list[Future] = []             # action coroutines waiting for the next tick

    def configure(self) -> None:
        self.frame_id = self.get_parameter('frame_id').value
        seed = self.get_parameter('faults_seed').value
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise RadError(f'faults_seed must be a non-negative integer, got {seed!r}')
        faults = FaultConfig.parse(str(self.get_parameter('faults').value), seed)
        self.mocap_frame = str(self.get_parameter('mocap_frame').value) or self.frame_id
        self.to_mocap = mocap_from_base(self.get_parameter('mocap_to_base_translation').value,
                                        self.get_parameter('mocap_to_base_quaternion').value)
        self.rtf = float(self.get_parameter('real_time_factor').value)
        rate = float(self.get_parameter('publish_rate_hz').value)
        if not (rate > 0 and self.rtf > 0):
            raise RadError('publish_rate_hz and real_time_factor must be positive')

        self.workspace = Workspace()
        effector = str(self.get_parameter('effector').value)
        self.world = World(config=twin_world_config(WorldConfig(effector=effector),
                                                    play=float(self.get_parameter('block_play').value)))
        self.twin = Twin(self.world, TwinConfig(robot=str(self.get_parameter('robot').value),
                                                joint_prefix=str(self.get_parameter('joint_prefix').value),
                                                faults=faults))
        self.faults_published = 0
        self.scene: Scene | None = None
        self.frame_number = 0
        self.pose_pubs: dict[str, object] = {}

        self.sim_time = 0.0                        # s of simulated time since the twin started
        self.clock_pub = (self.own(self.create_publisher(Clock, '/clock', 10))
                          if self.get_parameter('publish_clock').value else None)
        self.joint_pub = self.own(self.create_publisher(JointState, 'joint_states', 10))
        if self.get_parameter('publish_robot_description').value:
            self.description_pub = self.own(self.create_publisher(String, 'robot_description', LATCHED))
            self.description_pub.publish(String(data=robot_description(effector, self.twin.model.prefix)))
        self.tf_pub = self.own(self.create_publisher(TFMessage, '/tf', 10))
        root = f'{self.twin.model.prefix}_link0'
        if self.get_parameter('publish_base_tf').value and root != self.frame_id:
            self.tf_static_pub = self.own(self.create_publisher(TFMessage, '/tf_static', LATCHED))
            self.tf_static_pub.publish(base_tf(self.frame_id, root, self.get_clock().now().to_msg()))
        self.tf_every = max(1, round(rate / TF_RATE_HZ))
        self.bodies_pub = self.own(self.create_publisher(RigidBodies, 'rigid_bodies', qos_profile_sensor_data))
        self.scene_pub = self.own(self.create_publisher(SceneMsg, 'scene', LATCHED))
        self.events_pub = self.own(self.create_publisher(String, '~/events', 10))
        controller = str(self.get_parameter('arm_controller').value).rstrip('/')
        self.own(self.create_subscription(JointTrajectory, f'{controller}/joint_trajectory',
                                          self.trajectory_callback, 10))
        self.own(ActionServer(self, FollowJointTrajectory, f'{controller}/follow_joint_trajectory',
                              self.follow_joint_trajectory_callback, goal_callback=self.goal_callback,
                              cancel_callback=lambda goal: CancelResponse.ACCEPT))
        if effector == 'hand':
            self.own(ActionServer(self, GripperCommand, str(self.get_parameter('gripper_action').value),
                                  self.gripper_command_callback, goal_callback=self.goal_callback,
                                  cancel_callback=lambda goal: CancelResponse.ACCEPT))
        else:
            ns = str(self.get_parameter('vacuum_ns').value).rstrip('/')
            for kind, name, callback in ((Vacuum, 'vacuum', self.vacuum_callback),
                                         (DropOff, 'dropoff', self.dropoff_callback),
                                         (Stop, 'stop', self.stop_callback)):
                self.own(ActionServer(self, kind, f'{ns}/{name}', callback, goal_callback=self.goal_callback))
        for kind, name, callback in ((LoadScene, 'load_scene', self.load_scene_callback),
                                     (Trigger, 'reset', self.reset_callback),
                                     (GetSceneState, 'get_scene_state', self.get_scene_state_callback),
                                     (SetBlockPose, 'set_block_pose', self.set_block_pose_callback),
                                     (PresentBlock, 'feeder/present', self.present_block_callback)):
            self.own(self.create_service(kind, name, callback))

        path = self.get_parameter('scene_file').value
        if path:
            self.load(Scene.load(path))
        self.last_tick = time.monotonic()
        self.own(self.create_timer(1.0 / rate, self.tick_callback))
        self.get_logger().info(f'{faults.describe()}; motion capture in frame {self.mocap_frame!r}')
        self.get_logger().info('twin configured' + (f' with {path}' if path else ' (no scene loaded)'))

    def apply(self, changes: dict) -> None:
        """real_time_factor set while the twin runs: the simulation runs at the new rate from the next tick."""
        if 'real_time_factor' in changes:
            self.rtf = float(changes['real_time_factor'])
            self.get_logger().info(f'real_time_factor now {self.rtf:g}')

    def activate(self) -> None:
        self.last_tick = time.monotonic()     # the world stood still while inactive

    def deactivate(self) -> None:
        """Running goals end: the arm stops where it is, the hand where it is."""
        if self.arm_done is not None and not self.arm_done.done():
            self.twin.cancel()
        stopped = self.twin.cancel_gripper() if self.gripper_done is not None and not self.gripper_done.done() else None
        self.end_goals('the controller was deactivated: the arm stopped where it was', stopped)

    def end_goals(self, why: str, gripper: GripperResult | None = None) -> None:
        """The arm and gripper goals still running end: the arm's aborted with `why`, the hand's with
        `gripper` (default: where the fingers are)."""
        if self.arm_done is not None and not self.arm_done.done():
            self.arm_done.set_result({'error_code': FollowJointTrajectory.Result.INVALID_GOAL, 'error_string': why})
        if self.gripper_done is not None and not self.gripper_done.done():
            self.gripper_done.set_result(gripper or GripperResult(self.finger_position()))

    def finger_position(self) -> float:
        """Where the fingers are now, per finger (m)."""
        return float(self.world.joint_positions()[7:].mean())

    def cleanup(self) -> None:
        self.wake_all()
        super().cleanup()
        self.pose_pubs.clear()
        self.world = self.twin = self.scene = None

    def goal_callback(self, goal) -> GoalResponse:
        if self.is_active:
            return GoalResponse.ACCEPT
        self.get_logger().error(f'goal rejected: {self.inactive_reason()}')
        return GoalResponse.REJECT

    # ---- world ------------------------------------------------------------
    def load(self, scene: Scene) -> None:
        self.workspace.check_scene(scene)
        self.twin.load_scene(scene)
        self.end_goals('the scene was reloaded while the arm moved')   # the robot was put back home
        self.scene = scene
        for block in scene.blocks:
            if block.id not in self.pose_pubs:
                topic = f'{self.get_parameter("mocap_prefix").value}/{block.id}/pose'
                self.pose_pubs[block.id] = self.own(self.create_publisher(PoseStamped, topic, qos_profile_sensor_data))
        self.scene_pub.publish(scene_to_msg(scene, self.frame_id))

    def event(self, kind: str, **fields) -> None:
        self.events_pub.publish(String(data=json.dumps({'event': kind, **fields})))

    def tick_callback(self) -> None:
        if not self.is_active:
            self.wake_all()                    # goals ended by deactivate finish
            return
        now = time.monotonic()
        # Never try to catch up more than a quarter second of lag in one tick.
        dt = min(now - self.last_tick, 0.25) * self.rtf
        self.last_tick = now
        self.sim_time += dt
        gripping = self.gripper_done is not None and self.twin.gripper_result is None
        finished = self.twin.advance(dt)
        if finished is not None:
            self.event('done', **finished)
            if self.arm_done is not None and not self.arm_done.done():
                self.arm_done.set_result(finished)
        if gripping and self.twin.gripper_result is not None and not self.gripper_done.done():
            self.gripper_done.set_result(self.twin.gripper_result)
        self.publish_state()
        self.wake_all()

    def wake_all(self) -> None:
        wakers, self.wakers = self.wakers, []
        for wake in wakers:
            wake.set_result(None)

    def stamp(self):
        """Now: the simulated time where the twin publishes /clock, else the node's clock."""
        if self.clock_pub is None:
            return self.get_clock().now().to_msg()
        ns = int(round(self.sim_time * 1e9))
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def publish_state(self) -> None:
        stamp = self.stamp()
        if self.clock_pub is not None:
            self.clock_pub.publish(Clock(clock=stamp))
        names, positions, velocities = self.twin.joint_state()
        msg = JointState(name=list(names), position=[float(v) for v in positions],
                         velocity=[float(v) for v in velocities])
        msg.header.stamp = stamp
        self.joint_pub.publish(msg)
        faults = self.twin.fault_events
        for event in faults[self.faults_published:]:
            self.event('fault', **event)
        self.faults_published = len(faults)
        if self.scene is None:
            return
        self.frame_number += 1
        if self.twin.drop_frame():
            return
        if self.frame_number % self.tf_every == 0:
            self.tf_pub.publish(block_tf(self.twin.bodies(exact=True), self.frame_id, stamp))
        bodies = [self.to_mocap(b) for b in self.twin.bodies()]
        self.bodies_pub.publish(rigid_bodies_msg(bodies, self.frame_number, stamp, self.mocap_frame))
        for body in bodies:
            pub = self.pose_pubs.get(body.name)
            if pub is not None and body.tracking_valid:
                pub.publish(pose_stamped(body, stamp, self.mocap_frame))

    # ---- callbacks ----------------------------------------------------------
    def trajectory_callback(self, msg: JointTrajectory) -> None:
        if not self.is_active:
            self.get_logger().error(f'trajectory rejected: {self.inactive_reason()}')
            self.event('rejected', reason=self.inactive_reason())
            return
        try:
            info = self.twin.start(trajectory_from_msg(msg))
        except (RadError, ValueError) as e:
            self.get_logger().error(f'trajectory rejected: {e}')
            self.event('rejected', reason=str(e))
            return
        self.event('accepted', **info)

    async def follow_joint_trajectory_callback(self, goal_handle):
        """A FollowJointTrajectory goal: checked as Franka's controller checks it, run, answered."""
        goal = goal_handle.request
        result = FollowJointTrajectory.Result()
        tolerances = Tolerances(path=_tolerance(goal.path_tolerance), goal=_tolerance(goal.goal_tolerance),
                                goal_time=duration_to_s(goal.goal_time_tolerance))
        if self.arm_done is not None and not self.arm_done.done():
            self.arm_done.set_result({'error_code': FollowJointTrajectory.Result.INVALID_GOAL, 'preempted': True,
                                      'error_string': 'preempted by a new goal'})
        try:
            info = self.twin.start(trajectory_from_msg(goal.trajectory), tolerances)
        except TrajectoryRejected as e:
            self.get_logger().error(f'goal refused: {e}')
            self.event('rejected', reason=str(e), error_code=e.code)
            result.error_code, result.error_string = e.code, str(e)
            goal_handle.abort()
            return result
        except RadError as e:
            result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_GOAL, str(e)
            goal_handle.abort()
            return result
        self.event('accepted', **info)
        done = self.arm_done = Future()
        while not done.done():
            if goal_handle.is_cancel_requested:
                self.twin.cancel()
                goal_handle.canceled()
                result.error_string = 'cancelled: the arm stopped where it was'
                return result
            await _tick(self)
        report = done.result()
        result.error_code = int(report.get('error_code', 0))
        result.error_string = report.get('error_string', '')
        if result.error_code == FollowJointTrajectory.Result.SUCCESSFUL:
            result.error_string = result.error_string or 'goal reached'
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    async def gripper_command_callback(self, goal_handle):
        """A GripperCommand goal: per-finger position, grasp force; the result says where the fingers stopped."""
        command = goal_handle.request.command
        result = GripperCommand.Result()
        try:
            self.twin.grip(float(command.position), float(command.max_effort))
        except RadError as e:
            self.get_logger().error(f'gripper goal refused: {e}')
            result.position = self.finger_position()
            goal_handle.abort()
            return result
        self.twin.gripper_result = None
        done = self.gripper_done = Future()
        while not done.done():
            if goal_handle.is_cancel_requested:
                stopped = self.twin.cancel_gripper()
                result.position = stopped.position if stopped else self.finger_position()
                goal_handle.canceled()
                return result
            await _tick(self)
        r = done.result()
        result.position, result.effort, result.stalled, result.reached_goal = (
            float(r.position), float(r.effort), bool(r.stalled), bool(r.reached_goal))
        (goal_handle.succeed if r.reached_goal else goal_handle.abort)()
        return result

    async def vacuum_callback(self, goal_handle):
        """A Vacuum goal (level in 10 mbar, timeout in ms): success once the cup seals and the level is
        reached, else aborted with the reason in `error`."""
        goal = goal_handle.request
        return await self._vacuum_goal(goal_handle, Vacuum.Result(), GripperStep(
            'vacuum', FINGER_OPEN, 0.0, 0, vacuum=int(goal.vacuum), timeout_ms=int(goal.timeout)))

    async def dropoff_callback(self, goal_handle):
        """A DropOff goal (timeout in ms): the vacuum released, the held block let go."""
        return await self._vacuum_goal(goal_handle, DropOff.Result(), GripperStep(
            'drop_off', FINGER_OPEN, 0.0, 0, timeout_ms=int(goal_handle.request.timeout)))

    async def stop_callback(self, goal_handle):
        """A Stop goal: the pump stops; the twin lets the held block go at once (a real cup holds it a
        while longer, until the vacuum leaks away)."""
        return await self._vacuum_goal(goal_handle, Stop.Result(), GripperStep(
            'drop_off', FINGER_OPEN, 0.0, 0, timeout_ms=1))

    async def _vacuum_goal(self, goal_handle, result, command):
        end = self.twin.time + min(command.timeout_ms / 1000.0, VACUUM_BUILD_UP_S)
        while self.twin.time < end - 1e-9:
            await _tick(self)
            if not self.is_active:
                result.success = False
                result.error = f'the vacuum gripper was deactivated before {command.action} ended'
                goal_handle.abort()
                return result
        try:
            got = self.twin.vacuum_now(command)
        except RadError as e:
            got = GripperResult(FINGER_OPEN, reached_goal=False, error=str(e))
        result.success, result.error = bool(got.reached_goal), got.error
        if not got.reached_goal:
            self.get_logger().error(f'{command.action} failed: {got.error}')
        self.event(command.action, success=result.success, error=result.error)
        (goal_handle.succeed if got.reached_goal else goal_handle.abort)()
        return result

    def load_scene_callback(self, request, response):
        try:
            self.load(scene_from_request(request.scene, request.scene_json))
        except RadError as e:
            response.success, response.reason = False, str(e)
            return response
        response.success = True
        return response

    def reset_callback(self, request, response):
        if self.scene is None:
            response.success, response.message = False, 'no scene loaded: call load_scene first'
            return response
        self.load(self.scene)
        response.success, response.message = True, 'reset to the scene last loaded'
        return response

    def get_scene_state_callback(self, request, response):
        if self.scene is None:
            response.success, response.reason = False, 'no scene loaded: call load_scene first'
            return response
        try:
            current = self.twin.current_scene(self.scene)
        except RadError as e:
            response.success, response.reason = False, f'the world is not a valid scene now: {e}'
            return response
        response.success = True
        response.scene = scene_to_msg(current, self.frame_id)
        response.scene_json = current.dumps()
        return response


    def present_block_callback(self, request, response):
        response.success = False
        if self.scene is None:
            response.reason = 'no scene loaded: call load_scene first'
            return response
        try:
            self.twin.present(request.block_id)
        except RadError as e:
            response.reason = str(e)
            return response
        response.success = True
        return response

    def set_block_pose_callback(self, request, response):
        response.success = False
        if self.scene is None:
            response.reason = 'no scene loaded: call load_scene first'
            return response
        if request.block_id not in self.world.blocks:
            response.reason = f'unknown block id {request.block_id!r} (known: {", ".join(sorted(self.world.blocks))})'
            return response
        position, quaternion = pose_from_msg(request.pose)
        norm = sum(q * q for q in quaternion) ** 0.5
        if not abs(norm - 1.0) < 1e-3:
            response.reason = f'orientation is not a unit quaternion (norm {norm:.4g})'
            return response
        try:
            self.workspace.check_points(position, f'block {request.block_id!r}')
        except RadError as e:
            response.reason = str(e)
            return response
        if request.block_id in self.world.parked:
            self.world.unpark(request.block_id)       # taken out of the feeder by hand
        self.world.set_block_pose(request.block_id, position, quaternion)
        response.success = True
        return response


def mocap_from_base(translation, quaternion):
    """The map of a base-frame body to what motion capture reports in its own frame, given the calibration
    p_base = R(q) p_mocap + t; RadError naming the parameter when it is malformed."""
    t = np.asarray(list(translation), dtype=float) if _numbers(translation) else None
    q = np.asarray(list(quaternion), dtype=float) if _numbers(quaternion) else None
    if t is None or t.shape != (3,) or not np.all(np.isfinite(t)):
        raise RadError(f'mocap_to_base_translation must be 3 finite numbers (m), got {list(translation)!r}')
    if q is None or q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise RadError(f'mocap_to_base_quaternion must be a unit quaternion [x, y, z, w], got {list(quaternion)!r}')
    q = q / np.linalg.norm(q)
    if np.allclose(t, 0.0) and np.allclose(q, [0, 0, 0, 1]):
        return lambda body: body
    r = matrix_from_quaternion(q)
    q_inv = np.array([-q[0], -q[1], -q[2], q[3]])

    def to_mocap(body: RigidBodyPose) -> RigidBodyPose:
        p = r.T @ (np.asarray(body.position) - t)
        return RigidBodyPose(body.name, tuple(float(v) for v in p),
                             tuple(float(v) for v in _quat_mul(q_inv, np.asarray(body.quaternion))),
                             body.tracking_valid)
    return to_mocap


def _numbers(values) -> bool:
    try:
        return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)
    except TypeError:
        return False


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of [x, y, z, w] quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def _tolerance(tolerances) -> float:
    """One position tolerance for all joints from a goal's JointTolerance list: the tightest
    positive one (0 or -1 leave the twin's default, as in joint_trajectory_controller)."""
    values = [float(t.position) for t in tolerances if t.position > 0]
    return min(values) if values else 0.0


async def _tick(node: TwinNode) -> None:
    """Wait, without blocking the node's one thread, until the next timer tick."""
    wake = Future()
    node.wakers.append(wake)
    await wake


main = main_for(TwinNode)

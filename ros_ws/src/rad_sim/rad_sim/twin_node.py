"""The digital twin as a plant node: it behaves like the real cell does.

Endpoints (relative names, so namespaces and remaps work):
  sub  joint_trajectory_controller/joint_trajectory  trajectory_msgs/JointTrajectory
       (the ros2_control joint_trajectory_controller's topic; a new one replaces the
       one executing, as that controller does)
  pub  joint_states                    sensor_msgs/JointState, publish_rate_hz
  pub  <mocap_prefix>/<body>/pose      geometry_msgs/PoseStamped per block (sensor-data QoS)
  pub  rigid_bodies                    rad_msgs/RigidBodies, all bodies + frame number
  pub  scene                           rad_msgs/Scene, latched: the scene last loaded
  pub  ~/events                        std_msgs/String: accepted / rejected (with the reason) / done
  srv  load_scene                      rad_msgs/LoadScene
  srv  reset                           std_srvs/Trigger: back to the scene last loaded
  srv  get_scene_state                 rad_msgs/GetSceneState: the scene as it is now
  srv  set_block_pose                  rad_msgs/SetBlockPose: move one block (a disturbance)

Physics runs all the time at real_time_factor x wall time, in the timer callback,
so service calls and trajectories interleave with it on one thread.
"""

from __future__ import annotations

import json
import time

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from rad_core.errors import RadError
from rad_core.scene import Scene
from rad_core.sim.twin import Twin, TwinConfig
from rad_core.sim.workspace import Workspace
from rad_core.sim.world import World
from rad_msgs.msg import RigidBodies, Scene as SceneMsg
from rad_msgs.srv import GetSceneState, LoadScene, SetBlockPose
from rad_ros.conversions import scene_from_request, scene_to_msg
from rad_ros.motion import pose_from_msg, pose_stamped, rigid_bodies_msg, trajectory_from_msg
from rad_ros.node_main import main_for
from rad_ros.qos import LATCHED


class TwinNode(Node):
    def __init__(self):
        super().__init__('twin')
        self.declare_parameter('scene_file', '')
        self.declare_parameter('publish_rate_hz', 50.0)
        self.declare_parameter('real_time_factor', 1.0)
        self.declare_parameter('frame_id', 'world')
        self.declare_parameter('mocap_prefix', 'mocap')
        self.frame_id = self.get_parameter('frame_id').value
        self.rtf = float(self.get_parameter('real_time_factor').value)
        rate = float(self.get_parameter('publish_rate_hz').value)
        if not (rate > 0 and self.rtf > 0):
            raise RadError('publish_rate_hz and real_time_factor must be positive')

        self.workspace = Workspace()
        self.world = World()
        self.twin = Twin(self.world, TwinConfig())
        self.scene: Scene | None = None
        self.frame_number = 0
        self.pose_pubs: dict[str, object] = {}

        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        self.bodies_pub = self.create_publisher(RigidBodies, 'rigid_bodies', qos_profile_sensor_data)
        self.scene_pub = self.create_publisher(SceneMsg, 'scene', LATCHED)
        self.events_pub = self.create_publisher(String, '~/events', 10)
        self.create_subscription(JointTrajectory, 'joint_trajectory_controller/joint_trajectory',
                                 self.trajectory_callback, 10)
        self.create_service(LoadScene, 'load_scene', self.load_scene_callback)
        self.create_service(Trigger, 'reset', self.reset_callback)
        self.create_service(GetSceneState, 'get_scene_state', self.get_scene_state_callback)
        self.create_service(SetBlockPose, 'set_block_pose', self.set_block_pose_callback)

        path = self.get_parameter('scene_file').value
        if path:
            self.load(Scene.load(path))
        self.last_tick = time.monotonic()
        self.create_timer(1.0 / rate, self.tick_callback)
        self.get_logger().info('twin ready' + (f' with {path}' if path else ' (no scene loaded)'))

    # ---- world ------------------------------------------------------------
    def load(self, scene: Scene) -> None:
        self.workspace.check_scene(scene)
        self.twin.load_scene(scene)
        self.scene = scene
        for block in scene.blocks:
            if block.id not in self.pose_pubs:
                topic = f'{self.get_parameter("mocap_prefix").value}/{block.id}/pose'
                self.pose_pubs[block.id] = self.create_publisher(PoseStamped, topic, qos_profile_sensor_data)
        self.scene_pub.publish(scene_to_msg(scene, self.frame_id))

    def event(self, kind: str, **fields) -> None:
        self.events_pub.publish(String(data=json.dumps({'event': kind, **fields})))

    def tick_callback(self) -> None:
        now = time.monotonic()
        # Never try to catch up more than a quarter second of lag in one tick.
        dt = min(now - self.last_tick, 0.25) * self.rtf
        self.last_tick = now
        finished = self.twin.advance(dt)
        if finished is not None:
            self.event('done', **finished)
        self.publish_state()

    def publish_state(self) -> None:
        stamp = self.get_clock().now().to_msg()
        names, positions, velocities = self.twin.joint_state()
        msg = JointState(name=list(names), position=[float(v) for v in positions],
                         velocity=[float(v) for v in velocities])
        msg.header.stamp = stamp
        self.joint_pub.publish(msg)
        if self.scene is None:
            return
        bodies = self.twin.bodies()
        self.frame_number += 1
        self.bodies_pub.publish(rigid_bodies_msg(bodies, self.frame_number, stamp, self.frame_id))
        for body in bodies:
            pub = self.pose_pubs.get(body.name)
            if pub is not None:
                pub.publish(pose_stamped(body, stamp, self.frame_id))

    # ---- callbacks ----------------------------------------------------------
    def trajectory_callback(self, msg: JointTrajectory) -> None:
        try:
            info = self.twin.start(trajectory_from_msg(msg))
        except (RadError, ValueError) as e:
            self.get_logger().error(f'trajectory rejected: {e}')
            self.event('rejected', reason=str(e))
            return
        self.event('accepted', **info)

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
        self.world.set_block_pose(request.block_id, position, quaternion)
        response.success = True
        return response


main = main_for(TwinNode)

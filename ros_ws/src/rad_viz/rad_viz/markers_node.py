"""RViz's view of rad: the scene, the blocks as motion capture sees them and the plan as markers.

Endpoints (relative names, so namespaces and remaps work):
  sub  scene          rad_msgs/Scene, latched: target cells and blocks
  sub  rigid_bodies   rad_msgs/RigidBodies, sensor-data QoS: where each block is (bodies named by
                      block id, in frame_id; others are left where the scene has them)
  sub  plan_json      std_msgs/String, latched: the allocation's poses and the next step
  pub  markers        visualization_msgs/MarkerArray, latched (`rad_ros.markers`): on every scene and
                      plan, and as blocks move, at most rate_hz

Parameters: frame_id (the robot's base frame, 'world' as the twin's), rate_hz (2.0). In RViz, add a
MarkerArray display on /markers (rad_viz/config/rad.rviz has it, with the robot model).
"""

from __future__ import annotations

from rad_core.domain.errors import RadError
from rad_core.view import viz
from rad_msgs.msg import RigidBodies
from rad_msgs.msg import Scene as SceneMsg
from rad_ros.conversions import scene_from_msg
from rad_ros.markers import scene_markers
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare
from rad_ros.qos import LATCHED
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

PARAMS = [Param('frame_id', 'world', "the frame markers are drawn in: the robot's base frame"),
          Param('rate_hz', 2.0, 'how often moving blocks redraw, at most', range=(0.1, 30.0))]


class MarkersNode(Node):
    def __init__(self):
        super().__init__('markers')
        declare(self, PARAMS)
        self.frame_id = str(self.get_parameter('frame_id').value)
        self.scene, self.plan, self.poses, self.dirty = None, None, {}, False
        self.pub = self.create_publisher(MarkerArray, 'markers', LATCHED)
        self.create_subscription(SceneMsg, 'scene', self.scene_callback, LATCHED)
        self.create_subscription(String, 'plan_json', self.plan_callback, LATCHED)
        self.create_subscription(RigidBodies, 'rigid_bodies', self.bodies_callback, qos_profile_sensor_data)
        self.create_timer(1.0 / float(self.get_parameter('rate_hz').value), self.tick)
        self.get_logger().info(f'markers ready, in frame {self.frame_id!r}')

    def scene_callback(self, msg: SceneMsg) -> None:
        try:
            self.scene = scene_from_msg(msg)
        except RadError as e:
            self.get_logger().error(f'scene not drawn: {e}')
            return
        self.poses = {}
        self.publish()

    def plan_callback(self, msg: String) -> None:
        try:
            self.plan = viz.parse_plan(msg.data)
        except RadError as e:
            self.get_logger().error(f'plan not drawn: {e}')
            return
        self.publish()

    def bodies_callback(self, msg: RigidBodies) -> None:
        if msg.header.frame_id and msg.header.frame_id != self.frame_id:
            return                        # in a motion-capture frame of its own: the scene's poses stand
        for b in msg.rigidbodies:
            if b.tracking_valid:
                p, q = b.pose.position, b.pose.orientation
                pose = ((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
                if self.poses.get(b.rigid_body_name) != pose:
                    self.poses[b.rigid_body_name], self.dirty = pose, True

    def tick(self) -> None:
        if self.dirty:
            self.publish()

    def publish(self) -> None:
        self.dirty = False
        if self.scene is None:
            return
        known = {b.id for b in self.scene.blocks}
        poses = {k: v for k, v in self.poses.items() if k in known}
        try:
            markers = scene_markers(self.scene, self.frame_id, self.get_clock().now().to_msg(), poses, self.plan)
        except RadError as e:             # a plan of another scene's regions
            self.get_logger().warning(f'plan not drawn: {e}')
            markers = scene_markers(self.scene, self.frame_id, self.get_clock().now().to_msg(), poses)
        self.pub.publish(markers)


main = main_for(MarkersNode)

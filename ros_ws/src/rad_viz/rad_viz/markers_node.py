"""RViz's view of rad: the scene, the blocks as motion capture sees them and the plan as markers.

Endpoints (relative names, so namespaces and remaps work):
  sub  scene          rad_msgs/Scene, latched: target cells and blocks
  sub  rigid_bodies   rad_msgs/RigidBodies, sensor-data QoS: where each block is (bodies named by
                      block id, in frame_id; others are left where the scene has them)
  sub  plan_json      std_msgs/String, latched: the allocation's poses and the next step
  pub  markers        visualization_msgs/MarkerArray, latched (`rad_ros.markers`): on every scene and
                      plan, and as blocks move, at most rate_hz
  pub  collision_object_topic (parameter, '/collision_object': where MoveIt 2's move_group listens)
                      moveit_msgs/CollisionObject, reliable, volatile, only with collision_objects on:
                      one object per block, id 'rad/block/<block id>' (`rad_ros.collision_objects`),
                      ADD when it appears, changes or moves (by more than 1 mm or 1 mrad, at most
                      rate_hz), REMOVE when its block leaves the scene; every object again whenever a
                      new subscriber (a restarted move_group) matches

Parameters: frame_id (the robot's base frame, 'world' as the twin's), rate_hz (2.0), collision_objects
(false), collision_object_topic. In RViz, add a MarkerArray display on /markers (rad_viz/config/rad.rviz
has it, with the robot model).

move_group's subscription keeps the last 10 messages (rclcpp::ServicesQoS in Jazzy's
planning_scene_monitor), so a burst larger than that could overwrite objects it has not read yet:
the objects go out from a queue, at most COLLISION_BURST every COLLISION_PERIOD_S, the latest
object of each id replacing one still waiting.
"""

from __future__ import annotations

from collections import OrderedDict

from moveit_msgs.msg import CollisionObject
from rad_core.domain.errors import RadError
from rad_core.view import viz
from rad_msgs.msg import RigidBodies
from rad_msgs.msg import Scene as SceneMsg
from rad_ros.collision_objects import block_objects, changes
from rad_ros.conversions import scene_from_msg
from rad_ros.markers import scene_markers
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare
from rad_ros.qos import LATCHED
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

PARAMS = [Param('frame_id', 'world', "the frame markers are drawn in: the robot's base frame"),
          Param('rate_hz', 2.0, 'how often moving blocks redraw, at most', range=(0.1, 30.0)),
          Param('collision_objects', False, "publish the blocks as MoveIt 2 collision objects "
                "(moveit_msgs/CollisionObject, ids 'rad/block/<block id>') on collision_object_topic"),
          Param('collision_object_topic', '/collision_object',
                "where collision objects go: move_group's planning scene monitor listens on /collision_object")]

COLLISION_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)
"""Reliable and volatile as move_group's subscription (rclcpp::ServicesQoS); deep enough to hold what
is resent to it while it acknowledges."""
COLLISION_BURST = 5
"""Collision objects published at most per COLLISION_PERIOD_S: half of move_group's subscription depth."""
COLLISION_PERIOD_S = 0.02
"""How often queued collision objects go out (s): with COLLISION_BURST, at most 250 objects a second."""


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
        self.co_pub, self.co_sent, self.co_queue, self.co_subscribers = None, {}, OrderedDict(), 0
        also = ''
        if self.get_parameter('collision_objects').value:
            topic = str(self.get_parameter('collision_object_topic').value)
            self.co_pub = self.create_publisher(CollisionObject, topic, COLLISION_QOS)
            self.create_timer(COLLISION_PERIOD_S, self.send_collision_objects)
            also = f'; collision objects on {self.co_pub.topic_name}'
        self.get_logger().info(f'markers ready, in frame {self.frame_id!r}{also}')

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
        if self.co_pub is not None:
            self.queue_collision_objects(block_objects(self.scene, self.frame_id, poses))

    def queue_collision_objects(self, current: dict) -> None:
        """Queue what MoveIt needs to go from the objects sent so far to `current` (id -> object)."""
        for obj in changes(self.co_sent, current, self.frame_id):
            self.co_queue.pop(obj.id, None)
            self.co_queue[obj.id] = obj
            if obj.operation == CollisionObject.REMOVE:
                self.co_sent.pop(obj.id, None)
            else:
                self.co_sent[obj.id] = obj

    def send_collision_objects(self) -> None:
        """Publish up to COLLISION_BURST queued objects; queue all again when a new subscriber matched."""
        count = self.co_pub.get_subscription_count()
        if count > self.co_subscribers:
            for oid, obj in self.co_sent.items():
                self.co_queue.pop(oid, None)
                self.co_queue[oid] = obj
        self.co_subscribers = count
        stamp = self.get_clock().now().to_msg()
        for _ in range(min(COLLISION_BURST, len(self.co_queue))):
            _, obj = self.co_queue.popitem(last=False)
            obj.header.stamp = stamp
            self.co_pub.publish(obj)


main = main_for(MarkersNode)

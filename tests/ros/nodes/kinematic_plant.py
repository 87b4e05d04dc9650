#!/usr/bin/env python3
"""A different plant for the planners: kinematic, no physics, not the twin.

It speaks the same contract a real cell does (JointTrajectory in on
joint_trajectory_controller/joint_trajectory; joint_states, rigid_bodies and the
latched scene out) but is built differently: joints jump along the trajectory
by linear interpolation in wall time, and a block is carried rigidly while the
fingers are closed around it (its unit within 1 cm of the grasp point). Used to
prove the planners never depend on the twin's internals.

    kinematic_plant.py --ros-args -p scene_file:=FILE -p speed:=5.0
"""

import sys
import time

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from rad_core.scene import Scene
from rad_core.sim import panda
from rad_core.sim.mocap import RigidBodyPose
from rad_core.sim.world import World
from rad_core.transforms import matrix_from_quaternion, quaternion_from_matrix
from rad_msgs.msg import RigidBodies
from rad_ros.conversions import scene_to_msg
from rad_ros.motion import rigid_bodies_msg, trajectory_from_msg
from rad_ros.node_main import run_node


class KinematicPlant(Node):
    def __init__(self):
        super().__init__('kinematic_plant')
        self.declare_parameter('scene_file', '')
        self.declare_parameter('speed', 1.0)
        self.scene = Scene.load(self.get_parameter('scene_file').value)
        self.speed = float(self.get_parameter('speed').value)
        self.world = World(self.scene)   # used as a kinematic model only: never stepped
        self.q = np.array(panda.HOME, dtype=float)
        self.world.set_joint_positions(self.q)
        self.trajectory, self.t0, self.held = None, 0.0, None
        self.frame = 0
        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        self.bodies_pub = self.create_publisher(RigidBodies, 'rigid_bodies', qos_profile_sensor_data)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_publisher(type(scene_to_msg(self.scene)), 'scene', latched).publish(scene_to_msg(self.scene))
        self.create_subscription(JointTrajectory, 'joint_trajectory_controller/joint_trajectory',
                                 self.trajectory_callback, 10)
        self.create_timer(0.02, self.tick)

    def trajectory_callback(self, msg):
        doc = trajectory_from_msg(msg)
        index = [doc['joint_names'].index(n) for n in panda.JOINT_NAMES]
        times = np.array([0.0] + [p['time_from_start'] for p in doc['points']])
        points = np.array([self.q] + [np.asarray(p['positions'])[index] for p in doc['points']])
        self.trajectory, self.t0 = (times, points), time.monotonic()

    def tick(self):
        if self.trajectory is not None:
            times, points = self.trajectory
            t = (time.monotonic() - self.t0) * self.speed
            self.q = np.array([np.interp(t, times, points[:, j]) for j in range(9)])
            if t >= times[-1]:
                self.trajectory = None
            self.world.set_joint_positions(self.q)
            self.carry()
        self.publish()

    def carry(self):
        hand_p, hand_q = self.world.link_pose()
        hand = np.eye(4)
        hand[:3, :3], hand[:3, 3] = matrix_from_quaternion(hand_q), hand_p
        closed = self.q[7] < self.scene.unit / 2 + 0.002
        if self.held is None and closed:
            for block in self.scene.blocks:
                p, q = self.world.block_pose(block.id)
                units = p + (matrix_from_quaternion(q) @ (self.scene.block_types[block.type].rotated(0).T
                                                          * self.scene.unit)).T
                if np.min(np.linalg.norm(units - hand_p, axis=1)) < 0.01:
                    pose = np.eye(4)
                    pose[:3, :3], pose[:3, 3] = matrix_from_quaternion(q), p
                    self.held = (block.id, np.linalg.inv(hand) @ pose)
                    break
        elif self.held is not None and not closed:
            self.held = None
        if self.held is not None:
            pose = hand @ self.held[1]
            self.world.set_block_pose(self.held[0], pose[:3, 3], quaternion_from_matrix(pose[:3, :3]))

    def publish(self):
        stamp = self.get_clock().now().to_msg()
        self.joint_pub.publish(JointState(name=list(panda.JOINT_NAMES), position=[float(v) for v in self.q],
                                          velocity=[0.0] * 9, header=self._header(stamp)))
        bodies = [RigidBodyPose(b.id, *self.world.block_pose(b.id)) for b in self.scene.blocks]
        self.frame += 1
        self.bodies_pub.publish(rigid_bodies_msg(bodies, self.frame, stamp, 'world'))

    @staticmethod
    def _header(stamp):
        from std_msgs.msg import Header
        return Header(stamp=stamp, frame_id='world')


def main():
    return run_node(KinematicPlant)


if __name__ == '__main__':
    sys.exit(main())

#!/usr/bin/env python3
"""A different plant for the planners: kinematic, no physics, not the twin.

It speaks the same contract a real cell does (the arm controller's
control_msgs/FollowJointTrajectory action on
joint_trajectory_controller/follow_joint_trajectory, the hand's
control_msgs/GripperCommand action on franka_gripper/gripper_action;
joint_states, rigid_bodies and the latched scene out) but is built differently:
joints move along the trajectory's points by linear interpolation in wall time,
a goal naming other joints than the Panda's 7 arm joints is aborted with
INVALID_JOINTS, the fingers close until they meet a unit of a block between them
(else they close fully and the grasp fails), and a block is carried rigidly while
the fingers hold it. Used to prove the planners never depend on the twin's internals.

    kinematic_plant.py --ros-args -p scene_file:=FILE -p speed:=5.0
"""

import sys
import threading
import time

import numpy as np
from control_msgs.action import FollowJointTrajectory, GripperCommand
from rad_core.cell import panda
from rad_core.cell.mocap import RigidBodyPose
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, quaternion_from_matrix
from rad_core.sim.world import World
from rad_msgs.msg import RigidBodies
from rad_ros.conversions import scene_to_msg
from rad_ros.motion import rigid_bodies_msg, trajectory_from_msg
from rad_ros.node_main import run_node
from rclpy.action import ActionServer
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import JointState


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
        self.held = None
        self.lock = threading.Lock()
        self.frame = 0
        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        self.bodies_pub = self.create_publisher(RigidBodies, 'rigid_bodies', qos_profile_sensor_data)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_publisher(type(scene_to_msg(self.scene)), 'scene', latched).publish(scene_to_msg(self.scene))
        group = ReentrantCallbackGroup()
        ActionServer(self, FollowJointTrajectory, 'joint_trajectory_controller/follow_joint_trajectory',
                     self.arm_callback, callback_group=group)
        ActionServer(self, GripperCommand, 'franka_gripper/gripper_action', self.gripper_callback,
                     callback_group=group)
        self.create_timer(0.02, self.publish, callback_group=group)

    def arm_callback(self, goal_handle):
        doc = trajectory_from_msg(goal_handle.request.trajectory)
        result = FollowJointTrajectory.Result()
        if sorted(doc['joint_names']) != sorted(panda.ARM_JOINT_NAMES):
            result.error_code = FollowJointTrajectory.Result.INVALID_JOINTS
            result.error_string = f'joints {doc["joint_names"]} are not the arm controller\'s'
            goal_handle.abort()
            return result
        index = [doc['joint_names'].index(n) for n in panda.ARM_JOINT_NAMES]
        with self.lock:
            start = self.q[:7].copy()
        times = np.array([0.0] + [p['time_from_start'] for p in doc['points']])
        points = np.array([start] + [np.asarray(p['positions'])[index] for p in doc['points']])
        t0 = time.monotonic()
        while True:
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return result
            t = (time.monotonic() - t0) * self.speed
            with self.lock:
                self.q[:7] = [np.interp(t, times, points[:, j]) for j in range(7)]
                self.world.set_joint_positions(self.q)
                self.carry()
            if t >= times[-1]:
                break
            time.sleep(0.01)
        goal_handle.succeed()
        return result

    def gripper_callback(self, goal_handle):
        goal = float(goal_handle.request.command.position)
        result = GripperCommand.Result()
        with self.lock:
            closing = goal < self.q[7]
            # A grasp closes until a unit's faces stop the fingers (fully on air), as franka_gripper's does.
            stop = self.block_between_fingers() if closing else goal
            self.q[7:] = stop
            self.world.set_joint_positions(self.q)
            if closing and stop > goal:
                self.grab()
            elif not closing:
                self.held = None
        time.sleep(0.2 / self.speed)
        result.position, result.effort = stop, goal_handle.request.command.max_effort if closing else 0.0
        result.reached_goal = abs(2 * stop - 2 * goal) <= 0.005
        result.stalled = stop != goal
        (goal_handle.succeed if result.reached_goal else goal_handle.abort)()
        return result

    def hand(self):
        hand_p, hand_q = self.world.link_pose()
        hand = np.eye(4)
        hand[:3, :3], hand[:3, 3] = matrix_from_quaternion(hand_q), hand_p
        return hand

    def unit_at_hand(self):
        """(block id, its pose) of a block with a unit within 1 cm of the grasp point, or None."""
        hand_p = self.hand()[:3, 3]
        for block in self.scene.blocks:
            p, q = self.world.block_pose(block.id)
            units = p + (matrix_from_quaternion(q) @ (self.scene.block_types[block.type].rotated(0).T
                                                      * self.scene.unit)).T
            if np.min(np.linalg.norm(units - hand_p, axis=1)) < 0.01:
                pose = np.eye(4)
                pose[:3, :3], pose[:3, 3] = matrix_from_quaternion(q), p
                return block.id, pose
        return None

    def block_between_fingers(self) -> float:
        """Where closing fingers stop (per finger): a unit's faces, or fully closed on air."""
        found = self.unit_at_hand()
        return self.scene.unit * (1 - self.scene.clearance) / 2 if found else 0.0

    def grab(self):
        found = self.unit_at_hand()
        if found is not None:
            self.held = (found[0], np.linalg.inv(self.hand()) @ found[1])

    def carry(self):
        hand = self.hand()
        if self.held is not None:
            pose = hand @ self.held[1]
            self.world.set_block_pose(self.held[0], pose[:3, 3], quaternion_from_matrix(pose[:3, :3]))

    def publish(self):
        stamp = self.get_clock().now().to_msg()
        with self.lock:
            self._publish(stamp)

    def _publish(self, stamp):
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
    return run_node(KinematicPlant, executor_factory=lambda: MultiThreadedExecutor(num_threads=4))


if __name__ == '__main__':
    sys.exit(main())

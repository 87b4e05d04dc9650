"""Records calibration pairs from a live cell, for `rad calibrate`.

A marker (a motion-capture body) is fixed to the flange. Move the arm to a pose,
let it rest, call ~/record: the node appends one row to the pairs CSV, the
marker's base-frame position by forward kinematics (the simulated URDF's, the
flange link panda_link8, plus marker_offset in the flange frame) beside its
motion-capture position, both averaged over the last rest_window_s. Repeat at a
dozen poses spread over the workspace (not on one line), then
`rad calibrate pairs.csv --out calibration.yaml`.

Endpoints (relative names):
  sub  joint_states    sensor_msgs/JointState: the arm joints by name (robot, joint_prefix)
  sub  <marker_topic>  geometry_msgs/PoseStamped: the marker body as natnet_ros2 or vrpn_mocap
                       publish it (e.g. /natnet_ros2/flange_marker/pose, /vrpn_mocap/flange_marker/pose)
  srv  ~/record        std_srvs/Trigger: append a pair; refused with the reason (no input, stale
                       input, the arm or the marker moving, a frame_id other than mocap_frame)

The robot comes from the cell's profile, as for every other node: start the recorder with the same
parameter file (`--params-file franka.yaml`: its calibration_recorder section says robot: fr3) or
give `-p robot:=fr3` (or panda). Left unset, the node stays up and every ~/record is refused saying so.

Parameters: robot ('' = unset: refused), joint_prefix (''), marker_topic ('mocap/flange_marker/pose'),
marker_offset ([x, y, z] m in the flange frame), csv_file ('calibration_pairs.csv'),
mocap_frame ('' = take any frame_id), rest_window_s (0.5), joint_tol (0.001 rad),
marker_tol (0.001 m), stale_after_s (0.5). Both inputs use sensor-data QoS, which also
hears a reliable publisher.
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np
from geometry_msgs.msg import PoseStamped
from rad_core.cell.calibration import RestConfig, append_pair_row, marker_in_base, still_mean
from rad_core.cell.robot_model import robot_model
from rad_core.domain.errors import RadError
from rad_core.sim.world import World
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

KEEP_S = 5.0
"""s of input history kept (at least the rest window)."""

# All read when the recorder starts: read-only.
PARAMS = [Param('robot', '', "panda or fr3, as the cell's profile says ('' = unset: recording is refused)"),
          Param('joint_prefix', '', "joint names' prefix ('' = the robot's)"),
          Param('marker_topic', 'mocap/flange_marker/pose', "the flange marker's PoseStamped topic"),
          Param('marker_offset', [0.0, 0.0, 0.0], "the marker's offset from the flange, flange frame (m)",
                any_type=True),
          Param('csv_file', 'calibration_pairs.csv', 'where recorded pairs are appended'),
          Param('mocap_frame', '', "motion capture's frame, checked against each marker message ('' = any)"),
          Param('rest_window_s', 0.5, 'the robot and the marker must rest this long (s)', range=(0.01, 60.0)),
          Param('joint_tol', 0.001, 'joint motion allowed while resting (rad)', range=(0.0, 0.1)),
          Param('marker_tol', 0.001, 'marker motion allowed while resting (m)', range=(0.0, 0.1)),
          Param('stale_after_s', 0.5, 'inputs older than this are stale (s)', range=(0.01, 60.0))]


class CalibrationRecorder(Node):
    def __init__(self):
        super().__init__('calibration_recorder')
        declare(self, PARAMS)
        robot = str(self.param('robot'))
        # No silent default: FR3 and Panda name their joints differently, and the profile says which this is.
        self.model = robot_model(robot, str(self.param('joint_prefix'))) if robot else None
        self.no_robot = ('' if robot else "the robot is not set: start the recorder with the cell's parameter file "
                         '(--ros-args --params-file <your franka.yaml>, whose calibration_recorder section names it) '
                         'or -p robot:=fr3 (or panda)')
        self.rest = RestConfig(float(self.param('rest_window_s')), float(self.param('joint_tol')),
                               float(self.param('marker_tol')), float(self.param('stale_after_s')))
        self.offset = np.asarray(self.param('marker_offset'), dtype=float)
        if self.offset.shape != (3,) or not np.all(np.isfinite(self.offset)):
            raise RadError(f'marker_offset must be 3 finite numbers (m, flange frame), got {self.offset.tolist()}')
        self.keep_s = max(KEEP_S, 2 * self.rest.window_s)
        self.world = World()              # forward kinematics of the simulated URDF
        # one thread (rclpy.spin) runs every callback: the histories need no lock
        self.joints: deque = deque()
        self.markers: deque = deque()
        self.input_problem = {'joint_states': '', 'marker': ''}   # why the last message was not taken
        self.create_subscription(JointState, 'joint_states', self.joint_states_callback, qos_profile_sensor_data)
        topic = str(self.param('marker_topic'))
        self.create_subscription(PoseStamped, topic, self.marker_callback, qos_profile_sensor_data)
        self.create_service(Trigger, '~/record', self.record_callback)
        if self.model is None:
            self.get_logger().error(self.no_robot)
            return
        self.get_logger().info(f'recording pairs into {self.param("csv_file")}: {self.model.name}, marker on '
                               f'{topic}, offset {self.offset.tolist()} m from {self.model.prefix}_link8')

    def destroy_node(self):
        self.world.close()
        super().destroy_node()

    def param(self, name):
        return self.get_parameter(name).value

    def _keep(self, samples: deque, value: np.ndarray, key: str) -> None:
        now = time.monotonic()
        samples.append((now, value))
        while samples[0][0] < now - self.keep_s:
            samples.popleft()
        self.input_problem[key] = ''

    def joint_states_callback(self, msg: JointState) -> None:
        if self.model is None:
            return
        by_name = dict(zip(msg.name, msg.position))
        missing = [n for n in self.model.arm_joint_names if n not in by_name]
        if missing:
            self.input_problem['joint_states'] = (f'/joint_states lacks {", ".join(missing)} (robot '
                                                  f'{self.model.name}, joint_prefix {self.model.prefix!r})')
            return
        self._keep(self.joints, np.array([by_name[n] for n in self.model.arm_joint_names], dtype=float),
                   'joint_states')

    def marker_callback(self, msg: PoseStamped) -> None:
        frame = str(self.param('mocap_frame'))
        if frame and msg.header.frame_id != frame:
            self.input_problem['marker'] = (f'the marker pose is in frame {msg.header.frame_id!r}, '
                                            f'not mocap_frame {frame!r}')
            return
        p = msg.pose.position
        self._keep(self.markers, np.array([p.x, p.y, p.z], dtype=float), 'marker')

    def take_pair(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(arm q, marker in base, marker in mocap) over the rest window, or RadError."""
        if self.model is None:
            raise RadError(self.no_robot)
        now = time.monotonic()
        joints, markers = list(self.joints), list(self.markers)
        for key, samples in (('joint_states', joints), ('marker', markers)):
            if self.input_problem[key] and (not samples or now - samples[-1][0] > self.rest.stale_after_s):
                raise RadError(self.input_problem[key])
        q = still_mean(joints, now, self.rest, '/joint_states', self.rest.joint_tol, 'rad')
        p_mocap = still_mean(markers, now, self.rest, f'the marker on {self.param("marker_topic")}',
                             self.rest.marker_tol, 'm')
        return q, marker_in_base(self.world, q, self.offset), p_mocap

    def record_callback(self, request, response):
        try:
            q, p_base, p_mocap = self.take_pair()
            count = append_pair_row(str(self.param('csv_file')), p_base, p_mocap,
                                    {f'q{k}': float(v) for k, v in enumerate(q, start=1)})
        except RadError as e:
            response.success, response.message = False, str(e)
            self.get_logger().warning(f'record refused: {e}')
            return response
        except Exception as e:  # noqa: BLE001 - a service must answer, never die
            response.success, response.message = False, f'internal error: {type(e).__name__}: {e}'
            self.get_logger().error(response.message)
            return response
        response.success = True
        response.message = (f'pair {count} recorded: base {np.round(p_base, 4).tolist()} m, '
                            f'mocap {np.round(p_mocap, 4).tolist()} m')
        self.get_logger().info(response.message)
        return response


main = main_for(CalibrationRecorder)

"""Grasp and motion planning as a service (the paper's Sec. IV-C).

  srv  plan_action   rad_msgs/PlanAction: can this action be executed from this scene
                     state, with which grasp and which motion (arm trajectories of the
                     robot model's 7 joints, timed within its limits x speed_scale, and
                     the gripper commands between them)? On failure, failure = 'grasp'
                     (f_g) or 'placement' (f_p) and a reason. With `place_at_pose`, the
                     block's anchor goes to `place_pose` instead of the action's cell
                     (upright, yaw a multiple of 90 degrees: taking a structure apart puts
                     blocks back on the table). With `execute`, the motion
                     is also sent (in the background) through the arm controller's and
                     the gripper's actions (parameters arm_controller, gripper_action).

The node keeps one planning world (its own PyBullet client) and loads each
request's scene into it; the world is never stepped, only probed.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time

import numpy as np
from rad_core.cell.motion import run_motion
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion
from rad_core.gamp.action import MotionPlanner, SceneAction
from rad_core.gamp.planner import GampConfig, plan_action
from rad_core.gamp.trajectory import TimingConfig
from rad_core.sim.workspace import Workspace
from rad_msgs.srv import PlanAction
from rad_ros.conversions import scene_from_request
from rad_ros.motion import motion_to_msgs, moved_aside_to_msgs, pose_from_msg
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare, on_set
from rad_ros.plant import ActionPlant
from rclpy.node import Node


TIMING = ('speed_scale', 'acceleration_scale', 'grasp_force')
"""The parameters that change the next plan's timing while the node runs; the others are read at start."""

PARAMS = [
    Param('frame_id', 'world', 'frame of the planned trajectories\' headers'),
    Param('seed', 0, "GAMP's random seed (IK restarts)"),
    Param('robot', 'panda', "the robot model whose joints, limits and names plans use: 'panda' or 'fr3'"),
    Param('joint_prefix', '', 'prefix of the joint names (a namespaced robot description)'),
    Param('speed_scale', 0.7, "fraction of the robot's velocity limits trajectories use; from the next plan",
          dynamic=True, range=(0.01, 1.0)),
    Param('limits', 'both', "'both' (the robot's and rad's own margins) or 'robot' (the robot's alone)"),
    Param('acceleration_scale', 1.0, "fraction of the robot's acceleration and jerk limits; from the next plan",
          dynamic=True, range=(0.01, 1.0)),
    Param('grasp_force', 20.0, "the hand's grasp force (N); from the next plan", dynamic=True, range=(1.0, 70.0)),
    Param('arm_controller', 'joint_trajectory_controller', 'the arm controller (its follow_joint_trajectory action)'),
    Param('gripper_action', 'franka_gripper/gripper_action', "the hand's GripperCommand action"),
    Param('wide_grasps', True, "grasps across a block's whole row where it fits the open hand"),
    Param('drop', True, "let a block the hand cannot set down between built neighbours go 14 mm over its place"),
    Param('effector', 'hand', "what the arm carries: 'hand' or 'suction'"),
    Param('vacuum_ns', 'franka_vacuum_gripper', "the vacuum gripper node's namespace (effector 'suction')"),
]


class GampNode(Node):
    def __init__(self):
        super().__init__('gamp')
        declare(self, PARAMS)
        param = lambda name: self.get_parameter(name).value  # noqa: E731
        timing = TimingConfig(robot=str(param('robot')), joint_prefix=str(param('joint_prefix')),
                              limits=str(param('limits')), speed_scale=float(param('speed_scale')),
                              acceleration_scale=float(param('acceleration_scale')),
                              grasp_force=float(param('grasp_force')))
        timing.validate()    # a bad robot, scale or force stops the node here with the reason
        effector = str(param('effector'))
        self.planner = MotionPlanner(GampConfig(seed=int(param('seed')), timing=timing,
                                                wide_grasps=bool(param('wide_grasps')), drop=bool(param('drop')),
                                                effector=effector))
        on_set(self, self.retime)
        self.plant = ActionPlant(self, timing.model, str(param('arm_controller')), str(param('gripper_action')),
                                 vacuum_ns=str(param('vacuum_ns')) if effector == 'suction' else '')
        self.create_service(PlanAction, 'plan_action', self.plan_action_callback)
        self.get_logger().info('grasp and motion planning ready')

    def retime(self, changes: dict) -> None:
        """speed_scale, acceleration_scale or grasp_force set while the node runs: the next plan uses
        them (RadError, refusing the change, for values the robot model does not take)."""
        timing = dataclasses.replace(self.planner.config.timing, **{k: float(v) for k, v in changes.items()
                                                                   if k in TIMING})
        timing.validate()
        self.planner.config = dataclasses.replace(self.planner.config, timing=timing)
        if changes:
            self.get_logger().info('timing now ' + ', '.join(f'{k} {v:g}' for k, v in changes.items()))

    def plan(self, request):
        scene = scene_from_request(request.scene, request.scene_json)
        a = request.action
        if request.place_at_pose:
            block = scene.block(a.block_id)
            position, yaw = place_pose(request.place_pose)
            units = position + scene.pitch * scene.block_types[block.type].rotated(yaw)
            Workspace().check_points(units, f'place_pose of block {a.block_id!r}: a unit')
            if units[:, 2].min() < scene.course / 4:
                raise RadError(f'place_pose of block {a.block_id!r} puts it into the table (lowest unit centre '
                               f'z = {units[:, 2].min():.3f} m, on the table it is {scene.course / 2:.3f} m)')
            start = self.planner.load(scene, request.start_positions)
            config = self.planner.config
            return plan_action(self.planner.world, a.block_id, position, yaw, start=start,
                               config=dataclasses.replace(config, drop=False) if request.set_down else config)
        action = SceneAction(a.block_id, a.unit, a.target, (a.cell.i, a.cell.j, a.cell.k), a.rotation)
        result, _, _ = self.planner(scene, action, start=request.start_positions, move_aside=request.move_aside,
                                    set_down=request.set_down)
        return result

    def plan_action_callback(self, request, response):
        t0 = time.perf_counter()
        try:
            result = self.plan(request)
        except RadError as e:
            response.success, response.reason, response.failure = False, str(e), 'invalid_request'
            self.get_logger().warning(f'plan_action refused: {e}')
            return response
        except Exception as e:  # noqa: BLE001 - a service must answer, never die
            self.get_logger().error(f'plan_action failed: {type(e).__name__}: {e}')
            response.success, response.reason, response.failure = False, f'internal error: {e}', 'error'
            return response
        response.planning_time_s = time.perf_counter() - t0
        response.success, response.failure, response.reason = result.success, result.failure, result.reason
        if not result.success:
            self.get_logger().info(f'{request.action.block_id}: {result.reason}')
            return response
        response.grasp.unit, response.grasp.yaw_deg = int(result.grasp.unit), int(result.grasp.yaw)
        response.grasp.span = int(result.grasp.span)
        response.drop = float(result.drop)
        response.trajectories, response.gripper = motion_to_msgs(result.motion.to_dict(),
                                                                 self.get_parameter('frame_id').value)
        response.moved_aside_blocks, response.moved_aside_poses = moved_aside_to_msgs(result.moved_aside)
        if request.execute:
            threading.Thread(target=self.execute, args=(request.action.block_id, result.motion), daemon=True).start()
        sent = ' (sent for execution)' if request.execute else ''
        self.get_logger().info(f'{request.action.block_id}: planned {len(result.motion.trajectories)} trajectories, '
                               f'{result.motion.duration:.1f} s of arm motion, in '
                               f'{response.planning_time_s * 1e3:.0f} ms{sent}')
        return response

    def execute(self, block_id: str, motion) -> None:
        """Run a planned motion through the controllers' actions (the node's executor serves the futures)."""
        try:
            problem = run_motion(motion, self.plant.move_arm, self.plant.move_gripper)
        except RadError as e:
            problem = str(e)
        if problem:
            self.get_logger().error(f'{block_id}: execution failed: {problem}')
        else:
            self.get_logger().info(f'{block_id}: executed')


def place_pose(pose) -> tuple[np.ndarray, int]:
    """A place pose's anchor position and yaw (deg, a multiple of 90); RadError for what a scene
    cannot hold (not finite, not upright, turned between the quarter turns)."""
    position, quaternion = pose_from_msg(pose)
    q = np.asarray(quaternion, dtype=float)
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(q))):
        raise RadError('place_pose must be finite')
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-3:
        raise RadError(f'place_pose: the orientation is not a unit quaternion (norm {norm:.4f})')
    r = matrix_from_quaternion(q / norm)
    if r[2, 2] < math.cos(math.radians(1.0)):
        raise RadError('place_pose must be upright (a turn about z only): a block is put down flat')
    yaw = math.degrees(math.atan2(r[1, 0], r[0, 0]))
    quarter = round(yaw / 90.0) * 90
    if abs(yaw - quarter) > 1.0:
        raise RadError(f'place_pose: yaw {yaw:.1f} deg is not a multiple of 90 degrees')
    return np.asarray(position, dtype=float), int(quarter) % 360


main = main_for(GampNode)

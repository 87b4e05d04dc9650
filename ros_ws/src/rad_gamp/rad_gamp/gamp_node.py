"""Grasp and motion planning as a service (the paper's Sec. IV-C).

  srv  plan_action   rad_msgs/PlanAction: can this action be executed from this scene
                     state, with which grasp and which trajectory? On failure,
                     failure = 'grasp' (f_g) or 'placement' (f_p) and a reason.
  pub  joint_trajectory_controller/joint_trajectory  trajectory_msgs/JointTrajectory
                     the planned trajectory, when the request asks to execute it

The node keeps one planning world (its own PyBullet client) and loads each
request's scene into it; the world is never stepped, only probed.
"""

from __future__ import annotations

import time

from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from rad_core.errors import RadError
from rad_core.gamp.action import MotionPlanner, SceneAction
from rad_core.gamp.planner import GampConfig
from rad_msgs.srv import PlanAction
from rad_ros.conversions import scene_from_request
from rad_ros.motion import trajectory_to_msg
from rad_ros.node_main import main_for


class GampNode(Node):
    def __init__(self):
        super().__init__('gamp')
        self.declare_parameter('frame_id', 'world')
        self.declare_parameter('seed', 0)
        self.planner = MotionPlanner(GampConfig(seed=int(self.get_parameter('seed').value)))
        self.trajectory_pub = self.create_publisher(
            JointTrajectory, 'joint_trajectory_controller/joint_trajectory', 10)
        self.create_service(PlanAction, 'plan_action', self.plan_action_callback)
        self.get_logger().info('grasp and motion planning ready')

    def plan(self, request):
        scene = scene_from_request(request.scene, request.scene_json)
        a = request.action
        action = SceneAction(a.block_id, a.unit, a.target, (a.cell.i, a.cell.j, a.cell.k), a.rotation)
        result, _, _ = self.planner(scene, action, start=request.start_positions)
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
        response.trajectory = trajectory_to_msg(result.trajectory.to_dict(), self.get_parameter('frame_id').value)
        if request.execute:
            self.trajectory_pub.publish(response.trajectory)
        self.get_logger().info(f'{request.action.block_id}: planned {len(result.trajectory.points)} points, '
                               f'{result.trajectory.duration:.1f} s, in {response.planning_time_s * 1e3:.0f} ms'
                               + (' (sent for execution)' if request.execute else ''))
        return response


main = main_for(GampNode)

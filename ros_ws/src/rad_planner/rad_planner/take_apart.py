"""/take_apart: take the built structure apart, back onto the table, on the assembly node.

  act  take_apart  rad_msgs/TakeApart: register the world from motion capture, plan the
                   take-apart (rad_core.sequencing.execution.disassembly: blocks with nothing on
                   them first, each back to its pose in the goal's heap scene or the
                   nearest free table spot, every motion from /plan_action with a place
                   pose), run it through the arm controller's and the hand's actions,
                   re-register after each step and re-plan when a step deviates
                   (bounded by the node's max_replans); cancelling it stops the arm

The server lives on the assembly node (`serve_take_apart(node)`), whose plant, joint
states, registration (`registered_world` where the node has it: fallen blocks set aside)
and parameters (settle_s, position_tol, max_replans, time_limit_s, the tracker's noise)
it shares with /execute_assembly, and its arm: one goal of the two at a time (`rad_ros.arm_lock`).
"""

from __future__ import annotations

import json
import time

from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_quaternion
from rad_core.sequencing.execution.disassembly import TableConfig, take_apart
from rad_core.sequencing.execution.execute import ExecuteConfig
from rad_core.sequencing.planning.plan import MotionPlan
from rad_msgs.action import TakeApart
from rad_ros.motion import pose_msg
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup


def place_planner(node):
    """A disassembly.PlacePlanner over /plan_action (a place pose instead of a cell)."""
    def plan_place(scene: Scene, block_id: str, position, yaw: int, start) -> MotionPlan:
        request = node.plan_action_request(scene, start)
        request.action.block_id = block_id
        request.place_at_pose, request.place_pose = True, pose_msg(position, yaw_quaternion(yaw))
        return node.ask_plan_action(request, start)
    return plan_place


def heap_of(node, goal) -> Scene:
    """The goal's heap scene, or the node's task (the scene the twin loaded) when it has none."""
    if goal.heap_json.strip():
        return Scene.loads(goal.heap_json)
    if node.task is None:
        raise RadError('no heap_json in the goal and no task known: give the start scene as heap_json')
    return node.task


def serve_take_apart(node) -> ActionServer:
    """Mount /take_apart on an assembly node (rad_planner.assembly_node.AssemblyNode)."""
    plan_place = place_planner(node)

    def run(goal_handle):
        goal = goal_handle.request
        result = TakeApart.Result()
        feedback = TakeApart.Feedback()
        t0 = time.perf_counter()
        cancelled = lambda: node.stop_requested(goal_handle)  # noqa: E731

        def report(step, planned, block, phase, message):
            feedback.step, feedback.steps_planned, feedback.block_id = step, planned, block
            feedback.phase, feedback.message = phase, message
            goal_handle.publish_feedback(feedback)

        try:
            limit = node.time_limit(goal.time_limit_s)
            heap = heap_of(node, goal)
            # Lenient registration: a fallen block is set aside (and reported lost), not a reason to
            # leave the rest of the structure standing.
            register = node.registered_world
            scene = register().scene
            if not {b.id for b in heap.blocks} & {b.id for b in scene.blocks}:
                raise RadError('the heap scene has none of the blocks motion capture sees')
            config = ExecuteConfig(float(node.param('settle_s')), float(node.param('position_tol')),
                                   int(node.param('max_replans')), True,
                                   mocap_noise=node.noise[0])
            plant = node.plant(cancelled)
            run = take_apart(scene, heap, plan_place, plant.move_arm, plant.move_gripper, register,
                             config, TableConfig(), build_order=list(goal.build_order), time_limit_s=limit,
                             joints=lambda: node.start_joints([]), cancelled=cancelled, report=report)
        except Exception as e:  # noqa: BLE001 - an action must answer, never die
            result.success = False
            result.reason = str(e) if isinstance(e, RadError) else f'internal error: {type(e).__name__}: {e}'
            if not isinstance(e, RadError):
                node.get_logger().error(f'take_apart failed: {result.reason}')
            report(0, 0, '', 'done', result.reason)
            goal_handle.abort()
            return result
        stats = run.drift_stats()
        result.success, result.reason = run.success, node.ended_why(goal_handle, run.reason)
        result.steps_executed, result.replans = len(run.steps), run.run.replans
        result.lost = list(run.lost)
        result.drift_mean_m, result.drift_max_m = stats['mean_mm'] / 1e3, stats['max_mm'] / 1e3
        result.result_json = json.dumps(run.document({'total': time.perf_counter() - t0}))
        node.get_logger().info(f'take_apart: {len(run.steps)} steps, {run.run.replans} replans, '
                               f'{len(run.lost)} lost, drift max {stats["max_mm"]:.1f} mm'
                               + (f': {run.reason}' if run.reason else ''))
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            (goal_handle.succeed if result.success else goal_handle.abort)()
        return result

    return ActionServer(node, TakeApart, 'take_apart', node.arm_lock.serve(node, '/take_apart', TakeApart.Result, run,
                                                                            node.refusal),
                        goal_callback=lambda goal: GoalResponse.ACCEPT,
                        cancel_callback=lambda goal: CancelResponse.ACCEPT,
                        callback_group=ReentrantCallbackGroup())

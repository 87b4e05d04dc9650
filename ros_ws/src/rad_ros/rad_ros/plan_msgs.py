"""AssemblyPlan -> rad_msgs (PlanAssembly response, PlanStep) and the plan_json topic."""

from __future__ import annotations

from rad_core.allocation import Placement
from rad_core.domain.transforms import yaw_quaternion
from rad_core.sequencing.planning.plan import AssemblyPlan
from rad_msgs.msg import PlanStep, Reallocation, StageTiming

from rad_ros.conversions import cells_msg, placement_to_msg
from rad_ros.motion import motion_to_msgs, moved_aside_to_msgs, pose_msg


def step_to_msg(step, frame_id: str) -> PlanStep:
    msg = PlanStep(block_id=step.block, type=step.type, target=step.target, yaw_deg=int(step.yaw),
                   cells=cells_msg(step.cells), unit=int(step.unit), rotation=int(step.rotation))
    msg.cell.i, msg.cell.j, msg.cell.k = (int(v) for v in step.cell)
    msg.grasp.unit, msg.grasp.yaw_deg = int(step.grasp[0]), int(step.grasp[1])
    msg.grasp.span = int(step.grasp[2]) if len(step.grasp) > 2 else 1
    msg.target_pose = pose_msg(step.position, yaw_quaternion(step.yaw))
    if step.motion:
        msg.trajectories, msg.gripper = motion_to_msgs(step.motion, frame_id)
    msg.moved_aside_blocks, msg.moved_aside_poses = moved_aside_to_msgs(step.moved_aside)
    return msg


def reallocation_to_msg(event) -> Reallocation:
    """A `sequencing.planning.reallocation.Reallocation` as a message."""
    return Reallocation(
        step=int(event.step), reason=event.reason,
        no_goods=[placement_to_msg(Placement(d['type'], d['target'], 0, tuple(tuple(c) for c in d['cells'])))
                  for d in event.no_goods],
        no_good_reasons=[d['reason'] for d in event.no_goods],
        excluded_blocks=[d['block'] for d in event.blocks], excluded_block_reasons=[d['reason'] for d in event.blocks],
        status=event.status,
        objective=float(event.objective), bound=float(event.bound), solve_time_s=float(event.solve_time_s),
        placements=[placement_to_msg(p) for p in event.placements], changed=bool(event.changed))


def fill_plan_response(response, plan: AssemblyPlan, timings: dict, frame_id: str):
    response.success, response.reason = plan.success, plan.reason
    if plan.allocation is not None:
        response.allocation_status = plan.allocation.status
        response.allocation_objective = float(plan.allocation.objective)
        response.allocation_bound = float(plan.allocation.bound)
        response.allocation = [placement_to_msg(p) for p in plan.allocation.placements]
    response.steps = [step_to_msg(s, frame_id) for s in plan.steps]
    response.predicted_coverage = float(plan.predicted_coverage)
    response.timings = [StageTiming(stage=k, seconds=float(v)) for k, v in timings.items()]
    response.scene_json = plan.scene.dumps()
    response.reallocations = [reallocation_to_msg(e) for e in plan.reallocations]
    response.anytime_times_s = [float(a['t']) for a in plan.anytime]
    response.anytime_coverages = [float(a['coverage']) for a in plan.anytime]
    response.anytime_plans = [str(a['plan']) for a in plan.anytime]
    return response


def plan_json(plan: AssemblyPlan) -> dict:
    """What the visualizer reads from the latched plan_json topic."""
    return {'allocation': plan.allocation.to_dict() if plan.allocation is not None else None,
            'steps': [{k: v for k, v in s.to_dict().items() if k not in ('trajectories', 'gripper')}
                      for s in plan.steps],
            'timings': plan.timings, 'predicted_coverage': plan.predicted_coverage,
            'success': plan.success, 'reason': plan.reason,
            'reallocations': [e.to_dict() for e in plan.reallocations], 'anytime': plan.anytime}

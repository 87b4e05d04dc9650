"""Build a plan in a PyBullet twin, in process: what the node graph's execution does, without DDS.

Two ways, as `rad eval --execution` names them:

- `build_teleported`: every planned step puts its block at the pose the plan gives, physics
  settles the world after each, and the twin's registration (as motion capture sees it)
  judges the result; a block that fell over or off its cell is set aside and not counted.
- `build_simulated`: `sequencing.execution.execute.execute_assembly`, the execute / verify / replan loop
  the assembly node's /execute_assembly runs, against the twin's controller: the arm follows
  every trajectory, the gripper closes and opens, faults (if configured) happen, and the loop
  replans from the registered world.

Benchmarks and `rad eval` with the robot use these, so their figures are what the graph builds.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from rad_core.cell.trajectory import TrajectoryAborted
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_quaternion
from rad_core.sequencing.execution.execute import ExecuteConfig, execute_assembly
from rad_core.sim.twin import Tolerances, Twin, TwinConfig, twin_world_config
from rad_core.sim.world import World, WorldConfig


@dataclass
class SimulatedBuild:
    """What `build_simulated` returns: the execution's result and what the twin saw."""

    result: object                        # sequencing.execution.execute.ExecutionResult
    sim_s: float = 0.0                    # simulated seconds the run took
    injected: dict = field(default_factory=dict)   # fault (or action) -> how many the twin injected


def build_teleported(scene: Scene, steps, settle_s: float = 0.5, effector: str = 'hand'):
    """Put each step's block (`PlanStep`: block, position, yaw; first the blocks it moves out of
    the way, `moved_aside`) where the plan says and the arm where its motion ends, settle
    `settle_s` simulated seconds after each, and register the world: a `cell.mocap.Registration`
    (its scene: where every block is; set_aside: blocks no scene can express, with why). effector:
    what the arm carries (`cell.panda.EFFECTORS`)."""
    with World(scene, twin_world_config(WorldConfig(effector=effector))) as world:
        twin = Twin(world)
        for step in steps:
            for d in getattr(step, 'moved_aside', ()):
                world.set_block_pose(d['block'], d['position'], yaw_quaternion(d['yaw']))
            world.present(step.block)       # from the feeder, if the scene has one and it is there
            world.set_block_pose(step.block, step.position, yaw_quaternion(step.yaw))
            world.studs.join(world, step.block)     # teleported: pressed home onto the studs under it
            if step.motion:
                # The arm where the step's motion leaves it (retreated above the block), as after a real
                # step: left at home, a tall structure would grow into the hand.
                world.set_joint_positions(step.final_joints())
            twin.sync()
            twin.settle(settle_s)
        return twin.registration()


def build_simulated(scene: Scene, plan, plan_motion, twin_config=None, execute_config=None,
                    effector: str = 'hand') -> SimulatedBuild:
    """Run /execute_assembly's loop in a fresh twin of the scene.

    plan(scene, start) -> AssemblyPlan (e.g. an `AgentPlanner`); plan_motion: its motion planner
    (for backing out after an abort); twin_config: a `sim.twin.TwinConfig` (faults; default none);
    execute_config: an `ExecuteConfig` (default: settle 0.5 s, 3 replans). Trajectories run with
    the tolerances the assembly node sends with every goal, so contact aborts them as on a cell.
    effector: what the arm carries (`cell.panda.EFFECTORS`): the hand's or the vacuum gripper's actions.
    """
    with World(scene, twin_world_config(WorldConfig(effector=effector))) as world:
        twin = Twin(world, twin_config or TwinConfig())
        sim0 = twin.time

        def move_arm(trajectory):
            report = twin.execute(trajectory, tolerances=Tolerances(path=0.05, goal=0.01, goal_time=1.0))
            if report.error_code:      # as rad_ros.plant.ActionPlant: a started trajectory stopped
                raise TrajectoryAborted(report.error_code, f'trajectory aborted (error code {report.error_code}): '
                                                           f'{report.error_string}')

        result = execute_assembly(scene, plan, move_arm, twin.execute_gripper, twin.registration,
                                  execute_config or ExecuteConfig(settle_s=0.5),
                                  joints=lambda: twin.world.joint_positions(), settle=twin.settle,
                                  plan_motion=plan_motion, present=twin.present)
        injected = Counter(e.get('fault', e.get('action', '?')) for e in twin.fault_events)
        return SimulatedBuild(result, twin.time - sim0, dict(injected))

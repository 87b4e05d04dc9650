"""Execute an assembly on a plant: plan, run each step, verify it, replan on deviation.

`execute_assembly` knows nothing of ROS: the plant and the planner come in as
callables, so /execute_assembly passes DDS glue (the arm controller's
FollowJointTrajectory and the hand's GripperCommand actions, joint states, motion
capture) and tests pass an in-process `rad_core.sim.twin.Twin`.

A step runs its arm trajectories and gripper commands in order
(`rad_core.cell.motion.run_motion`). Every answer is checked and every failure stops
the step with its cause, then the world is registered and, with `replan`, a new plan
starts from it:
- a trajectory the controller aborts (the arm held back) or refuses (it never moved):
  the arm backs out from where it came to rest, along the path it came, to where the
  step began; a block in the hand is put back where it was picked (`_run_step`);
- a grasp that holds nothing (the width the hand reports after closing): the hand
  opens and the arm backs out along its approach;
- any other gripper command the hand refuses, drops, or ends short of its width (an
  'open' before the descent, a 'release'): the arm stops where it is, so it never
  descends with closed fingers nor carries a block it was to let go of.

After each step the world is registered again and compared with what the plan
expected (`result.deviation`). A step that left the world other than planned (a
block nudged, a block that slid) ends that plan: with `replan`, a new plan starts
from the measured world, at most `max_replans` times; without, the run fails with
the deviation as its reason. Every executed step is kept in the result, including
the one that deviated, so the rad-result/1 document says what the robot did.

The faults of a real cell (`rad_core.sim.faults`) all end up as one of these:
- a block left a few millimetres off (placement error, a nudge, motion-capture
  noise) that registration still snaps to its cell, or that stays within the
  deviation tolerance on the table: it counts as where the plan put it. The
  registration keeps how far off its cell it was seen (`Scene.measured_offsets`),
  and with `plan_motion` each later step's motion is planned again from the world
  as measured just before it runs: the motion planning world puts those blocks
  where they were seen, and the next block is set down clear of them
  (`rad_core.gamp.action.seat_shift`), not onto the edge of a neighbour that
  landed 2 mm into its cell. A step that cannot be planned again so is a
  deviation (below). The tolerance follows the tracker's noise
  (`ExecuteConfig.mocap_noise`), so noise alone does not look like a fault;
- a block farther off, or fallen (a slip): a deviation; the plan is repaired by
  replanning from what is seen, where a block lying flat on the table is just a
  block to pick again;
- a grasp on nothing (a miss): the step fails, the hand opens and backs out, and
  the loop replans;
- a block a scene cannot express (on its side, on an edge, turned, off its grid
  in a region): `register` may return a `rad_core.cell.mocap.Registration`
  (`register_world`), which sets such blocks aside instead of failing the whole
  frame. A set-aside block is reported lost and left out of later plans: it can
  neither be picked nor counted. It is still there, so the cells of the targets it
  occupies are left out of the plans too (`Registration.plannable`): no block is
  planned into it, and coverage, measured against the real targets, shows the
  loss. Known limit: GAMP does not see a set-aside block as an obstacle to the arm's
  paths (one lying on the table far from the structure rarely is one).
Nothing is counted as built that registration does not see on its cells: the
coverage is measured from the last registration, and a run whose last plan
finished but whose coverage is below what the first plan set out to build (lost
blocks, cells left out) is not a success; its reason says what was lost. The
result counts replans, every fault the loop met (`faults`, with whether a new
plan recovered from it) and the lost blocks.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from rad_core.allocation.result import AllocationResult
from rad_core.cell.mocap import Registration
from rad_core.cell.motion import VACUUM_ACTIONS, GripperCommand, GripperResult, Motion, gripper_problem, run_motion
from rad_core.cell.panda import HOME
from rad_core.cell.robot_model import PANDA, envelope
from rad_core.cell.trajectory import Trajectory, TrajectoryAborted, TrajectoryRejected
from rad_core.domain.coverage import measured_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.gamp.action import SceneAction
from rad_core.gamp.trajectory import retime
from rad_core.sequencing.execution.result import deviation, result_document
from rad_core.sequencing.planning.plan import AssemblyPlan, PlanMotion


@dataclass(frozen=True)
class ExecuteConfig:
    """How execution checks its steps."""

    settle_s: float = 0.5
    """Wait this long (s) after a step before registering the world (blocks come to rest)."""
    position_tol: float = 0.005
    """A block farther than this (m) from where the plan put it is a deviation."""
    max_replans: int = 3
    """At most this many new plans after deviations."""
    replan: bool = True
    """Replan on a deviation (else the run fails with it)."""
    mocap_noise: float = 0.0
    """Std dev (m) per axis of motion capture's positions: a block counts as off only when it is
    off by more than 6 sigma of the difference of two measurements as well as position_tol."""
    recover_aborts: bool = True
    """A trajectory the controller aborted after it started (the arm held back by contact): open the
    hand, back out along the path it came, re-register and replan (False: the abort ends the run)."""
    back_out_speed: float = 0.3
    """Fraction of the Franka limits (velocity, acceleration, jerk) the back-out moves at."""
    press_retries: int = 2
    """A studded brick seen standing on its studs after its step (not pressed home) is taken again where it
    stands and pressed onto its cell, at most this many times, before the step counts as deviated."""

    @property
    def deviation_tol(self) -> float:
        """How far (m) a block may be from where the plan put it and still count as there."""
        return max(self.position_tol, 6 * math.sqrt(2) * self.mocap_noise)

    def validate(self) -> None:
        if not (self.settle_s >= 0 and np.isfinite(self.settle_s)):
            raise RadError(f'settle_s must be finite and >= 0, got {self.settle_s}')
        if not (self.position_tol > 0 and np.isfinite(self.position_tol)):
            raise RadError(f'position_tol must be positive, got {self.position_tol}')
        if not (self.mocap_noise >= 0 and np.isfinite(self.mocap_noise)):
            raise RadError(f'mocap_noise must be finite and >= 0, got {self.mocap_noise}')
        if not (0 < self.back_out_speed <= 1):
            raise RadError(f'back_out_speed must be in (0, 1], got {self.back_out_speed}')
        if self.max_replans < 0:
            raise RadError(f'max_replans must be >= 0, got {self.max_replans}')
        if self.press_retries < 0:
            raise RadError(f'press_retries must be >= 0, got {self.press_retries}')


@dataclass
class ExecutionResult:
    success: bool
    reason: str
    scene: Scene                                   # the world the run started from
    steps: list[dict] = field(default_factory=list)   # PlanStep.to_dict() of every executed step
    replans: int = 0
    final_scene: Scene | None = None               # registered at the end (or the last one known)
    allocation: AllocationResult | None = None     # the first plan's
    reallocations: list[dict] = field(default_factory=list)   # of every plan, Reallocation.to_dict()
    faults: list[dict] = field(default_factory=list)
    """Every problem a step met, in order: {'step' (index into steps), 'block', 'problem', 'recovered'
    (a new plan was made from the measured world)}."""
    lost_blocks: dict[str, str] = field(default_factory=dict)
    """Blocks the last registration could not express (block id -> why): not planned for, not counted."""
    blocked_cells: dict[str, list] = field(default_factory=dict)
    """Region name -> target cells the lost blocks occupy (left out of the plans)."""
    planned_coverage: float | None = None
    """The coverage the first plan set out to build (its steps applied to the scene)."""
    unseated: dict[str, float] = field(default_factory=dict)
    """Studded bricks the last registration saw standing on their studs, not pressed home (block id ->
    how far above its seat, m)."""

    @property
    def coverage(self) -> float:
        return measured_coverage(self.final_scene) if self.final_scene is not None else 0.0

    @property
    def recovered_faults(self) -> int:
        return sum(f['recovered'] for f in self.faults)

    def execution(self) -> dict:
        """The run's recovery figures, as the rad-result/1 document's `execution` holds them."""
        return {'replans': self.replans, 'faults': [dict(f) for f in self.faults],
                'recovered_faults': self.recovered_faults, 'lost_blocks': dict(self.lost_blocks),
                'planned_coverage': self.planned_coverage,
                'blocked_cells': {k: [list(c) for c in v] for k, v in self.blocked_cells.items()}}

    def document(self, timings: dict) -> dict:
        """The rad-result/1 document of the run."""
        return result_document(self.scene, self.allocation, self.steps, self.final_scene, timings,
                               self.reallocations, self.execution())


Plan = Callable[[Scene, 'np.ndarray | None'], AssemblyPlan]   # scene, start joints (None: home)
MoveArm = Callable[[dict], None]     # run an arm trajectory to its end; RadError if refused or aborted
MoveGripper = Callable[[GripperCommand], GripperResult]   # run a gripper command, return what the hand says
Register = Callable[[], 'Scene | Registration']   # the world as measured now; RadError if it cannot be
Report = Callable[[int, int, str, str, str], None]   # (steps done, steps planned, block, phase, message)


def execute_assembly(scene: Scene, plan: Plan, move_arm: MoveArm, move_gripper: MoveGripper, register: Register,
                     config: ExecuteConfig = ExecuteConfig(), joints: Callable[[], 'np.ndarray | None'] | None = None,
                     cancelled: Callable[[], bool] = lambda: False, report: Report | None = None,
                     settle: Callable[[float], None] = time.sleep,
                     plan_motion: PlanMotion | None = None,
                     present: Callable[[str], object] | None = None) -> ExecutionResult:
    """Build `scene` on the plant; never raises RadError (it becomes the result's reason).

    joints: the robot's joints now (arm and fingers), for each plan's start (None: home); without
    it, every plan starts where the last executed motion ended (home at first).
    settle(seconds): let the plant come to rest (a real plant: wait; a twin: step it).
    plan_motion: the planner's motion planner (scene, action, start joints), to plan a step's motion
    again from the measured world when registration saw blocks off their cells (None: never).
    present(block id): the scene's feeder puts that block at its station (None: the plant has no
    feeder; a scene with one then fails at its first block from it, with that reason).
    Phases reported: planning, executing, verifying, replanning, done.
    """
    config.validate()
    report = report or (lambda *_: None)
    plant = _Plant(move_arm, move_gripper, register, joints, settle, present, report, config)
    result = ExecutionResult(False, '', scene, final_scene=scene)
    last_q = None
    current = scene
    try:
        while True:
            report(len(result.steps), 0, '', 'planning', '')
            start = joints() if joints is not None else last_q
            last_q = None if start is None else np.asarray(start, dtype=float)
            assembly = plan(current, start)
            _note_plan(result, assembly, current)
            problem = None
            for k, step in enumerate(assembly.steps):
                if cancelled():
                    raise RadError('cancelled')
                report(len(result.steps), len(assembly.steps), step.block, 'executing', '')
                step_start = HOME if last_q is None else last_q
                if plan_motion is not None and k > 0 and (current.measured_offsets
                                                          or not _starts_at(step.motion, step_start)):
                    # Blocks were seen off their cells since the plan was made, or the step before was
                    # planned again and left the arm elsewhere: plan this motion again from the world as
                    # measured (the first step's was planned from it).
                    step, problem = _plan_motion_again(step, current, step_start, plan_motion)
                    if problem is not None:
                        result.faults.append({'step': len(result.steps), 'block': step.block, 'problem': problem,
                                              'recovered': False})
                        break
                problem, current, last_q = _execute_step(plant, result, step, step_start, current,
                                                         len(assembly.steps))
                for _ in range(config.press_retries if plan_motion is not None else 0):
                    if not _is_not_pressed(problem, step.block):
                        break
                    problem, current, last_q = _press_again(plant, result, step, current, last_q, plan_motion,
                                                            len(assembly.steps))
                    if problem is None:          # pressed home this time
                        for fault in result.faults:
                            if _is_not_pressed(fault['problem'], step.block):
                                fault['recovered'] = True
                if problem is not None:
                    break
            if problem is None:
                result.success, result.reason = assembly.success, assembly.reason
                break
            if _refused_again(result):
                raise RadError(f'{problem} (the controller refused this step\'s motion twice in a row: a new plan '
                               'would not change its mind)')
            if not config.replan or result.replans >= config.max_replans:
                raise RadError(f'the world differs from the plan: {problem}')
            result.replans += 1
            report(len(result.steps), len(assembly.steps), '', 'replanning', problem)
    except RadError as e:
        result.success, result.reason = False, str(e)
    try:
        _measure(register, result)
    except RadError:
        pass   # the plant is gone, or a block is where no plan can go: keep what was measured last
    _judge_coverage(result)
    report(len(result.steps), len(result.steps), '', 'done', result.reason)
    return result


@dataclass(frozen=True)
class _Plant:
    """What `execute_assembly` runs a step with and checks it by (its arguments of the same names)."""

    move_arm: MoveArm
    move_gripper: MoveGripper
    register: Register
    joints: Callable[[], 'np.ndarray | None'] | None
    settle: Callable[[float], None]
    present: Callable[[str], object] | None
    report: Report
    config: ExecuteConfig


def _measure(register: Register, result: ExecutionResult) -> Scene:
    """The world as registered now (into the result's final_scene, lost_blocks and blocked_cells),
    and the scene to plan from."""
    got = register()
    reg = got if isinstance(got, Registration) else Registration(got)
    result.final_scene, result.lost_blocks = reg.scene, dict(reg.set_aside)
    result.unseated = dict(reg.unseated)
    result.blocked_cells = {name: [list(c) for c in cells] for name, cells in reg.blocked.items()}
    return reg.plannable()


def _note_plan(result: ExecutionResult, assembly: AssemblyPlan, current: Scene) -> None:
    """Record a new plan: a fault before it recovered, the first plan's allocation and the coverage it
    sets out to build, every plan's re-allocations."""
    if result.faults and result.replans and not _still_unpressed(result, result.faults[-1]):
        result.faults[-1]['recovered'] = True     # a new plan from the measured world
    if result.allocation is None:
        result.allocation = assembly.allocation
        promised = current
        for step in assembly.steps:
            promised = step.scene_after(promised)
        result.planned_coverage = measured_coverage(promised)
    result.reallocations += [e.to_dict() for e in assembly.reallocations]


def _plan_motion_again(step, current: Scene, step_start: np.ndarray, plan_motion: PlanMotion):
    """(the step with its motion planned again from the measured world `current`, None), or (the
    step as it was, the problem) where it cannot be placed so."""
    fresh = plan_motion(current, SceneAction(step.block, step.unit, step.target, tuple(step.cell),
                                             step.rotation), step_start,
                        **({'move_aside': True} if step.moved_aside else {}))
    if not fresh.success:
        return step, (f'block {step.block}: planned again against the blocks where motion capture '
                      f'sees them, it cannot be placed ({fresh.reason})')
    return replace(step, motion=fresh.motion, grasp=tuple(fresh.grasp), moved_aside=list(fresh.moved_aside)), None


def _execute_step(plant: _Plant, result: ExecutionResult, step, step_start: np.ndarray, current: Scene,
                  n_steps: int) -> tuple[str | None, Scene, np.ndarray]:
    """Run one step on the plant, register the world and compare it with what the step expected.
    The step goes into the result, with a fault where it failed or deviated (a failed registration is
    booked as a fault and raised). Returns (the problem or None, the measured world to plan from,
    where the arm is)."""
    if current.in_feeder(step.block):
        if plant.present is None:
            raise RadError(f'block {step.block} is in the feeder, and this plant has no feeder '
                           f'to present it')
        plant.present(step.block)
    motion = Motion.from_dict(step.motion)
    try:
        failed = _run_step(motion, plant.move_arm, plant.move_gripper, step_start, plant.joints, plant.config,
                           plant.settle)
    except RadError as e:
        if str(e) != 'cancelled':
            result.steps.append({**step.to_dict(), 'failure': str(e)})
            result.faults.append({'step': len(result.steps) - 1, 'block': step.block, 'problem': str(e),
                                  'recovered': False})
        raise
    # A failed grasp, or a trajectory the controller aborted or refused, has opened the hand and backed
    # the arm out to where the step began; another failed gripper command left the arm where it was:
    # the next plan starts from the joints as measured, where they are known.
    last_q = motion.final_joints()
    if failed:
        measured = plant.joints() if plant.joints is not None else None
        last_q = np.asarray(measured, dtype=float) if measured is not None else np.concatenate(
            [step_start[:7], [motion.opening] * 2])
    plant.settle(plant.config.settle_s)
    plant.report(len(result.steps), n_steps, step.block, 'verifying', failed)
    expected = step.scene_after(current)
    result.steps.append({**step.to_dict(), **({'failure': failed} if failed else {})})
    try:
        current = _measure(plant.register, result)
    except RadError as e:
        result.faults.append({'step': len(result.steps) - 1, 'block': step.block,
                              'problem': str(e), 'recovered': False})
        raise
    problem = failed or deviation(expected, current, plant.config.deviation_tol, result.lost_blocks)
    if problem is None and step.block in result.unseated:
        problem = _not_pressed(step.block, result.unseated[step.block])
    if problem is not None:
        result.faults.append({'step': len(result.steps) - 1, 'block': step.block, 'problem': problem,
                              'recovered': False})
    return problem, current, last_q


def _not_pressed(block: str, raised: float) -> str:
    return (f'block {block} is not pressed home: motion capture sees it {raised * 1000:.1f} mm above its seat, '
            f'standing on the studs under it')


def _is_not_pressed(problem: str | None, block: str) -> bool:
    """Whether a step's problem is `_not_pressed` of this block."""
    return problem is not None and problem.startswith(f'block {block} is not pressed home:')


def _press_again(plant: _Plant, result: ExecutionResult, step, current: Scene, start: np.ndarray,
                 plan_motion: PlanMotion, n_steps: int) -> tuple[str | None, Scene, np.ndarray]:
    """A brick left standing on its studs: take it again where it stands and set it down on its cell
    with a press (its own step's action, its motion planned from the world as measured), as
    `_execute_step` runs a step. (the problem or None, the measured world, where the arm is)."""
    fresh = plan_motion(current, SceneAction(step.block, step.unit, step.target, tuple(step.cell), step.rotation),
                        start)
    if not fresh.success:
        problem = f'block {step.block}: cannot be taken again to press it home ({fresh.reason})'
        result.faults.append({'step': len(result.steps) - 1, 'block': step.block, 'problem': problem,
                              'recovered': False})
        return problem, current, start
    again = replace(step, motion=fresh.motion, grasp=tuple(fresh.grasp), moved_aside=[])
    return _execute_step(plant, result, again, start, current, n_steps)


def _still_unpressed(result: ExecutionResult, fault: dict) -> bool:
    """Whether the fault is a brick not pressed home that still is (a new plan takes it as built)."""
    return fault['block'] in result.unseated and _is_not_pressed(fault['problem'], fault['block'])


def _judge_coverage(result: ExecutionResult) -> None:
    """Judge the run by what the last registration sees: below what the first plan set out to build
    is no success, and the reason names the lost blocks; so is a brick left standing on its studs."""
    if result.success and result.unseated:
        result.success = False
        result.reason = 'not pressed home: ' + ', '.join(
            f'{b} ({h * 1000:.1f} mm above its seat)' for b, h in sorted(result.unseated.items()))
    lost = '; '.join(f'{b} ({why})' for b, why in sorted(result.lost_blocks.items()))
    if result.success and result.planned_coverage is not None and result.coverage < result.planned_coverage - 1e-9:
        result.success = False
        result.reason = (f'coverage {result.coverage:.3f} is below the {result.planned_coverage:.3f} the first plan '
                         f'set out to build' + (f'; lost blocks: {lost}' if lost else ''))
    elif result.success and lost and not result.reason:
        result.reason = f'built without {len(result.lost_blocks)} lost block(s): {lost}'
    elif not result.success and lost:
        result.reason = f'{result.reason}; lost blocks: {lost}'


def _refused_again(result: ExecutionResult) -> bool:
    """Whether the last two faults are refusals of the same block's motion by the arm controller."""
    last = result.faults[-2:]
    return len(last) == 2 and all(f['problem'].startswith('trajectory refused') for f in last) and \
        last[0]['block'] == last[1]['block']


def _starts_at(motion: dict | None, q: np.ndarray) -> bool:
    """Whether a motion's first arm trajectory starts where the arm is (q)."""
    trajectories = (motion or {}).get('trajectories') or []
    if not trajectories:
        return True
    first = trajectories[0]
    first = first if isinstance(first, Trajectory) else Trajectory.from_dict(first)
    start = np.asarray(first.points[0].positions, dtype=float)
    return bool(np.abs(start - np.asarray(q, dtype=float)[:7]).max() < 1e-6)


def _run_step(motion: Motion, move_arm: MoveArm, move_gripper: MoveGripper, step_start: np.ndarray,
              joints, config: ExecuteConfig, settle: Callable[[float], None] = time.sleep) -> str:
    """run_motion, and when the controller aborts a trajectory it had started (the arm or the held
    block met something: PATH_TOLERANCE_VIOLATED) or refuses one (it never moved), recover as a cell's
    operator would script it: back the arm out along the path it came (the checked straight joint
    segments between the motion's rest points, reversed) to where the step began. A block in the hand
    is carried back to where it was picked and put down there (its spot is free: it came from there),
    then the arm goes on backing out with the hand open; the loop then re-registers and replans.

    The back-out starts from the arm's measured state: after an abort the arm is still moving (the
    controller brakes it to a hold), and the last joint state may be older than the stop, so the
    joints are read until two readings `_REST_EVERY_S` apart agree (`_at_rest`), and the back-out
    begins there, at rest, as Franka's controller needs a new motion to begin. Needs `joints`;
    without it, or with config.recover_aborts false, the abort ends the run."""
    sent: list = []
    grips: list[GripperCommand] = []

    def tracked_arm(trajectory):
        sent.append(trajectory)
        move_arm(trajectory)

    def tracked_gripper(command):
        grips.append(command)
        return move_gripper(command)

    try:
        return run_motion(motion, tracked_arm, tracked_gripper, start=step_start[:7])
    except (TrajectoryAborted, TrajectoryRejected) as e:
        if joints is None or not config.recover_aborts:
            raise
        aborted = e
    what = 'refused' if isinstance(aborted, TrajectoryRejected) else 'aborted'
    held = next((g for g in reversed(grips) if g.action in ('grasp', 'release', 'vacuum', 'drop_off')), None)
    held = held if held is not None and held.action in ('grasp', 'vacuum') else None

    def let_go(action: str, before: int) -> None:
        """Open the hand ('open', 'release'), or with the vacuum gripper drop off (nothing to open); a
        hand that does not open ends the recovery (RadError)."""
        vacuum = next((g for g in motion.gripper if g.action in VACUUM_ACTIONS), None)
        if vacuum is None:
            command = GripperCommand(action, motion.opening, 0.0, before)
        elif action == 'release' or held is not None:
            command = GripperCommand('drop_off', vacuum.position, 0.0, before, timeout_ms=vacuum.timeout_ms)
        else:
            return
        problem = gripper_problem(command, move_gripper(command))
        if problem:
            raise RadError(problem)
    try:
        q_now = _at_rest(joints, settle)
        path = back_out_path(sent, q_now, np.asarray(step_start, dtype=float)[:7])
        first = sent[0] if isinstance(sent[0], Trajectory) else Trajectory.from_dict(sent[0])
        names = first.joint_names
        if held is None:
            let_go('open', 0)
            legs = [path]
        else:
            # Where the hand closed on the block: the end of the trajectory before the grasp.
            before = sent[held.before - 1] if held.before > 0 else None
            picked = np.asarray((before if isinstance(before, Trajectory) else Trajectory.from_dict(before))
                                .points[-1].positions if before is not None else step_start[:7], dtype=float)
            cut = next((i for i, q in enumerate(path) if np.abs(q - picked).max() < 1e-6), len(path) - 1)
            legs = [path[:cut + 1], path[cut:]]
        def back_out(waypoints) -> None:
            back = retime(waypoints, envelope(PANDA), config.back_out_speed, joint_names=names)
            try:
                move_arm(back)
            except TrajectoryRejected:
                move_arm(back)          # refused, so it never moved: ask once more
        wedged = False
        for k, leg in enumerate(legs):
            if len(leg) > 1:
                try:
                    back_out(leg)
                except TrajectoryAborted:
                    if k > 0 or held is None:
                        raise
                    # The held block is wedged and does not come back out with the hand: let go of it
                    # where it is and back out empty from where the arm stopped.
                    let_go('open', held.before)
                    wedged = True
                    q_here = _at_rest(joints, settle)
                    rest = back_out_path(sent, q_here, np.asarray(step_start, dtype=float)[:7])
                    if len(rest) > 1:
                        back_out(rest)
                    break
            if k == 0 and held is not None:
                let_go('release', held.before)
    except RadError as e:
        raise RadError(f'{aborted}; backing out failed: {e}') from None
    where = '' if held is None else (', let go of the wedged block' if wedged
                                     else ', put the block back where it was picked')
    return f'trajectory {what}: {aborted}; the arm backed out{where} and the hand opened'


_REST_EVERY_S = 0.1
"""Seconds between the joint readings `_at_rest` compares (a joint state published at 10 Hz or more
gives a new reading each time)."""
_REST_TOL = 2e-4
"""Two readings this close on every joint count as the arm at rest (0.1 s apart: under 2 mrad/s)."""
_REST_TIMEOUT_S = 3.0


def _at_rest(joints, settle: Callable[[float], None]) -> np.ndarray:
    """The arm's 7 joints once it is at rest: joints() read every `_REST_EVERY_S` until two readings in a
    row agree within `_REST_TOL` on every joint; RadError when it is not still after `_REST_TIMEOUT_S`
    (or joint states stop coming)."""
    def read():
        q = joints()
        if q is None:
            raise RadError("no joint state to back out from")
        return np.asarray(q, dtype=float)[:7]
    q = read()
    for _ in range(int(round(_REST_TIMEOUT_S / _REST_EVERY_S))):
        settle(_REST_EVERY_S)
        q_next = read()
        if np.abs(q_next - q).max() <= _REST_TOL:
            return q_next
        q = q_next
    raise RadError(f'the arm did not come to rest within {_REST_TIMEOUT_S:g} s of the stop (its joints still '
                   f'move by more than {_REST_TOL / _REST_EVERY_S * 1000:.0f} mrad/s)')


def back_out_path(sent: list, q_now: np.ndarray, step_start: np.ndarray) -> list[np.ndarray]:
    """Arm waypoints from where an aborted trajectory left the arm (q_now) back to where the step
    began: the rest points (zero velocity: the planner's waypoints, joined by straight joint segments)
    of the trajectories sent so far, in reverse, entering the last one's path on the segment q_now is
    nearest to."""
    trajs = [t if isinstance(t, Trajectory) else Trajectory.from_dict(t) for t in sent]
    rests: list[np.ndarray] = [np.asarray(step_start, dtype=float)]
    for k, traj in enumerate(trajs):
        pts = [np.asarray(p.positions, dtype=float) for p in traj.points
               if not p.velocities or max(abs(v) for v in p.velocities) < 1e-9]
        if k == len(trajs) - 1:
            # Keep the rest points up to the segment the arm stopped on.
            chain = [rests[-1]] + pts
            j = min(range(len(chain) - 1), key=lambda i: _to_segment(q_now, chain[i], chain[i + 1]))
            pts = pts[:j]
        rests += pts
    path = [np.asarray(q_now, dtype=float)]
    for q in reversed(rests):
        if np.abs(q - path[-1]).max() > 1e-6:
            path.append(q)
    return path


def _to_segment(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    t = 0.0 if not d.any() else float(np.clip(np.dot(q - a, d) / np.dot(d, d), 0.0, 1.0))
    return float(np.linalg.norm(q - (a + t * d)))

"""sequencing.execution.execute: the execute / verify / replan loop on an in-process plant, without DDS.

The plant is a real twin (physics, contact grasps), the plans come from real CP-SAT
and GAMP; only the faults the real parts will not produce on demand are injected
(a block moved by hand mid-run, a block taken away before the hand closes on it, a plant
that never finishes, a cancel).
"""

from dataclasses import replace

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.cell.panda import HOME
from rad_core.cell.trajectory import PATH_TOLERANCE_VIOLATED, TrajectoryAborted
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.gamp.action import MotionPlanner
from rad_core.sequencing import HeurPolicy
from rad_core.sequencing.execution.execute import ExecuteConfig, execute_assembly
from rad_core.sequencing.planning.plan import local_motion_planner, plan_assembly
from rad_core.sim.faults import FaultConfig
from rad_core.sim.twin import Tolerances, Twin, twin_world_config
from rad_core.sim.world import World

SCENE = generate_scene(GeneratorConfig(grid=3), 1)


@pytest.fixture(scope='module')
def motion():
    planner = MotionPlanner()
    yield local_motion_planner(planner)
    planner.close()


@pytest.fixture
def twin():
    # The twin as the twin node builds it: its blocks have a real block's play between neighbours
    # (sim.twin.BLOCK_PLAY), not the planning worlds' hairline.
    with World(SCENE, twin_world_config()) as world:
        yield Twin(world)


class Run:
    """The callables a node would build from DDS (the arm controller's and the gripper's actions),
    here on the in-process twin."""

    def __init__(self, twin, motion):
        self.twin, self.plans, self.sent, self.grips, self.phases = twin, [], [], [], []
        self.motion = motion

    def plan(self, scene, start):
        plan = plan_assembly(scene, solve, self.motion, HeurPolicy(), seed=1, start=start)
        self.plans.append((scene, start, plan))
        return plan

    def move_arm(self, trajectory):
        self.sent.append(trajectory)
        report = self.twin.execute(trajectory)
        if report.error_code:
            raise RadError(f'aborted ({report.error_code}): {report.error_string}')

    def move_gripper(self, command):
        self.grips.append(command)
        return self.twin.execute_gripper(command)

    @property
    def placed(self) -> int:
        """Steps whose block has been released."""
        return sum(g.action == 'release' for g in self.grips)

    def register(self):
        return self.twin.current_scene()

    def report(self, step, planned, block, phase, message):
        self.phases.append((phase, message))

    def __call__(self, config=ExecuteConfig(settle_s=0.2), **kw):
        kw = {'plan': self.plan, 'move_arm': self.move_arm, 'move_gripper': self.move_gripper,
              'register': self.register, 'report': self.report,
              'settle': self.twin.settle, **kw}
        return execute_assembly(SCENE, config=config, **kw)


def test_builds_the_scene_step_by_step_and_documents_it(twin, motion):
    run = Run(twin, motion)
    result = run()
    assert result.success, result.reason
    assert result.replans == 0 and len(run.plans) == 1
    assert len(result.steps) == len(result.allocation.placements) == run.placed
    # Arm and hand apart: three arm trajectories of the 7 arm joints per step, grasp and release between.
    assert len(run.sent) == 3 * len(result.steps)
    assert all(list(t.joint_names) == [f'panda_joint{k}' for k in range(1, 8)] for t in run.sent)
    assert [g.action for g in run.grips if g.action in ('grasp', 'release')] == ['grasp', 'release'] * len(result.steps)
    assert result.coverage == 1.0
    phases = [p for p, _ in run.phases]
    assert phases[0] == 'planning' and phases[-1] == 'done'
    assert phases.count('executing') == phases.count('verifying') == len(result.steps)
    doc = result.document({'total': 1.0})
    assert doc['format'] == 'rad-result/1' and doc['coverage'] == 1.0
    assert [s['block'] for s in doc['steps']] == [s['block'] for s in result.steps]
    assert {b['id'] for b in doc['final_blocks']} == {b.id for b in SCENE.blocks}


def test_a_block_moved_mid_run_replans_from_the_measured_world(twin, motion):
    run = Run(twin, motion)
    move_arm = run.move_arm

    def move_and_disturb(trajectory):
        move_arm(trajectory)
        if len(run.sent) == 3:   # after the first step, someone moves a block the plan does not use
            used = {s.block for s in run.plans[0][2].steps}
            block = next(b for b in SCENE.blocks if b.id not in used)
            pos, q = twin.world.block_pose(block.id)
            twin.world.set_block_pose(block.id, [pos[0] + 0.02, pos[1] - 0.06, pos[2]], q)
            run.moved = block.id
    result = run(move_arm=move_and_disturb)
    assert result.replans == 1, result.reason
    assert [p for p, _ in run.phases].count('replanning') == 1
    message = next(m for p, m in run.phases if p == 'replanning')
    assert run.moved in message and 'mm from where the plan put it' in message
    # The replan starts from the measured world (the moved block where it now is) and the
    # last trajectory's end joints (and the hand as the release left it).
    replanned_scene, start, _ = run.plans[-1]
    assert replanned_scene.block(run.moved).position != SCENE.block(run.moved).position
    assert np.allclose(start[:7], run.sent[2].points[-1].positions)
    assert np.allclose(start[7:], run.grips[-1].position)
    assert result.success, result.reason
    assert result.coverage == 1.0


def test_without_replan_a_deviation_is_the_reason(twin, motion):
    run = Run(twin, motion)
    move_arm = run.move_arm

    def move_and_disturb(trajectory):
        move_arm(trajectory)
        block = next(b for b in SCENE.blocks if b.id not in {s.block for s in run.plans[0][2].steps})
        pos, q = twin.world.block_pose(block.id)
        twin.world.set_block_pose(block.id, [pos[0], pos[1] - 0.05, pos[2]], q)
    result = run(config=ExecuteConfig(settle_s=0.1, replan=False), move_arm=move_and_disturb)
    assert not result.success and result.reason.startswith('the world differs from the plan')
    assert len(result.steps) == 1 and result.replans == 0


def test_a_plant_that_never_finishes_is_a_timeout_reason(twin, motion):
    run = Run(twin, motion)

    def never_finishes(trajectory):
        run.sent.append(trajectory)
        raise RadError('the arm controller (joint_trajectory_controller/follow_joint_trajectory) did not '
                       'finish within 12.0 s')
    result = run(move_arm=never_finishes)
    assert not result.success and 'did not finish within' in result.reason
    # The step that timed out is in the result with the reason, and so is its fault: nothing is lost.
    assert [s['failure'] for s in result.steps] == [result.reason] and len(run.sent) == 1
    assert result.faults[-1]['problem'] == result.reason and not result.faults[-1]['recovered']
    assert result.final_scene is not None and result.coverage == 0.0
    assert run.phases[-1] == ('done', result.reason)


def test_a_grasp_on_nothing_fails_the_step_and_the_loop_replans(twin, motion):
    """The block is taken away while the hand comes down: the hand closes on air, the width it
    reports says nothing is held, it opens, the world is measured and a new plan builds it."""
    run = Run(twin, motion)
    move_gripper = run.move_gripper

    def take_the_block_away(command):
        if command.action == 'grasp' and not hasattr(run, 'taken'):
            block = run.plans[0][2].steps[0].block
            pos, q = twin.world.block_pose(block)
            twin.world.set_block_pose(block, [pos[0], pos[1] + 0.1 if pos[1] < 0 else pos[1] - 0.1, pos[2]], q)
            run.taken = block
        return move_gripper(command)
    result = run(move_gripper=take_the_block_away, joints=lambda: twin.world.joint_positions())
    failed = result.steps[0]
    assert failed['block'] == run.taken and 'nothing is held' in failed['failure']
    assert result.replans == 1 and [p for p, _ in run.phases].count('replanning') == 1
    assert run.grips[run.grips.index(next(g for g in run.grips if g.action == 'grasp')) + 1].action == 'open'
    assert result.success, result.reason
    assert result.coverage == 1.0


def test_a_trajectory_aborted_mid_carry_puts_the_block_back_backs_out_and_replans(twin, motion):
    """The controller stops the carry halfway (as it does when the arm is held back; here forced):
    the arm carries the block back along the path it came to where it was picked, puts it down
    there, backs out to where the step began, and the loop re-registers and replans: the block is
    picked again and the build completes."""
    run = Run(twin, motion)

    def move_arm(trajectory):
        run.sent.append(trajectory)
        if len(run.sent) == 2:                   # the first step's carry: stopped 0.6 s in
            twin.start(trajectory, Tolerances())
            twin.advance(0.6)
            twin.cancel()
            raise TrajectoryAborted(PATH_TOLERANCE_VIOLATED, 'path tolerance violated (forced)')
        report = twin.execute(trajectory)
        if report.error_code:
            raise RadError(report.error_string)
    result = run(move_arm=move_arm, joints=lambda: twin.world.joint_positions())
    first = result.steps[0]
    assert 'trajectory aborted' in first['failure'] and 'put the block back' in first['failure'], first
    run_block = first['block']
    picked = run.sent[0].points[-1].positions           # the approach ends where the hand closed
    # Back to the pick with the block, released there, then back to where the step began.
    assert np.allclose(run.sent[2].points[-1].positions, picked, atol=1e-6)
    actions = [g.action for g in run.grips]
    assert actions[actions.index('grasp') + 1] == 'release'
    assert np.allclose(run.sent[3].points[-1].positions, HOME[:7], atol=1e-6)
    assert result.replans == 1 and result.faults[0]['recovered']
    # The block lay where it was picked, so the new plan picks it again and the build completes.
    assert run.plans[1][0].block(run_block).position == pytest.approx(SCENE.block(run_block).position, abs=1e-3)
    assert result.success and result.coverage == 1.0, result.reason


def test_a_block_wedged_on_the_way_back_is_let_go_and_the_arm_backs_out_empty(twin, motion):
    run = Run(twin, motion)

    def move_arm(trajectory):
        run.sent.append(trajectory)
        if len(run.sent) in (2, 3):              # the carry, and then the way back with the block
            twin.start(trajectory, Tolerances())
            twin.advance(0.6 if len(run.sent) == 2 else 0.2)
            twin.cancel()
            raise TrajectoryAborted(PATH_TOLERANCE_VIOLATED, 'path tolerance violated (forced)')
        report = twin.execute(trajectory)
        if report.error_code:
            raise RadError(report.error_string)
    result = run(move_arm=move_arm, joints=lambda: twin.world.joint_positions())
    assert 'let go of the wedged block' in result.steps[0]['failure'], result.steps[0]
    actions = [g.action for g in run.grips]
    assert actions[actions.index('grasp') + 1] == 'open'                   # let go where it stuck
    assert np.allclose(run.sent[3].points[-1].positions, HOME[:7], atol=1e-6)   # then back out empty
    assert result.replans >= 1 and result.faults[0]['recovered']
    dropped = result.steps[0]['block']
    assert dropped in {b.id for b in result.final_scene.blocks} or dropped in result.lost_blocks


def test_back_out_path_follows_the_rest_points_in_reverse():
    from rad_core.cell.trajectory import Trajectory, TrajectoryPoint
    from rad_core.sequencing.execution.execute import back_out_path
    names = tuple(f'panda_joint{k}' for k in range(1, 8))
    a, b, c, d = (np.full(7, v) for v in (0.0, 0.1, 0.2, 0.3))

    def traj(*qs):
        return Trajectory(names, [TrajectoryPoint(list(q), [0.0] * 7, float(i)) for i, q in enumerate(qs)])
    stopped = np.full(7, 0.25)                    # on the second trajectory's segment c -> d
    path = back_out_path([traj(a, b), traj(b, c, d)], stopped, a)
    assert [round(float(q[0]), 3) for q in path] == [0.25, 0.2, 0.1, 0.0]


def test_cancel_stops_before_the_next_step(twin, motion):
    run = Run(twin, motion)
    result = run(cancelled=lambda: run.placed >= 1 and len(run.sent) >= 3)
    assert not result.success and result.reason == 'cancelled'
    assert len(result.steps) == 1 and 0 < result.coverage < 1.0


def test_a_plan_that_cannot_be_made_is_the_reason_and_nothing_moves(twin):
    run = Run(twin, None)

    def plan(scene, start):
        raise RadError('service allocate is not available')
    result = run(plan=plan)
    assert not result.success and result.reason == 'service allocate is not available'
    assert run.sent == [] and run.grips == [] and result.allocation is None


def test_config_is_checked(twin):
    with pytest.raises(RadError, match='position_tol'):
        Run(twin, None)(config=ExecuteConfig(position_tol=0.0))


def test_the_deviation_tolerance_follows_the_tracker_noise():
    assert ExecuteConfig().deviation_tol == 0.005
    # 1 mm per axis: two measurements differ by sqrt(2) mm per axis; a deviation needs 6 sigma of that.
    assert ExecuteConfig(mocap_noise=0.001).deviation_tol == pytest.approx(0.0085, abs=1e-4)
    assert ExecuteConfig(position_tol=0.01, mocap_noise=0.001).deviation_tol == 0.01
    for bad in (-0.001, float('nan')):
        with pytest.raises(RadError, match='mocap_noise'):
            ExecuteConfig(mocap_noise=bad).validate()


# ---- the controllers' own failures, made to happen in the twin (sim.faults) -------------------------------

class Cell(Run):
    """Run, with the arm's answers as ActionPlant gives them (an abort raises TrajectoryAborted, a refusal
    TrajectoryRejected), the joints as a 50 Hz joint state gives them (the reading before the last 40 ms
    of motion, so a reading just after a stop is from before it), and one twin fault turned on for the
    n-th arm trajectory or gripper command."""

    def __init__(self, twin, motion, fault: str = '', nth: int = 0):
        super().__init__(twin, motion)
        self.fault, self.nth, self.history = fault, nth, []

    def _with_fault(self, kind: str, count: int, call):
        if self.fault.startswith(kind) and count == self.nth:
            calm = self.twin.config
            self.twin.config = replace(calm, faults=FaultConfig(**{self.fault: 1.0}))
            try:
                return call()
            finally:
                self.twin.config = calm
        return call()

    def move_arm(self, trajectory):
        self.sent.append(trajectory)
        report = self._with_fault('arm', len(self.sent), lambda: self.twin.execute(trajectory, callback=self.tick,
                                                                                   callback_period=0.02))
        if report.error_code:
            raise TrajectoryAborted(report.error_code, report.error_string)

    def move_gripper(self, command):
        self.grips.append(command)
        return self._with_fault('gripper', len(self.grips), lambda: self.twin.execute_gripper(command))

    def tick(self, twin):
        self.history = (self.history + [twin.world.joint_positions().copy()])[-3:]

    def joints(self):
        # The reading published 40 ms ago while the arm moved; the current one when it holds.
        stale, self.history = (self.history[0] if len(self.history) == 3 else None), []
        return stale if stale is not None else self.twin.world.joint_positions()

    def __call__(self, config=ExecuteConfig(settle_s=0.2), **kw):
        return super().__call__(config, joints=self.joints, **kw)


def test_an_arm_the_controller_stops_mid_carry_backs_out_from_where_it_came_to_rest(twin, motion):
    """The twin's controller stops the carry partway (arm_abort) while the arm moves fast; the last joint
    state is 40 ms older than the stop. The back-out starts where the arm came to rest, so the twin (which
    refuses any motion over the Panda's limits from where its controller holds) accepts it."""
    cell = Cell(twin, motion, 'arm_abort', 2)
    result = cell()
    first = result.steps[0]
    assert 'trajectory aborted' in first['failure'] and 'injected arm_abort' in first['failure'], first
    assert 'put the block back' in first['failure']
    assert result.faults[0]['recovered'] and twin.fault_counts['arm_abort'] == 1
    assert result.success and result.coverage == 1.0, result.reason


def test_a_trajectory_the_controller_refuses_is_backed_out_of_and_replanned(twin, motion):
    cell = Cell(twin, motion, 'arm_reject', 2)      # the carry, refused with the block in the hand
    result = cell()
    first = result.steps[0]
    assert 'trajectory refused' in first['failure'] and 'injected arm_reject' in first['failure'], first
    actions = [g.action for g in cell.grips]
    assert actions[actions.index('grasp') + 1] == 'release'       # put down where it was picked
    # Back from where it stood (a hair off the planned pick) to the pick, released, then home.
    assert np.allclose(cell.sent[3].points[-1].positions, HOME[:7], atol=1e-6)
    assert result.faults[0]['recovered'] and result.success and result.coverage == 1.0, result.reason


@pytest.mark.parametrize('fault', ['gripper_abort', 'gripper_reject'])
def test_a_hand_that_does_not_open_stops_the_step_before_the_arm_descends(twin, motion, fault):
    cell = Cell(twin, motion, fault, 2)               # close the empty hand, then open: the open fails
    result = cell()
    first = result.steps[0]
    assert first['failure'].startswith('open failed: '), first
    assert ('stopped at' in first['failure']) == (fault == 'gripper_abort'), first
    assert ('refused' in first['failure']) == (fault == 'gripper_reject'), first
    # Nothing moved in that step: the next arm trajectory sent belongs to the new plan.
    assert len(cell.plans) == 2 and cell.plans[1][0].block(first['block']).position == \
        pytest.approx(SCENE.block(first['block']).position, abs=1e-3)
    assert result.faults[0]['recovered'] and result.success and result.coverage == 1.0, result.reason


@pytest.mark.parametrize('fault', ['gripper_abort', 'gripper_reject'])
def test_a_hand_that_does_not_let_go_retreats_only_once_clear_of_the_block(twin, motion, fault):
    """A release that stops short (gripper_abort: the fingers stop partway, past the block's faces) lets
    the arm retreat as planned; one the hand refuses (gripper_reject: the fingers still hold the block)
    is asked again first. Either way the step reports it, and the loop re-registers and replans."""
    cell = Cell(twin, motion, fault, 4)               # close, open, grasp, release: the release fails
    result = cell()
    first = result.steps[0]
    assert first['failure'].startswith('release failed: '), first
    said = 'the fingers cleared the block' if fault == 'gripper_abort' else 'asked again, the hand let go'
    assert said in first['failure'], first
    releases = [g.action for g in cell.grips[:6]].count('release')
    assert releases == (1 if fault == 'gripper_abort' else 2)
    retreat = cell.plans[0][2].steps[0].motion['trajectories'][2]
    assert cell.sent[2].to_dict() == retreat                            # the planned retreat, as it was
    assert result.faults[0]['recovered'] and result.success and result.coverage == 1.0, result.reason


def test_a_hand_that_still_holds_a_placed_block_ends_the_run_for_a_person(twin, motion):
    cell = Cell(twin, motion, 'gripper_reject', 4)

    def move_gripper(command):                        # the release refused twice
        cell.grips.append(command)
        n = len(cell.grips)
        return cell._with_fault('gripper', 4 if n in (4, 5) else 0, lambda: twin.execute_gripper(command))
    result = cell(move_gripper=move_gripper)
    assert not result.success and 'free the block by hand' in result.reason, result.reason
    assert len(cell.sent) == 2                         # approach, carry: no retreat with the block held

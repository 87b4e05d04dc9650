"""sequencing.execute: the execute / verify / replan loop on an in-process plant, without DDS.

The plant is a real twin (physics, contact grasps), the plans come from real CP-SAT
and GAMP; only the faults the real parts will not produce on demand are injected
(a block moved by hand mid-run, a plant that never finishes, a cancel).
"""

import numpy as np
import pytest

from rad_core.allocation import solve
from rad_core.errors import RadError
from rad_core.gamp.action import MotionPlanner
from rad_core.generator import GeneratorConfig, generate_scene
from rad_core.sequencing import HeurPolicy
from rad_core.sequencing.execute import ExecuteConfig, execute_assembly
from rad_core.sequencing.plan import local_motion_planner, plan_assembly
from rad_core.sim.twin import Twin
from rad_core.sim.world import World

SCENE = generate_scene(GeneratorConfig(grid=3), 1)


@pytest.fixture(scope='module')
def motion():
    planner = MotionPlanner()
    yield local_motion_planner(planner)
    planner.close()


@pytest.fixture
def twin():
    with World(SCENE) as world:
        yield Twin(world)


class Run:
    """The callables a node would build from DDS, here on the in-process twin."""

    def __init__(self, twin, motion):
        self.twin, self.plans, self.sent, self.phases = twin, [], [], []
        self.motion = motion

    def plan(self, scene, start):
        plan = plan_assembly(scene, solve, self.motion, HeurPolicy(), seed=1, start=start)
        self.plans.append((scene, start, plan))
        return plan

    def send(self, trajectory):
        self.sent.append(trajectory)
        self.twin.execute(trajectory)

    def register(self):
        return self.twin.current_scene()

    def report(self, step, planned, block, phase, message):
        self.phases.append((phase, message))

    def __call__(self, config=ExecuteConfig(settle_s=0.2), **kw):
        kw = {'plan': self.plan, 'send': self.send, 'register': self.register, 'report': self.report,
              'settle': self.twin.settle, **kw}
        return execute_assembly(SCENE, config=config, **kw)


def test_builds_the_scene_step_by_step_and_documents_it(twin, motion):
    run = Run(twin, motion)
    result = run()
    assert result.success, result.reason
    assert result.replans == 0 and len(run.plans) == 1
    assert len(result.steps) == len(result.allocation.placements) == len(run.sent)
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
    send = run.send

    def send_and_disturb(trajectory):
        send(trajectory)
        if len(run.sent) == 1:   # after the first step, someone moves a block the plan does not use
            used = {s.block for s in run.plans[0][2].steps}
            block = next(b for b in SCENE.blocks if b.id not in used)
            pos, q = twin.world.block_pose(block.id)
            twin.world.set_block_pose(block.id, [pos[0] + 0.02, pos[1] - 0.06, pos[2]], q)
            run.moved = block.id
    result = run(send=send_and_disturb)
    assert result.replans == 1, result.reason
    assert [p for p, _ in run.phases].count('replanning') == 1
    message = next(m for p, m in run.phases if p == 'replanning')
    assert run.moved in message and 'mm from where the plan put it' in message
    # The replan starts from the measured world (the moved block where it now is) and the
    # last trajectory's end joints.
    replanned_scene, start, _ = run.plans[-1]
    assert replanned_scene.block(run.moved).position != SCENE.block(run.moved).position
    assert np.allclose(start, run.sent[0]['points'][-1]['positions'])
    assert result.success, result.reason
    assert result.coverage == 1.0


def test_without_replan_a_deviation_is_the_reason(twin, motion):
    run = Run(twin, motion)
    send = run.send

    def send_and_disturb(trajectory):
        send(trajectory)
        block = next(b for b in SCENE.blocks if b.id not in {s.block for s in run.plans[0][2].steps})
        pos, q = twin.world.block_pose(block.id)
        twin.world.set_block_pose(block.id, [pos[0], pos[1] - 0.05, pos[2]], q)
    result = run(config=ExecuteConfig(settle_s=0.1, replan=False), send=send_and_disturb)
    assert not result.success and result.reason.startswith('the world differs from the plan')
    assert len(result.steps) == 1 and result.replans == 0


def test_a_plant_that_never_finishes_is_a_timeout_reason(twin, motion):
    run = Run(twin, motion)

    def never_finishes(trajectory):
        run.sent.append(trajectory)
        raise RadError('the robot did not reach the end of the step within 3.0 s x 3 + 10 s')
    result = run(send=never_finishes)
    assert not result.success and 'did not reach the end of the step' in result.reason
    assert result.steps == [] and len(run.sent) == 1
    assert result.final_scene is not None and result.coverage == 0.0
    assert run.phases[-1] == ('done', result.reason)


def test_cancel_stops_before_the_next_step(twin, motion):
    run = Run(twin, motion)
    result = run(cancelled=lambda: len(run.sent) >= 1)
    assert not result.success and result.reason == 'cancelled'
    assert len(result.steps) == 1 and 0 < result.coverage < 1.0


def test_a_plan_that_cannot_be_made_is_the_reason_and_nothing_moves(twin):
    run = Run(twin, None)

    def plan(scene, start):
        raise RadError('service allocate is not available')
    result = run(plan=plan)
    assert not result.success and result.reason == 'service allocate is not available'
    assert run.sent == [] and result.allocation is None


def test_config_is_checked(twin):
    with pytest.raises(RadError, match='position_tol'):
        Run(twin, None)(config=ExecuteConfig(position_tol=0.0))

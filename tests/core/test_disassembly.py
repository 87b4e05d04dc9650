"""sequencing.execution.disassembly: take a built structure apart onto the table, on an in-process plant.

The plant is a real twin (physics, contact grasps), the plans real CP-SAT and GAMP; a fault is
injected only where the real parts will not make it on demand (a block pushed aside mid-run).
"""

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.domain.coverage import measured_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.gamp.action import MotionPlanner
from rad_core.sequencing import HeurPolicy
from rad_core.sequencing.execution.disassembly import (
    TableConfig,
    local_place_planner,
    plan_take_apart,
    removal_order,
    resting_on,
    return_poses,
    take_apart,
    to_take_apart,
)
from rad_core.sequencing.execution.execute import ExecuteConfig, execute_assembly
from rad_core.sequencing.planning.plan import MotionPlan, local_motion_planner, moved, plan_assembly
from rad_core.sim.twin import Twin, twin_world_config
from rad_core.sim.world import World

HEAP = generate_scene(GeneratorConfig(grid=3), 1)    # 4 blocks; the target takes 3, one stacked on another


@pytest.fixture(scope='module')
def planner():
    planner = MotionPlanner()
    yield planner
    planner.close()


@pytest.fixture(scope='module')
def built(planner):
    """The heap's target as planned (each block on its cells) and the order it was built in."""
    plan = plan_assembly(HEAP, solve, local_motion_planner(planner), HeurPolicy(), seed=1)
    assert plan.success, plan.reason
    return plan.final_scene, [s.block for s in plan.steps]


class Plant:
    """The callables a node builds from DDS, here on the in-process twin."""

    def __init__(self, twin):
        self.twin, self.phases, self.sent = twin, [], 0

    def move_arm(self, trajectory):
        self.sent += 1
        report = self.twin.execute(trajectory)
        if report.error_code:
            raise RadError(f'aborted ({report.error_code}): {report.error_string}')

    def report(self, step, planned, block, phase, message):
        self.phases.append((phase, block, message))

    def kw(self, **over):
        return {'move_arm': self.move_arm, 'move_gripper': self.twin.execute_gripper,
                'register': self.twin.current_scene, 'config': ExecuteConfig(settle_s=0.2),
                'joints': self.twin.world.joint_positions, 'report': self.report, 'settle': self.twin.settle,
                **over}


def test_what_rests_on_what_and_what_can_be_taken_first(built):
    scene, order = built
    pending = to_take_apart(scene)
    assert sorted(pending) == sorted(order) and to_take_apart(HEAP) == []
    on = resting_on(scene)
    stacked = {below: above for below, above in on.items() if above}
    assert stacked, 'the target has a block resting on another'
    below, above = next(iter(stacked.items()))
    first = removal_order(scene, pending, order)
    assert below not in first and above <= set(first)
    assert first[0] == order[-1]     # the reverse of the build order
    # Without the build order: the highest first.
    tops = {b: scene.unit_positions(scene.block(b))[:, 2].max() for b in first}
    assert removal_order(scene, pending)[0] == max(first, key=lambda b: (tops[b], b))


def test_a_block_goes_back_to_its_heap_pose_or_else_to_a_free_spot_off_the_target(built):
    scene, order = built
    bid = order[-1]
    poses = return_poses(scene, bid, HEAP)
    assert np.allclose(poses[0][0], HEAP.block(bid).position) and poses[0][1] == HEAP.block(bid).yaw
    # Another block stands on its heap spot: it goes somewhere free, off the targets, within reach.
    other = next(b for b in HEAP.blocks if b.id not in order)
    home = HEAP.block(bid)
    occupied = moved(scene, other.id, home.position, home.yaw)
    config = TableConfig()
    poses = return_poses(occupied, bid, HEAP, config)
    assert poses and not np.allclose(poses[0][0], home.position)
    for pos, yaw in poses:
        trial = moved(occupied, bid, pos, yaw)          # a valid scene: no overlap, not half in a region
        pts = trial.unit_positions(trial.block(bid))
        assert np.all(np.hypot(pts[:, 0], pts[:, 1]) <= config.reach)
        assert pts[:, 2].min() == pytest.approx(HEAP.unit / 2)
        assert bid not in to_take_apart(trial)


def test_a_block_that_can_go_straight_home_goes_before_one_that_cannot(planner, built):
    scene, order = built
    real = local_place_planner(planner)
    top = order[-1]
    home = HEAP.block(top)

    def place(current, block_id, position, yaw, start):
        if block_id == top and np.allclose(position, home.position):
            return MotionPlan(False, 'placement', 'placement: the hand hits a neighbour there')
        return real(current, block_id, position, yaw, start)
    plan = plan_take_apart(scene, HEAP, place, build_order=order)
    assert plan.success, plan.reason
    steps = [(s.block, np.allclose(s.position, HEAP.block(s.block).position)) for s in plan.steps]
    assert steps[0] == (order[-2], True) and (top, False) in steps
    assert all(at_home for b, at_home in steps if b != top)
    assert to_take_apart(plan.final_scene) == []


def test_builds_takes_apart_and_builds_again_with_nothing_touched(planner, built):
    """One cycle on the twin: build, take apart (every step verified), build again from what is seen."""
    with World(HEAP, twin_world_config()) as world:
        twin = Twin(world)
        plant = Plant(twin)

        def plan(scene, start):
            return plan_assembly(scene, solve, local_motion_planner(planner), HeurPolicy(), seed=1, start=start)
        build = execute_assembly(HEAP, plan, **plant.kw())
        assert build.success and build.coverage == 1.0, build.reason
        order = [s['block'] for s in build.steps]
        plant.phases.clear()
        run = take_apart(twin.current_scene(), HEAP, local_place_planner(planner), build_order=order,
                         **plant.kw())
        assert run.success, run.reason
        assert run.run.replans == 0 and run.failures == [] and run.lost == []
        assert len(run.steps) == len(order) and [s['target'] for s in run.steps] == [''] * len(order)
        # Every step was verified against the registered world; the structure came down top first.
        assert [p for p, _, _ in plant.phases].count('verifying') == len(run.steps)
        taken = [s['block'] for s in run.steps]
        for below, above in resting_on(build.final_scene).items():
            for b in above:
                assert taken.index(b) < taken.index(below), (b, below)
        final = run.final_scene
        assert to_take_apart(final) == [] and measured_coverage(final) == 0.0
        assert set(run.drift) == {b.id for b in HEAP.blocks}
        assert run.drift_stats()['max_mm'] < 2.0, run.drift      # every block back on its heap spot
        doc = run.document({'total': 1.0})
        assert doc['format'] == 'rad-result/1' and doc['take_apart']['lost'] == []
        assert doc['take_apart']['remaining'] == [] and doc['take_apart']['success']
        # Build again, from the registered heap.
        again = execute_assembly(twin.current_scene(), plan, **plant.kw())
        assert again.success and again.coverage == 1.0, again.reason


def test_a_block_pushed_aside_mid_take_apart_is_replanned_from_what_is_seen(planner, built):
    scene, order = built
    with World(scene, twin_world_config()) as world:
        twin = Twin(world)
        plant = Plant(twin)
        move_arm = plant.move_arm

        def move_and_push(trajectory):
            move_arm(trajectory)
            if plant.sent == 3:     # after the first step, a block waiting in the heap is pushed aside
                spare = next(b.id for b in HEAP.blocks if b.id not in order)
                pos, q = world.block_pose(spare)
                world.set_block_pose(spare, [pos[0] + 0.03, pos[1], pos[2]], q)
                plant.pushed = spare
        run = take_apart(twin.current_scene(), HEAP, local_place_planner(planner), build_order=order,
                         **plant.kw(move_arm=move_and_push))
        assert run.run.replans == 1, run.reason
        message = next(m for p, _, m in plant.phases if p == 'replanning')
        assert plant.pushed in message and 'mm from where the plan put it' in message
        assert run.success, run.reason
        assert to_take_apart(run.final_scene) == [] and run.lost == []
        assert run.drift[plant.pushed] == pytest.approx(0.03, abs=0.003)   # drift: what the push left


def test_a_block_missing_from_a_frame_is_looked_for_again_and_one_never_seen_is_lost(planner):
    """Nothing to take apart (the heap itself): no motion; the end's registration decides what is lost."""
    with World(HEAP, twin_world_config()) as world:
        twin = Twin(world)
        plant = Plant(twin)
        frames = []

        def register(drop=lambda n: n == 0):
            scene = twin.current_scene()
            frames.append(scene)
            return without_block(scene, 'b2') if drop(len(frames) - 1) else scene
        run = take_apart(twin.current_scene(), HEAP, local_place_planner(planner), **plant.kw(register=register))
        assert run.success and run.steps == [] and run.lost == [] and len(frames) == 2, run.reason
        assert set(run.drift) == {b.id for b in HEAP.blocks} and run.drift_stats()['max_mm'] < 0.5
        frames.clear()
        run = take_apart(twin.current_scene(), HEAP, local_place_planner(planner),
                         **plant.kw(register=lambda: register(drop=lambda n: True)))
        assert not run.success and run.lost == ['b2'] and run.reason == 'blocks lost: b2'
        assert len(frames) == 1 + TableConfig().recount and 'b2' not in run.drift
        assert run.document({})['take_apart']['lost'] == ['b2']


def without_block(scene, block_id):
    """The scene without one block (motion capture did not report its body)."""
    from rad_core.domain.scene import Scene
    doc = scene.to_dict()
    doc['blocks'] = [b for b in doc['blocks'] if b['id'] != block_id]
    return Scene.from_dict(doc)


def test_a_plan_that_cannot_be_made_says_why(built):
    scene, order = built

    def nothing_feasible(current, block_id, position, yaw, start):
        return MotionPlan(False, 'grasp', 'grasp: all 2 grasps blocked')
    plan = plan_take_apart(scene, HEAP, nothing_feasible, build_order=order)
    assert not plan.success and plan.steps == []
    assert plan.reason.startswith(f'no block can be taken off next ({len(order)} left')
    assert 'grasp: all 2 grasps blocked' in plan.reason
    with pytest.raises(RadError, match='max_spots'):
        plan_take_apart(scene, HEAP, nothing_feasible, config=TableConfig(max_spots=0))

"""A scene's feeder: blocks that arrive at a pick station instead of lying on the table.

Real parts throughout: the scene parser, PyBullet worlds, GAMP, CP-SAT and the twin."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from rad_core.domain.errors import RadError, SceneError
from rad_core.domain.scene import Scene, station_position
from rad_core.sequencing.planning.plan import moved

from scenes import U, doc

STATION = [0.45, -0.25]


def feeder_doc(order: str = 'request', **feeder) -> dict:
    """The core tests' default scene with every block in a feeder (positions left out)."""
    d = doc()
    for b in d['blocks']:
        b.pop('position')
        b.pop('yaw')
    d['feeder'] = {'station': STATION, 'blocks': [b['id'] for b in d['blocks']], 'order': order, **feeder}
    return d


@pytest.fixture(scope='module')
def fed() -> Scene:
    return Scene.from_dict(feeder_doc())


# ---- the scene format ------------------------------------------------------------------------

def test_a_block_in_the_feeder_has_its_pose_at_the_station(fed):
    i2 = fed.block('i0')
    assert i2.yaw == 0
    # An I2 at yaw 0 spans +x from its anchor: centred on the station, on the table.
    assert i2.position == pytest.approx((STATION[0] - U / 2, STATION[1], U / 2))
    assert fed.block('c0').position == pytest.approx((*STATION, U / 2))
    assert fed.feeder.available() == ('c0', 'c1', 'i0')
    again = Scene.loads(fed.dumps())
    assert again == fed and again.feeder == fed.feeder


@pytest.mark.parametrize('change, where, words', [
    (lambda d: d['feeder']['blocks'].append('nope'), 'feeder.blocks', "unknown block id 'nope'"),
    (lambda d: d['feeder']['blocks'].append('c0'), 'feeder.blocks', 'same block twice'),
    (lambda d: d['feeder'].update(order='fifo'), 'feeder.order', "'request', 'queue'"),
    (lambda d: d['feeder'].update(window=2), 'feeder.window', 'only a queue feeder'),
    (lambda d: d['feeder'].update(station=[0.4]), 'feeder.station', 'expected [x, y]'),
    (lambda d: d['blocks'][0].update(position=[0.1, 0.1, U / 2]), 'blocks[0].position', 'leave position out'),
    (lambda d: d['blocks'][2].update(yaw=90), 'blocks[2].yaw', 'presents it at yaw 0'),
    (lambda d: d['feeder'].update(station=[0.5, 0.1]), 'feeder.station', "stick into target region 'front'"),
])
def test_a_bad_feeder_is_refused_with_the_field_that_is_wrong(change, where, words):
    d = feeder_doc()
    change(d)
    with pytest.raises(SceneError) as e:
        Scene.from_dict(d)
    assert e.value.field == where and words in str(e.value), str(e.value)


def test_the_station_must_be_clear_of_the_blocks_on_the_table():
    d = doc()
    d['feeder'] = {'station': [0.4, -0.2], 'blocks': ['c1']}       # c0 lies there
    d['blocks'][1].pop('position')
    d['blocks'][1].pop('yaw')
    with pytest.raises(SceneError, match="block 'c0' lies on the feeder's station"):
        Scene.from_dict(d)


def test_a_block_placed_leaves_the_feeder(fed):
    after = moved(fed, 'c1', (0.45, 0.1, U / 2), 0)
    assert after.feeder.blocks == ('c0', 'i0') and after.block('c1').position == (0.45, 0.1, U / 2)


def test_a_queue_feeder_offers_its_first_blocks_only():
    q = Scene.from_dict(feeder_doc('queue', window=2))
    assert q.feeder.available() == ('c0', 'c1')
    assert moved(q, 'c0', (0.45, 0.1, U / 2), 0).feeder.available() == ('c1', 'i0')


# ---- the physics world and the twin -------------------------------------------------------------

def test_the_world_parks_feeder_blocks_and_presents_one_at_a_time(fed):
    from rad_core.sim.world import PARK_Z, World
    with World(fed) as world:
        assert world.parked == {'c0', 'c1', 'i0'}
        assert all(world.block_pose(b)[0][2] == pytest.approx(PARK_Z) for b in world.parked)
        saved = world.save()
        assert world.present('c0') and not world.present('c0')
        assert world.block_pose('c0')[0] == pytest.approx(fed.block('c0').position)
        world.step(240)                                   # presented: a body like any other, at rest
        assert world.block_pose('c0')[0] == pytest.approx(fed.block('c0').position, abs=1e-3)
        world.present('i0')                               # c0 was not taken: it goes back
        assert world.parked == {'c0', 'c1'} and world.presented == 'i0'
        world.restore(saved)
        assert world.parked == {'c0', 'c1', 'i0'} and world.presented is None
        world.step(240)                                   # parked blocks stay where they wait
        assert world.block_pose('i0')[0][2] == pytest.approx(PARK_Z)


def test_motion_capture_does_not_see_into_the_feeder_and_registration_keeps_its_blocks(fed):
    from rad_core.sim.twin import Twin
    from rad_core.sim.world import World
    with World(fed) as world:
        twin = Twin(world)
        assert twin.bodies() == []
        assert twin.current_scene() == fed                 # all still in the feeder
        twin.present('c1')
        assert [b.name for b in twin.bodies()] == ['c1']
        assert twin.current_scene().feeder.blocks == ('c0', 'c1', 'i0')   # presented, not taken
        world.set_block_pose('c1', (0.45, 0.1, U / 2))                    # taken and placed
        twin.settle(0.2)
        now = twin.current_scene()
        assert now.feeder.blocks == ('c0', 'i0') and now.block('c1').position == pytest.approx((0.45, 0.1, U / 2))
        with pytest.raises(RadError, match='not in the feeder'):
            twin.present('c1')
        with pytest.raises(RadError, match='unknown block'):
            twin.present('zz')


# ---- the generator -----------------------------------------------------------------------------

def test_the_generator_uses_a_feeder_where_the_table_cannot_hold_the_blocks():
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    with pytest.raises(RadError, match='do not fit on the table'):
        generate_scene(GeneratorConfig(grid=8, supply='table'), 0)
    big = generate_scene(GeneratorConfig(grid=8), 0)
    assert big.feeder is not None and set(big.feeder.blocks) == {b.id for b in big.blocks}
    small = generate_scene(GeneratorConfig(grid=4), 3)
    assert small.feeder is None
    fed = generate_scene(GeneratorConfig(grid=4, supply='feeder'), 3)
    assert fed.targets == small.targets and [b.type for b in fed.blocks] == [b.type for b in small.blocks]
    queue = generate_scene(GeneratorConfig(grid=4, supply='feeder', feeder_order='queue', feeder_window=2), 3)
    assert queue.feeder.available() == fed.feeder.blocks[:2]


# ---- planning and building from the feeder ------------------------------------------------------

def test_the_arm_aware_allocation_judges_a_feeder_block_where_it_is_presented(fed):
    from rad_core.allocation.arm import arm_filter
    from rad_core.allocation.placements import enumerate_candidates
    from rad_core.domain.grid import Grid
    grid = Grid(fed)
    _, counts, report = arm_filter(fed, grid, enumerate_candidates(fed, grid))
    assert counts == {'cube': 2, 'I2': 1, 'L3_up': 0} and not report.blocks
    far = Scene.from_dict({**feeder_doc(), 'feeder': {**feeder_doc()['feeder'], 'station': [0.95, -0.3]}})
    _, counts, report = arm_filter(far, Grid(far), enumerate_candidates(far, Grid(far)))
    assert sum(counts.values()) == 0 and 'cannot be picked where it lies' in report.blocks['c0']


def test_a_plan_picks_every_block_at_the_station_and_the_twin_builds_it(fed):
    from rad_core.domain.coverage import measured_coverage
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    from rad_core.sequencing.execution.twin_build import build_teleported
    planner = AgentPlanner('greedy')
    from rad_core.sim.world import World
    plan = planner(fed, None, 0)
    assert plan.success and plan.predicted_coverage == 1.0, plan.reason
    with World() as world:
        for step in plan.steps:
            # The first trajectory ends where the hand closes: over one of the block's units at the station.
            world.set_joint_positions(step.motion['trajectories'][0]['points'][-1]['positions'][:7])
            grasp = world.link_pose()[0]
            units = fed.unit_positions(fed.block(step.block))
            assert np.min(np.linalg.norm(units[:, :2] - grasp[:2], axis=1)) < 0.01, (step.block, grasp)
    registered = build_teleported(fed, plan.steps)
    assert measured_coverage(registered.scene) == 1.0 and not registered.set_aside
    assert set(registered.scene.feeder.blocks) == {'c0', 'c1', 'i0'} - {s.block for s in plan.steps}


def test_the_robot_mdp_takes_blocks_from_the_feeder(fed):
    from rad_core.env.mdp import Action
    from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
    with RobotAssemblyEnv(fed, RobotEnvConfig()) as env:
        env.reset()
        target = env.env.grid
        cell = int(np.flatnonzero(target.is_target)[0])
        result = env.step(Action(0, 0, cell, 0))              # c0 onto the first target cell
        assert not result.outcome.is_invalid, result.reason
        assert env.world.parked == {'c1', 'i0'}
        assert env.world.block_pose('c0')[0] == pytest.approx(target.centres[cell], abs=2e-3)


def test_execution_without_a_feeder_says_so():
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    from rad_core.sequencing.execution.execute import execute_assembly
    scene = Scene.from_dict(feeder_doc())
    planner = AgentPlanner('greedy')
    result = execute_assembly(scene, lambda s, q: planner(s, q, 0), lambda t: None, lambda c: None, lambda: scene)
    assert not result.success and 'has no feeder' in result.reason, result.reason


def test_the_feeder_doc_is_not_changed_by_parsing():
    d = feeder_doc()
    before = copy.deepcopy(d)
    Scene.from_dict(d)
    assert d == before
    # A generator writing positions gets the parser's own: the document with them parses the same.
    for b in d['blocks']:
        b['position'] = list(station_position(Scene.from_dict(before).block_types[b['type']], STATION, 0, U))
    assert Scene.from_dict(d) == Scene.from_dict(before)


# ---- the sequencer's actions ---------------------------------------------------------------------

def _two_cubes_feeder(order: str, **feeder) -> Scene:
    d = feeder_doc(order, **feeder)
    d['blocks'].append({'id': 'c2', 'type': 'cube'})
    d['feeder']['blocks'] = ['i0', 'c2', 'c0', 'c1']
    return Scene.from_dict(d)


def test_a_request_feeder_offers_one_block_of_each_type_its_blocks_being_alike():
    from rad_core.allocation.cpsat import solve
    from rad_core.allocation.guide import AllocationGuide
    from rad_core.env.mdp import AssemblyEnv
    scene = _two_cubes_feeder('request')
    result = solve(scene)
    env = AssemblyEnv(scene)
    guide = AllocationGuide(scene, result.placements, env.grid)
    offered = {scene.blocks[a.block].id for a in guide.allowed_actions(env.state)}
    assert offered == {'i0', 'c2'}                # the first cube waiting stands for the three
    cube = next(a for a in guide.allowed_actions(env.state)
                if scene.blocks[a.block].id == 'c2' and env.evaluate(a)[0] is None)
    assert not env.step(cube).outcome.is_invalid
    assert {scene.blocks[a.block].id for a in guide.allowed_actions(env.state)} == {'i0', 'c0'}


def test_a_queue_feeder_offers_its_window_and_the_mdp_refuses_a_block_behind_it():
    from rad_core.allocation.cpsat import solve
    from rad_core.allocation.guide import AllocationGuide
    from rad_core.env.mdp import Action, AssemblyEnv, Outcome
    scene = _two_cubes_feeder('queue', window=1)
    env = AssemblyEnv(scene)
    guide = AllocationGuide(scene, solve(scene).placements, env.grid)
    assert {scene.blocks[a.block].id for a in guide.allowed_actions(env.state)} == {'i0'}
    c0 = [b.id for b in scene.blocks].index('c0')
    cell = int(np.flatnonzero(env.grid.is_target)[0])
    outcome, reason, _, _ = env.evaluate(Action(c0, 0, cell, 0))
    assert outcome is Outcome.INVALID_BLOCK and "still in the feeder's queue (it offers i0 now)" in reason


# ---- large targets -------------------------------------------------------------------------------

def test_the_large_targets_have_50_to_100_blocks_in_a_feeder_enough_to_cover_them():
    from rad_core.domain.large_shapes import LARGE_SPECS, large_scene
    for name, spec in LARGE_SPECS.items():
        scene = large_scene(name)
        assert 45 <= len(scene.blocks) <= 100 and set(scene.feeder.blocks) == {b.id for b in scene.blocks}, name
        units = sum(scene.block_types[b.type].size for b in scene.blocks)
        spares = sum(scene.block_types[t].size for t in [b.type for b in scene.blocks][-spec.n_spare:])
        assert units - spares == scene.num_target_cells, name       # an exact tiling plus the spares


def test_a_cavity_wall_has_two_leaves_a_finger_apart_each_tiled_on_its_own():
    from rad_core.domain.large_shapes import CAVITY, FLUSH, LARGE_SPECS, large_scene
    scene = large_scene('cavity_wall')
    (region,) = scene.targets
    depths = sorted({int(c[1]) for c in region.filled})
    assert depths == [0, CAVITY + 1] and CAVITY * scene.unit >= 0.08 - 1e-9     # room for a finger
    leaf = sorted((int(i), int(k)) for i, j, k in region.filled if j == 0)
    assert leaf == sorted((int(i), int(k)) for i, j, k in region.filled if j == CAVITY + 1)
    assert set(FLUSH) < set(LARGE_SPECS) and all(len(large_scene(n).targets) == 2 for n in FLUSH)


def test_a_coursed_tiling_spans_a_two_cell_opening_with_a_lintel_resting_on_both_sides():
    from rad_core.domain.large_shapes import coursed_tiling
    from rad_core.domain.shapes import face
    _, cells = face('######',
                    '#..###',
                    '#..###')
    kinds = coursed_tiling(cells)
    assert kinds.count('bar4') == 1
    sizes = {'cube': 1, 'I2': 2, 'I3': 3, 'bar4': 4}
    assert sum(sizes[k] for k in kinds) == len(cells)


def test_a_result_document_keeps_what_is_left_in_the_feeder(fed):
    from rad_core.sequencing.execution.result import final_scene, result_document
    after = moved(fed, 'c1', (0.45, 0.1, U / 2), 0)
    result = result_document(fed, None, [], after, {})
    assert result['final_feeder']['blocks'] == ['c0', 'i0']
    assert final_scene(result) == after and final_scene(result).feeder == after.feeder
    table = Scene.from_dict(doc())
    assert 'final_feeder' not in result_document(table, None, [], table, {})

"""The faults of a real cell in the twin (rad_core.sim.faults), and the execute / verify / replan loop
that survives them.

Everything is real: PyBullet physics and contact grasps in the twin, CP-SAT allocation, GAMP motion.
A fault that must happen is forced with probability 1.0 and, where one occurrence is enough, switched
off again after its first event (`Once`), so the run shows the recovery rather than a wall of faults.
"""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_of_quaternion
from rad_core.gamp.action import MotionPlanner
from rad_core.sequencing import HeurPolicy
from rad_core.sequencing.execution.execute import ExecuteConfig, execute_assembly
from rad_core.sequencing.execution.result import deviation
from rad_core.sequencing.planning.plan import local_motion_planner, plan_assembly
from rad_core.sim.faults import KINDS, FaultConfig
from rad_core.sim.twin import Twin, TwinConfig, twin_world_config
from rad_core.sim.world import World

from scenes import U, scene

SCENE = generate_scene(GeneratorConfig(grid=3), 1)


# ---- FaultConfig ---------------------------------------------------------------------------------------

def test_faults_are_off_by_default_and_realistic_is_as_documented():
    assert not FaultConfig().active() and FaultConfig.none() == FaultConfig()
    assert FaultConfig.none().describe() == 'no faults'
    r = FaultConfig.realistic(seed=7)
    assert r.active() and r.seed == 7
    assert (r.mocap_position_noise, r.mocap_yaw_noise_deg, r.drop_body, r.drop_frame, r.placement_error, r.slip,
            r.miss, r.nudge) == (0.001, 0.5, 0.02, 0.01, 0.002, 0.05, 0.02, 0.05)
    assert FaultConfig(**r.to_dict()) == r
    assert FaultConfig(slip=0.1).active() and 'slip=0.1' in FaultConfig(slip=0.1).describe()


@pytest.mark.parametrize('bad, field', [({'slip': 1.5}, 'slip'), ({'drop_frame': -0.1}, 'drop_frame'),
                                        ({'miss': math.nan}, 'miss'), ({'mocap_position_noise': -1e-3},
                                                                       'mocap_position_noise'),
                                        ({'placement_error': math.inf}, 'placement_error'),
                                        ({'nudge': True}, 'nudge'), ({'seed': -1}, 'seed'),
                                        ({'mocap_yaw_noise_deg': '1'}, 'mocap_yaw_noise_deg')])
def test_fault_settings_are_checked(bad, field):
    with pytest.raises(RadError, match=field):
        FaultConfig(**bad)


def test_fault_files_json_and_yaml_and_the_spec(tmp_path):
    js = tmp_path / 'f.json'
    js.write_text(json.dumps({'slip': 0.2, 'mocap_position_noise': 0.0005}))
    assert FaultConfig.from_file(js) == FaultConfig(slip=0.2, mocap_position_noise=0.0005)
    ym = tmp_path / 'f.yaml'
    ym.write_text('seed: 3\nmiss: 0.5\nnudge_distance: 0.01\n')
    assert FaultConfig.parse(str(ym), seed=9) == FaultConfig(seed=3, miss=0.5, nudge_distance=0.01)
    assert FaultConfig.parse(str(js), seed=9).seed == 9                   # the file has none: the given one
    assert FaultConfig.parse('none', 4) == FaultConfig(seed=4)
    assert FaultConfig.parse('realistic', 4) == FaultConfig.realistic(4)
    bad = tmp_path / 'bad.json'
    bad.write_text(json.dumps({'slip': 0.1, 'teleport': 1.0, 'gremlins': 2}))
    with pytest.raises(RadError, match='unknown fault setting.*gremlins, teleport'):
        FaultConfig.from_file(bad)
    bad.write_text('{"slip": ')
    with pytest.raises(RadError, match='not valid JSON'):
        FaultConfig.from_file(bad)
    with pytest.raises(RadError, match='none, realistic or a JSON/YAML file'):
        FaultConfig.parse(str(tmp_path / 'missing.yaml'))
    ym.write_text('- just\n- a list\n')
    with pytest.raises(RadError, match='expected a mapping'):
        FaultConfig.from_file(ym)


# ---- motion capture as the twin reports it -----------------------------------------------------------------

def _twin(faults: FaultConfig, s=None) -> Twin:
    return Twin(World(s or scene()), TwinConfig(faults=faults))


def test_mocap_noise_has_the_configured_spread_and_is_seeded():
    twin = _twin(FaultConfig(seed=5, mocap_position_noise=0.001, mocap_yaw_noise_deg=0.5))
    exact = {b.name: b for b in twin.bodies(exact=True)}
    frames = [twin.bodies() for _ in range(300)]
    errs = np.array([[np.subtract(b.position, exact[b.name].position) for b in f] for f in frames]).reshape(-1, 3)
    yaws = np.array([[yaw_of_quaternion(b.quaternion) - yaw_of_quaternion(exact[b.name].quaternion) for b in f]
                     for f in frames]).ravel()
    yaws = (yaws + 180) % 360 - 180
    assert np.allclose(errs.std(axis=0), 0.001, rtol=0.1) and np.allclose(errs.mean(axis=0), 0, atol=2e-4)
    assert yaws.std() == pytest.approx(0.5, rel=0.1)
    assert twin.fault_counts['noise'] == 300 * len(exact)
    # Registration snaps heights and yaws; x/y on the table are what the tracker says (within a few sigma).
    seen = twin.current_scene()
    assert [(b.id, b.position[2], b.yaw) for b in seen.blocks] == [(b.id, b.position[2], b.yaw) for b in scene().blocks]
    assert np.allclose([b.position for b in seen.blocks], [b.position for b in scene().blocks], atol=0.005)
    # Seeded, and each fault kind on its own stream: turning another fault on does not change the noise.
    again = _twin(FaultConfig(seed=5, mocap_position_noise=0.001, mocap_yaw_noise_deg=0.5, drop_frame=0.5))
    assert again.bodies() == frames[0]
    assert _twin(FaultConfig(seed=6, mocap_position_noise=0.001)).bodies() != frames[0]


def test_a_dropped_body_keeps_its_last_pose_and_registration_does_not_lose_it():
    twin = _twin(FaultConfig(drop_body=1.0))
    first = twin.bodies()                                 # nothing reported yet: nothing to hold, all tracked
    assert all(b.tracking_valid for b in first)
    twin.world.set_block_pose('c0', [0.3, -0.3, U / 2])
    dropped = twin.bodies()
    assert not any(b.tracking_valid for b in dropped)
    assert [b.position for b in dropped] == [b.position for b in first]     # the last reported poses
    assert twin.current_scene().block('c0').position == pytest.approx((0.4, -0.2, U / 2))
    assert twin.fault_counts['drop_body'] > len(first)        # registration waited frames for them in vain


def test_dropped_frames_are_drawn_for_the_node_and_every_fault_kind_is_counted():
    twin = _twin(FaultConfig(seed=1, drop_frame=0.3))
    assert set(twin.fault_counts) == set(KINDS)
    assert 0.15 < np.mean([twin.drop_frame() for _ in range(400)]) < 0.45
    twin.config = replace(twin.config, faults=FaultConfig(drop_frame=1.0))
    counted = twin.fault_counts['drop_frame']
    assert all(twin.drop_frame() for _ in range(5)) and twin.fault_counts['drop_frame'] == counted + 5
    twin.config = replace(twin.config, faults=FaultConfig())
    assert not any(twin.drop_frame() for _ in range(50))


def test_deviation_names_set_aside_and_reappearing_blocks():
    s = scene()
    without = s.to_dict()
    without['blocks'] = without['blocks'][1:]
    fewer = Scene.from_dict(without)
    assert deviation(s, fewer, 0.005, {'c0': 'tilted'}) == 'block c0 cannot be registered: tilted'
    assert deviation(s, fewer, 0.005) == 'block c0 is not seen by motion capture'
    assert deviation(fewer, s, 0.005) == 'block c0 is seen again (it was not in the plan)'


# ---- the loop under faults ----------------------------------------------------------------------------

@pytest.fixture(scope='module')
def motion():
    planner = MotionPlanner()
    yield local_motion_planner(planner)
    planner.close()


class Cell:
    """The twin with faults as the plant of execute_assembly, registering leniently (register_world)."""

    def __init__(self, motion, faults: FaultConfig, once: str | None = None):
        self.world = World(SCENE, twin_world_config())     # the twin node's world (sim.twin.BLOCK_PLAY)
        self.twin = Twin(self.world, TwinConfig(faults=faults))
        self.motion, self.once, self.plans = motion, once, []

    def _after(self):
        """Switch the `once` fault off after it happened (it is forced with probability 1)."""
        if self.once and self.twin.fault_counts[self.once]:
            self.twin.config = replace(self.twin.config, faults=replace(self.twin.config.faults, **{self.once: 0.0}))

    def plan(self, scene, start):
        self.plans.append(scene)
        return plan_assembly(scene, solve, self.motion, HeurPolicy(), seed=1, start=start)

    def move_arm(self, trajectory):
        report = self.twin.execute(trajectory)
        self._after()
        if report.error_code:
            raise RadError(f'aborted ({report.error_code}): {report.error_string}')

    def move_gripper(self, command):
        result = self.twin.execute_gripper(command)
        self._after()
        return result

    def run(self, **kw):
        config = ExecuteConfig(settle_s=0.3, mocap_noise=self.twin.config.faults.mocap_position_noise, **kw)
        result = execute_assembly(SCENE, self.plan, self.move_arm, self.move_gripper, self.twin.registration,
                                  config, joints=self.world.joint_positions, settle=self.twin.settle)
        self.world.close()
        return result


def test_a_slipped_block_falls_and_is_picked_again(motion):
    cell = Cell(motion, FaultConfig(seed=3, slip=1.0), once='slip')
    result = cell.run()
    slip = next(e for e in cell.twin.fault_events if e['fault'] == 'slip')
    assert cell.twin.fault_counts['slip'] == 1
    # It fell: the loop saw the block far from where the plan put it, replanned from the measured world,
    # picked it again from where it lay and finished the target.
    assert result.replans == 1 and len(result.faults) == 1 and result.recovered_faults == 1
    assert slip['block'] in result.faults[0]['problem'] and 'from where the plan put it' in result.faults[0]['problem']
    assert cell.plans[1].block(slip['block']).position != SCENE.block(slip['block']).position
    assert result.success and result.coverage == 1.0 and result.lost_blocks == {}
    doc = result.document({})['execution']
    assert doc['replans'] == 1 and doc['recovered_faults'] == 1 and doc['lost_blocks'] == {}
    assert doc['planned_coverage'] == 1.0


def test_a_missed_grasp_opens_backs_out_and_replans(motion):
    cell = Cell(motion, FaultConfig(miss=1.0), once='miss')
    result = cell.run()
    assert cell.twin.fault_counts['miss'] == 1
    assert 'nothing is held' in result.steps[0]['failure'] and result.faults[0]['recovered']
    assert result.replans == 1 and result.success and result.coverage == 1.0


def test_a_miss_every_time_ends_with_the_reason_after_max_replans(motion):
    cell = Cell(motion, FaultConfig(miss=1.0))
    result = cell.run(max_replans=1)
    assert not result.success and 'nothing is held' in result.reason
    assert [f['recovered'] for f in result.faults] == [True, False] and cell.twin.fault_counts['miss'] == 2


def test_placement_errors_noise_and_dropped_bodies_at_realistic_levels_are_absorbed(motion):
    faults = FaultConfig(seed=2, placement_error=0.002, mocap_position_noise=0.001, mocap_yaw_noise_deg=0.5,
                         drop_body=0.3)
    cell = Cell(motion, faults)
    result = cell.run()
    counts = cell.twin.fault_counts
    assert counts['placement'] == len(result.steps) and counts['drop_body'] >= 1 and counts['noise'] > 0
    moved = [np.hypot(*e['offset']) for e in cell.twin.fault_events if e['fault'] == 'placement']
    assert max(moved) > 5e-4 and all(m < 0.01 for m in moved)
    # A few millimetres off in a region still registers on the cell; noise is not a deviation.
    assert result.success and result.coverage == 1.0 and result.replans == 0 and result.faults == []


def test_a_neighbour_nudged_a_few_millimetres_is_absorbed(motion):
    cell = Cell(motion, FaultConfig(nudge=1.0), once='nudge')
    result = cell.run()
    nudge = next(e for e in cell.twin.fault_events if e['fault'] == 'nudge')
    assert nudge['distance'] > 0 and nudge['block'] != nudge['by']
    assert result.success and result.coverage == 1.0 and result.replans == 0


def test_a_block_pushed_off_its_cell_is_lost_and_its_cells_are_left_out_of_the_plan(motion):
    cell = Cell(motion, FaultConfig(nudge=1.0, nudge_distance=0.02), once='nudge')
    result = cell.run()
    nudge = next(e for e in cell.twin.fault_events if e['fault'] == 'nudge')
    assert set(result.lost_blocks) == {nudge['block']} and 'off its grid' in result.lost_blocks[nudge['block']]
    assert result.faults[0]['problem'].startswith(f'block {nudge["block"]} cannot be registered')
    assert result.faults[0]['recovered'] and result.replans == 1
    # The replan neither counts on nor places into the cells the pushed block occupies ...
    blocked = {name: {tuple(c) for c in cells} for name, cells in result.blocked_cells.items()}
    assert blocked and all(not blocked.get(t.name, set()) & set(t.filled) for t in cell.plans[1].targets)
    # ... and nothing is counted as built that is not registered on its cells.
    assert result.final_scene.targets == SCENE.targets and result.coverage < 1.0
    assert not result.success and f'lost blocks: {nudge["block"]}' in result.reason
    assert result.planned_coverage == 1.0
    assert nudge['block'] not in {b.id for b in result.final_scene.blocks}
    assert result.document({})['execution']['lost_blocks'] == result.lost_blocks



@pytest.mark.parametrize('victim, built', [('b3', True), ('b1', False)])
def test_a_block_knocked_on_its_side_is_lost_and_the_run_succeeds_only_if_it_builds_what_was_planned(motion, victim,
                                                                                                      built):
    """After the first step a table block is tipped onto its side (by hand: a fault on demand). It cannot be in a
    scene: registration sets it aside, the loop replans without it. The other cube can stand in for b3; nothing
    can for the I2_up b1, so that run ends short of the first plan's coverage and says why."""
    cell = Cell(motion, FaultConfig())
    move_arm, moves = cell.move_arm, []

    def move_and_tip(trajectory):
        move_arm(trajectory)
        moves.append(trajectory)
        if len(moves) == 3:
            pos, _ = cell.world.block_pose(victim)
            cell.world.set_block_pose(victim, pos, [math.sqrt(0.5), 0, 0, math.sqrt(0.5)])   # 90 deg about x
            cell.twin.settle(0.5)
    cell.move_arm = move_and_tip
    result = cell.run()
    assert set(result.lost_blocks) == {victim} and 'tilted 90.0 deg' in result.lost_blocks[victim]
    assert result.faults[0]['problem'].startswith(f'block {victim} cannot be registered') and result.replans == 1
    assert victim not in {b.id for b in cell.plans[1].blocks} and result.blocked_cells == {}
    assert result.planned_coverage == 1.0 and result.success == built and (result.coverage == 1.0) == built
    if built:
        assert result.reason.startswith(f'built without 1 lost block(s): {victim}')
    else:
        assert result.reason.startswith(f'coverage {result.coverage:.3f} is below the 1.000 the first plan')
        assert f'lost blocks: {victim}' in result.reason


ROW = Scene.from_dict({
    'format': 'rad-scene/1', 'unit': U, 'block_types': {'cube': [[0, 0, 0]]},
    'blocks': [{'id': 'p', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0},
               {'id': 'q', 'type': 'cube', 'position': [0.5, -0.2, U / 2], 'yaw': 0}],
    'targets': [{'name': 'row', 'origin': [0.45, 0.1, U / 2], 'size': [2, 1, 1], 'filled': [[0, 0, 0], [1, 0, 0]]}]})


@pytest.mark.parametrize('refresh', [True, False])
def test_a_block_left_2mm_into_its_neighbours_cell_is_built_against_not_onto(motion, refresh):
    """The first block is left 2 mm into the other cell (a placement error, forced). Registration snaps
    it onto its cell and keeps the offset; with plan_motion the second block's motion is planned again
    against it and set down flush beside it. Without, the plan's motion lowers the block onto its edge
    (in a free row it shoves the first back; in a structure it jams and the controller aborts)."""
    from rad_core.cell.trajectory import TrajectoryAborted
    from rad_core.sim.twin import Tolerances
    world = World(ROW, twin_world_config())
    twin = Twin(world)
    shoved = {}

    def move_arm(trajectory):
        report = twin.execute(trajectory, tolerances=Tolerances(path=0.05, goal=0.01, goal_time=1.0))
        if report.error_code:
            raise TrajectoryAborted(report.error_code, f'aborted: {report.error_string}')

    def move_gripper(command):
        result = twin.execute_gripper(command)
        if command.action == 'release' and not shoved:
            for bid in ('p', 'q'):
                pos, quat = world.block_pose(bid)
                if abs(pos[1] - 0.1) < 0.01:
                    toward = 1.0 if pos[0] < 0.475 else -1.0       # into the other cell
                    world.set_block_pose(bid, [pos[0] + toward * 0.002, pos[1], pos[2]], quat)
                    shoved[bid] = toward
        return result

    def plan(scene, start):
        return plan_assembly(scene, solve, motion, HeurPolicy(), seed=1, start=start)

    result = execute_assembly(ROW, plan, move_arm, move_gripper, twin.registration, ExecuteConfig(settle_s=0.3),
                              joints=world.joint_positions, settle=twin.settle,
                              plan_motion=motion if refresh else None)
    (first, toward), = shoved.items()
    second = 'q' if first == 'p' else 'p'
    assert result.success and result.coverage == 1.0, result.reason
    x = world.block_pose(second)[0][0]
    nominal = 0.5 if first == 'p' else 0.45
    if refresh:
        assert result.replans == 0 and result.faults == []
        assert result.final_scene.measured_offsets[first][0] == pytest.approx(toward * 0.002, abs=2e-4)
        # Set down flush against the first block: 2 mm over, less the twin's play between them.
        assert toward * (x - nominal) > 0.0008
    else:
        # Lowered at its cell onto the first block's edge: here (a free row) it shoves the first block back.
        assert toward * (x - nominal) < 0.0008
        assert abs(result.final_scene.measured_offsets.get(first, (0, 0))[0]) < 0.0018
    world.close()


def test_a_block_found_turned_on_the_table_is_picked_where_it_lies_and_built_straight(motion):
    """A block that slipped lands anyhow: flat on the table, 30 degrees off the lattice. Registration
    keeps it (at the nearest yaw, the turn as its measured offset) and GAMP grasps it as it lies."""
    from rad_core.cell.trajectory import TrajectoryAborted
    from rad_core.domain.transforms import yaw_quaternion
    from rad_core.sim.twin import Tolerances
    world = World(ROW, twin_world_config())
    twin = Twin(world)
    world.set_block_pose('q', [0.5, -0.2, U / 2], yaw_quaternion(30.0))
    twin.settle(0.2)
    seen = twin.registration()
    assert seen.set_aside == {} and seen.scene.turn('q') == pytest.approx(30.0, abs=0.5)

    def move_arm(trajectory):
        report = twin.execute(trajectory, tolerances=Tolerances(path=0.05, goal=0.01, goal_time=1.0))
        if report.error_code:
            raise TrajectoryAborted(report.error_code, f'aborted: {report.error_string}')

    def plan(scene, start):
        return plan_assembly(scene, solve, motion, HeurPolicy(), seed=1, start=start)

    result = execute_assembly(seen.scene, plan, move_arm, twin.execute_gripper, twin.registration,
                              ExecuteConfig(settle_s=0.3), joints=world.joint_positions, settle=twin.settle,
                              plan_motion=motion)
    assert result.success and result.coverage == 1.0 and result.lost_blocks == {}, result.reason
    yaw = yaw_of_quaternion(world.block_pose('q')[1]) % 90
    assert min(yaw, 90 - yaw) < 2.0 and 'q' not in result.final_scene.measured_offsets
    world.close()

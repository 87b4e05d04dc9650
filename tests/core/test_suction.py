"""The vacuum gripper (issue 40): the cup on a unit's top face, its URDF, GAMP's plans, the twin's seal,
the Vacuum / DropOff commands with every result checked, and the allocation that knows it."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from rad_core.allocation.arm import HandBlocked
from rad_core.allocation.order import scene_state
from rad_core.allocation.supply import SupplyParams, choose_blocks
from rad_core.cell import panda
from rad_core.cell.motion import GripperCommand, GripperResult, Motion, run_motion
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.errors import RadError
from rad_core.domain.scene import TargetRegion
from rad_core.experiment.evaluation import evaluate
from rad_core.gamp import plan_action
from rad_core.gamp.grasps import Grasp, cup_fits, suction_grasps
from rad_core.gamp.planner import GampConfig
from rad_core.sim.faults import FaultConfig
from rad_core.sim.twin import Twin, TwinConfig, twin_world_config
from rad_core.sim.world import World, WorldConfig

from box_scenes import BOX, box_but_one

SUCTION = GampConfig(effector='suction')
SET_DOWN = GampConfig(drop=False)
"""The hand setting blocks down only: it may drop a block where the cup sets it down (tests/core/test_drop.py)."""
SUCTION_WORLD = WorldConfig(effector='suction')


# ---- which faces the cup takes -------------------------------------------------------------------

def test_the_cup_takes_the_top_face_of_every_unit_with_nothing_of_its_block_above():
    lib = DEFAULT_LIBRARY
    assert suction_grasps(lib['cube'], 0.04) == (Grasp(0, 0),)
    assert {g.unit for g in suction_grasps(lib['I2_up'], 0.04)} == {1}          # the upper unit only
    assert {g.unit for g in suction_grasps(lib['T4'], 0.04)} == {0, 1, 2, 3}    # flat: all four
    assert suction_grasps(lib['T4'], 0.04)[0] == Grasp(1, 0)                     # nearest the centre of mass
    assert {g.unit for g in suction_grasps(lib['L3_up'], 0.04)} == {1, 2}


def test_the_cup_needs_a_face_wider_than_its_rim_with_a_margin():
    # A 20 mm cup with 1 mm to spare: faces of 22 mm and more.
    assert cup_fits(0.022) and not cup_fits(0.021)
    assert cup_fits(0.03, clearance=0.2) and not cup_fits(0.025, clearance=0.2)     # 24 mm vs 20 mm faces
    assert suction_grasps(DEFAULT_LIBRARY['cube'], 0.02) == ()


def test_the_vacuum_gripper_urdf_has_a_housing_and_a_cup_and_no_fingers():
    root = ET.parse(panda.urdf_path('suction')).getroot()
    links = {link.get('name'): link for link in root.iter('link')}
    assert not links['panda_leftfinger'].findall('collision') and not links['panda_leftfinger'].findall('visual')
    shapes = [c.find('geometry')[0].tag for c in links['panda_hand'].findall('collision')]
    assert shapes == ['box', 'cylinder']
    tcp = next(j for j in root.iter('joint') if j.get('name') == 'panda_grasptarget_hand')
    assert float(tcp.find('origin').get('xyz').split()[2]) == pytest.approx(panda.SUCTION_TCP)
    with pytest.raises(RadError, match='effector must be one of hand, suction'):
        panda.urdf_path('magnet')
    with World(config=SUCTION_WORLD) as world:
        # The joint vector stays 9 long; the cup's lip is SUCTION_TCP below the flange.
        assert len(world.joint_positions()) == 9
        p = world.pybullet
        hand = p.getLinkState(world.robot, world.hand_link, physicsClientId=world.client)[4]
        lip = p.getLinkState(world.robot, world.ee_link, physicsClientId=world.client)[4]
        assert np.linalg.norm(np.subtract(hand, lip)) == pytest.approx(panda.SUCTION_TCP, abs=1e-6)


# ---- GAMP and the twin -----------------------------------------------------------------------------

@pytest.fixture(scope='module')
def box_last():
    """The solid 4 x 2 x 2 box at a 4 cm unit but its last block: the hand cannot set it down (its rows
    are 80 mm, wider than the open hand takes; it can drop it), the cup can."""
    unit = 0.04
    scene = box_but_one(unit)
    place = (BOX[0] + unit, BOX[1], 1.5 * unit)
    with World(scene) as world:
        hand = plan_action(world, 'm', place, 90, config=SET_DOWN)
    with World(scene, SUCTION_WORLD) as world:
        cup = plan_action(world, 'm', place, 90, config=SUCTION)
    return scene, place, hand, cup


def test_the_last_block_of_a_solid_box_is_set_down_by_the_cup_not_the_hand(box_last):
    _, _, hand, cup = box_last
    assert not hand.success and 'finger hits' in hand.reason
    assert cup.success, cup.reason
    actions = [g.action for g in cup.motion.gripper]
    assert actions == ['vacuum', 'drop_off']
    vacuum = cup.motion.gripper[0]
    assert (vacuum.vacuum, vacuum.timeout_ms) == (SUCTION.vacuum, SUCTION.vacuum_timeout_ms)
    assert GripperCommand.from_dict(vacuum.to_dict()).to_dict() == vacuum.to_dict()


def test_the_twin_seals_carries_and_drops_off_the_block(box_last):
    scene, place, _, cup = box_last
    with World(scene, twin_world_config(SUCTION_WORLD)) as world:
        twin = Twin(world)
        assert twin.execute_motion(cup.motion) == ''
        twin.settle(0.3)
        assert twin.attached is None
        assert np.linalg.norm(world.block_pose('m')[0] - place) < 0.004


def test_a_vacuum_on_nothing_fails_with_its_reason_and_the_step_backs_out(box_last):
    scene, _, _, cup = box_last
    with World(scene, twin_world_config(SUCTION_WORLD)) as world:
        twin = Twin(world)
        # The cup in the air at home: no seal, the action's success false, its error says why.
        got = twin.execute_gripper(GripperCommand('vacuum', panda.FINGER_OPEN, 0.0, 0, vacuum=50, timeout_ms=100))
        assert not got.reached_goal and 'touches no block' in got.error
        assert twin.attached is None
    with World(scene, twin_world_config(SUCTION_WORLD)) as world:
        # A vacuum that misses (the seal leaks): the motion stops at the vacuum and says so.
        twin = Twin(world, TwinConfig(faults=FaultConfig(miss=1.0)))
        reason = twin.execute_motion(cup.motion)
        assert reason.startswith('grasp failed: the vacuum did not hold the block: ') and 'leaks' in reason
        assert twin.attached is None
        with pytest.raises(RadError, match='not a hand'):
            twin.execute_gripper(GripperCommand('open', 0.04, 20.0, 0))


def test_the_hand_twin_refuses_vacuum_commands():
    with World() as world:
        with pytest.raises(RadError, match='not a vacuum gripper'):
            Twin(world).execute_gripper(GripperCommand('drop_off', 0.04, 0.0, 0, timeout_ms=100))


def test_run_motion_checks_every_vacuum_result_and_drops_off_after_a_failed_one():
    motion = Motion([], [GripperCommand('vacuum', 0.04, 0.0, 0, vacuum=50, timeout_ms=100)])
    sent = []

    def gripper(command):
        sent.append(command.action)
        return GripperResult(0.04, reached_goal=False, error='part not present')
    assert run_motion(motion, lambda t: None, gripper) == \
        'grasp failed: the vacuum did not hold the block: part not present'
    assert sent == ['vacuum', 'drop_off']
    with pytest.raises(RadError, match='int8'):
        GripperCommand.from_dict({'action': 'vacuum', 'position': 0.04, 'max_effort': 0, 'before': 0,
                                  'vacuum': 300, 'timeout_ms': 100})


def test_gamp_refuses_a_world_that_carries_another_effector():
    scene = box_but_one(0.04)
    with World(scene) as world, pytest.raises(RadError, match='carries the hand'):
        plan_action(world, 'm', (0.5, 0.0, 0.02), 0, config=SUCTION)


# ---- the allocation knows the cup ----------------------------------------------------------------

def test_the_hand_model_of_the_cup_needs_nothing_beside_the_block():
    unit = 0.04
    scene = box_but_one(unit)
    grid, occupied = scene_state(scene)
    last = grid.lookup(np.array([[BOX[0] + unit, BOX[1] + j * unit, 1.5 * unit] for j in range(2)]))
    assert HandBlocked(scene, grid, SET_DOWN).blocked('I2', 90, last, occupied)
    assert not HandBlocked(scene, grid, SUCTION).blocked('I2', 90, last, occupied)


def test_supply_at_4_cm_finds_a_box_the_cup_places_whole_and_the_hand_does_not():
    unit = 0.04
    box = TargetRegion('t', (BOX[0], BOX[1], unit / 2), (4, 2, 2),
                       tuple((i, j, k) for i in range(4) for j in range(2) for k in range(2)))
    types = {'I2': DEFAULT_LIBRARY['I2'], 'cube': DEFAULT_LIBRARY['cube']}
    _, hand = choose_blocks([box], unit, types, params=SupplyParams(time_limit_s=10.0, drop=False))
    _, cup = choose_blocks([box], unit, types, params=SupplyParams(time_limit_s=10.0, effector='suction'))
    assert hand.hand_covered == 14 and len(hand.hand_left) == 2
    assert all('ways of being held' in d['why'] for d in hand.hand_left)
    assert 'ways of being held' in hand.summary()
    assert cup.hand_covered == 16 and cup.hand_left == ()


def test_the_solid_box_is_built_whole_by_the_cup_in_a_simulated_twin():
    from rad_core.allocation.supply import supply
    from rad_core.domain.voxels import Model, place_regions

    unit = 0.04
    targets = place_regions([Model('box', '', np.ones((4, 2, 2), dtype=bool))], unit)
    scene, report = supply(targets, unit, dict(DEFAULT_LIBRARY), params=SupplyParams(time_limit_s=20.0,
                                                                                     effector='suction'))
    assert report.hand_covered == 16
    got = evaluate('default', [('box', scene)], True, 0, execution='simulate', effector='suction')
    row = got['scenes'][0]
    assert row['coverage'] == 1.0 and row['outcome'] == 'completed' and got['f'] == 0, row
    assert math.isfinite(row['return'])

"""The hand's drop (issue 40): a block whose neighbours at its level are built on both sides is held by its
top and let go over its place, the fingers above those neighbours (`GampConfig.drop`, on by default)."""

import numpy as np
import pytest
from rad_core.allocation.arm import HandBlocked
from rad_core.allocation.order import hand_order, scene_state
from rad_core.allocation.placements import Placement
from rad_core.domain.scene import Scene
from rad_core.gamp import plan_action
from rad_core.gamp.grasps import DROP_CLEAR, DROP_GRIP, DROP_HEIGHT, TIP_BELOW, drop_lift
from rad_core.gamp.planner import GampConfig, drop_styles
from rad_core.sim.twin import Twin, twin_world_config
from rad_core.sim.world import World

from box_scenes import BOX, box_but_one

SET_DOWN = GampConfig(drop=False)
UNIT = 0.04      # the box's rows are 80 mm: no wide grasp takes them, only a drop finishes it
PLACE = (BOX[0] + UNIT, BOX[1], 1.5 * UNIT)


def test_a_drop_holds_the_top_of_the_unit_and_lets_go_with_the_fingertips_over_its_level():
    for height in (0.02, 0.03, 0.04, 0.05):
        lift = drop_lift(height)
        tips = lift - TIP_BELOW                     # the fingertips' bottom, over the held unit's centre
        assert height / 2 - tips == pytest.approx(DROP_GRIP)       # the pads on the unit's top DROP_GRIP
        # Let go DROP_HEIGHT over its place: the tips DROP_CLEAR over the placed unit's top.
        assert tips + DROP_HEIGHT - height / 2 == pytest.approx(DROP_CLEAR)
    (open_f, lift), = drop_styles(0.04, 0.04)
    assert lift == drop_lift(0.04) and open_f == pytest.approx(0.02 + GampConfig().tight_finger_clearance)


@pytest.fixture(scope='module')
def last_block():
    scene = box_but_one(UNIT)
    with World(scene) as world:
        set_down = plan_action(world, 'm', PLACE, 90, config=SET_DOWN)
        dropped = plan_action(world, 'm', PLACE, 90)
    return scene, set_down, dropped


def test_the_last_block_of_a_solid_box_the_hand_cannot_set_down_is_dropped(last_block):
    _, set_down, dropped = last_block
    assert not set_down.success and 'finger hits block' in set_down.reason
    assert dropped.success, dropped.reason
    assert dropped.drop == DROP_HEIGHT and set_down.drop == 0.0
    # The fingers open once at the placement, with the hand DROP_HEIGHT over where setting down puts it.
    assert [g.action for g in dropped.motion.gripper].count('open') >= 1


def test_the_twin_lets_the_dropped_block_fall_into_its_place(last_block):
    scene, _, dropped = last_block
    with World(scene, twin_world_config()) as world:
        before = {b: world.block_pose(b)[0] for b in world.blocks if b != 'm'}
        twin = Twin(world)
        assert twin.execute_motion(dropped.motion) == ''
        twin.settle(0.5)
        assert twin.attached is None
        position, quaternion = world.block_pose('m')
        assert np.linalg.norm(position - PLACE) < 0.002
        assert abs(quaternion[0]) < 0.01 and abs(quaternion[1]) < 0.01          # flat, not tilted
        assert max(np.linalg.norm(world.block_pose(b)[0] - p) for b, p in before.items()) < 0.001


def test_the_hand_model_counts_the_drop_and_its_cells_are_those_over_the_level():
    scene = box_but_one(UNIT)
    grid, occupied = scene_state(scene)
    last = grid.lookup(np.array([[BOX[0] + UNIT, BOX[1] + j * UNIT, 1.5 * UNIT] for j in range(2)]))
    assert HandBlocked(scene, grid, SET_DOWN).blocked('I2', 90, last, occupied)
    hand = HandBlocked(scene, grid)
    assert not hand.blocked('I2', 90, last, occupied)
    # The drop's blocking offsets: none at the held unit's own level beside it, some a level up.
    offsets = hand.offsets(0)
    assert not any(k == 0 and abs(i) + abs(j) == 1 for i, j, k in offsets.astype(int).tolist())
    assert any(k == 1 and abs(i) + abs(j) == 1 for i, j, k in offsets.astype(int).tolist())


def test_the_hands_order_finishes_a_flush_square_only_with_the_drop():
    u = 0.05
    blocks = [{'id': f'c{k}', 'type': 'cube', 'position': [0.35 + 0.1 * k, -0.3, u / 2], 'yaw': 0} for k in range(4)]
    scene = Scene.from_dict({
        'format': 'rad-scene/1', 'unit': u, 'block_types': {'cube': [[0, 0, 0]]}, 'blocks': blocks,
        'targets': [{'name': 't', 'origin': [0.45, 0.1, u / 2], 'size': [2, 2, 1],
                     'filled': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}]})
    placements = [Placement('cube', 't', 0, ((i, j, 0),)) for i in range(2) for j in range(2)]
    assert len(hand_order(scene, placements, gamp=SET_DOWN).order) == 3
    assert len(hand_order(scene, placements).order) == 4


def test_studded_bricks_and_the_cup_are_never_dropped():
    d = box_but_one(0.032).to_dict()
    d['studs'] = 'duplo'
    course = Scene.from_dict(d | {'blocks': []}).course
    d['blocks'] = [b | {'position': [0.45, -0.25 + 0.1 * k, course / 2]} for k, b in enumerate(d['blocks'][:2])]
    d['targets'][0]['origin'][2] = course / 2
    studded = Scene.from_dict(d)
    grid, _ = scene_state(studded)
    assert np.array_equal(HandBlocked(studded, grid).offsets(0), HandBlocked(studded, grid, SET_DOWN).offsets(0))
    scene = box_but_one(UNIT)
    grid, _ = scene_state(scene)
    cup = GampConfig(effector='suction')
    assert np.array_equal(HandBlocked(scene, grid, cup).offsets(0),
                          HandBlocked(scene, grid, GampConfig(effector='suction', drop=False)).offsets(0))


def test_the_robot_ceiling_closes_a_flush_square_that_setting_down_leaves_a_cell_of(set_down_hand, monkeypatch):
    from rad_core.gamp import planner
    from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling

    from scenes import flush_square
    assert robot_ceiling(flush_square(), time_limit_s=60).coverage == pytest.approx(0.75)
    monkeypatch.setattr(planner, 'DROP_BY_DEFAULT', True)
    found = robot_ceiling(flush_square(), time_limit_s=60)
    assert found.complete and found.coverage == 1.0

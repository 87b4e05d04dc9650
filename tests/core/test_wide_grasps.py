"""Wide grasps (issue 40): the fingers close across a block's whole extent along one axis
(`GampConfig.wide_grasps`, on by default; off: the unit grasps only, the paper's hand)."""

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.cell import panda
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.hard_shapes import HARD_LIBRARY
from rad_core.domain.scene import Scene
from rad_core.gamp import allocated_pose, plan_action
from rad_core.gamp.grasps import (
    MAX_GRASP_WIDTH,
    Grasp,
    beside_blocks,
    block_grasps,
    grasp_centre,
    grasp_width,
    scene_grasps,
    span_width,
    wide_grasps,
)
from rad_core.gamp.planner import GampConfig, wide_grasp_styles
from rad_core.sim.twin import Twin, twin_world_config
from rad_core.sim.world import World

from box_scenes import BOX, box_but_one

WIDE = GampConfig(wide_grasps=True, drop=False)      # wide grasps alone: no drop after them
UNIT_ONLY = GampConfig(wide_grasps=False, drop=False)


# ---- which wide grasps a type offers ---------------------------------------------------------

def test_a_flat_i2_is_taken_across_both_units_where_the_open_hand_takes_it():
    i2 = DEFAULT_LIBRARY['I2']
    assert wide_grasps(i2, 0.035) == (Grasp(0, 0, 2),)              # 70 mm + 2 x 5 mm = the 80 mm opening
    assert wide_grasps(i2, 0.05) == ()                               # 100 mm: too wide
    assert wide_grasps(i2, 0.036) == ()
    # After the unit grasps, which stay as they are.
    unit = block_grasps(i2, 0.035)
    assert block_grasps(i2, 0.035, wide=True) == unit + (Grasp(0, 0, 2),)
    assert block_grasps(i2, 0.05, wide=True) == block_grasps(i2, 0.05)
    # The target sits in the middle of the row, over its column.
    assert grasp_centre(i2, Grasp(0, 0, 2)).tolist() == [0.5, 0.0, 0.0]
    assert grasp_centre(i2, Grasp(1, 90)).tolist() == [1.0, 0.0, 0.0]   # a unit grasp: the unit's centre
    assert str(Grasp(0, 0, 2)) == 'unit 0 yaw 0 span 2' and str(Grasp(1, 90)) == 'unit 1 yaw 90'


def test_a_2x2_square_that_no_unit_grasp_takes_is_taken_across_either_axis_at_3_cm():
    o4 = HARD_LIBRARY['O4']
    assert block_grasps(o4, 0.03) == ()
    got = wide_grasps(o4, 0.03)
    assert set(got) == {Grasp(0, 0, 2), Grasp(2, 0, 2), Grasp(0, 90, 2), Grasp(1, 90, 2)}
    assert block_grasps(o4, 0.03, wide=True) == got
    # Each row's two units, between the fingers at its two ends.
    assert {tuple(grasp_centre(o4, g)) for g in got} == {(0.5, 0, 0), (0.5, 1, 0), (0, 0.5, 0), (1, 0.5, 0)}
    # With a clearance the outer faces move in: 2 units at 4 cm with 0.2 is 72 mm, too wide.
    assert wide_grasps(o4, 0.04) == () and wide_grasps(o4, 0.04, 0.3) != ()


def test_the_width_fits_the_open_hand_with_5_mm_on_each_side():
    i3 = DEFAULT_LIBRARY['I3']
    assert wide_grasps(i3, 0.023) == (Grasp(0, 0, 3),)               # 69 mm
    assert wide_grasps(i3, 0.025) == ()                              # 75 mm + 10 mm > 80 mm
    assert wide_grasps(i3, 0.025, clearance=0.2) == (Grasp(0, 0, 3),)   # 70 mm between the outer faces
    assert span_width(1, 0.04, 0.2) == grasp_width(0.04, 0.2)
    assert MAX_GRASP_WIDTH == pytest.approx(panda.MAX_OPENING - 0.01)


def test_the_fingers_pass_no_unit_of_the_block_on_their_way_down():
    lib = DEFAULT_LIBRARY
    # O4_up: the top row only (the bottom one has the top above it).
    assert wide_grasps(lib['O4_up'], 0.03) == (Grasp(2, 0, 2),)
    # L3_up: the bottom row has a unit above it; its top unit is alone.
    assert wide_grasps(lib['L3_up'], 0.03) == ()
    # T4: the bar across x has the stem beside it (not in a finger column); the stem's row across y
    # has the bar's middle unit, so the row is (1,0)-(1,1).
    assert set(wide_grasps(lib['T4'], 0.025)) == {Grasp(1, 90, 2)}
    # An L3 lying flat: both arms.
    assert set(wide_grasps(lib['L3'], 0.03)) == {Grasp(0, 0, 2), Grasp(0, 90, 2)}
    # S4_up: its top row, whose finger columns are free at its level and above.
    assert wide_grasps(lib['S4_up'], 0.03) == (Grasp(2, 0, 2),)


def test_where_the_fingers_are_wider_than_a_unit_the_blocks_diagonal_units_rule_out_a_grasp():
    # At a 2 cm unit the 17.5 mm fingertips, with the planner's 2 mm margin, reach past a unit's sides:
    # the T's bar units diagonal to the stem's finger columns (and the stem diagonal to the bar's ends')
    # rule out every unit grasp of a flat T4; its wide grasps stay. At 2.5 cm there is room.
    t4, l3 = DEFAULT_LIBRARY['T4'], DEFAULT_LIBRARY['L3']
    assert set(scene_grasps(t4, 0.02)) == {Grasp(0, 0, 3), Grasp(1, 90, 2)}
    assert {g for g in scene_grasps(t4, 0.025) if g.span == 1} == {Grasp(3, 0), Grasp(0, 90), Grasp(2, 90)}
    assert all(g.span > 1 for g in scene_grasps(l3, 0.02))
    assert beside_blocks(0, 0.02) and not beside_blocks(0, 0.022)
    assert not beside_blocks(0, 0.02, clearance=0.2)                # faces set back 2 mm more
    assert beside_blocks(1, 0.025) and not beside_blocks(1, 0.027)  # the 22 mm finger over the tips
    # Blocks one unit wide keep every unit grasp: nothing of theirs lies diagonal to a finger.
    for name in ('cube', 'I2', 'I3'):
        assert block_grasps(DEFAULT_LIBRARY[name], 0.02) == block_grasps(DEFAULT_LIBRARY[name], 0.03)


def test_the_grasps_the_finger_width_rules_out_are_those_gamp_refuses(monkeypatch):
    # The rule is the planner's own: with it off, GAMP tries the T4's unit grasps at 2 cm and each
    # finger hits the T itself; the wide grasps place it.
    from rad_core.gamp import grasps as grasps_module
    u = 0.02
    scene = Scene.from_dict({
        'format': 'rad-scene/1', 'unit': u, 'block_types': {'T4': [list(o) for o in DEFAULT_LIBRARY['T4'].offsets]},
        'blocks': [{'id': 't', 'type': 'T4', 'position': [0.45, -0.25, u / 2], 'yaw': 0}],
        'targets': [{'name': 'g', 'origin': [0.45, 0.15, u / 2], 'size': [3, 2, 1],
                     'filled': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0]]}]})
    with World(scene) as world:
        on = plan_action(world, 't', (0.45, 0.15, u / 2), 0, config=WIDE)
        monkeypatch.setattr(grasps_module, 'beside_blocks', lambda *a, **k: False)
        unit_only = plan_action(world, 't', (0.45, 0.15, u / 2), 0, config=UNIT_ONLY)
    assert on.success and on.grasp.span > 1, on.reason
    assert not unit_only.success
    assert unit_only.reason.count('finger hits block t') >= 3, unit_only.reason


def test_wide_styles_hold_at_the_tight_grasp_height_never_wider_than_the_hand():
    styles = wide_grasp_styles(0.07, 0.035)
    assert styles == ((panda.FINGER_OPEN, pytest.approx(0.035 / 2 - 0.013)),
                      (pytest.approx(0.039), pytest.approx(0.035 / 2 - 0.013)))
    assert len(wide_grasp_styles(0.05, 0.025)) == 2
    assert all(f <= panda.FINGER_OPEN for f, _ in wide_grasp_styles(0.078, 0.039))


# ---- where rows are too wide for the hand, nothing changes -------------------------------------

def test_at_4_and_5_cm_units_plans_with_and_without_wide_grasps_are_the_same():
    for btype in [*DEFAULT_LIBRARY.values(), *HARD_LIBRARY.values()]:
        for unit in (0.025, 0.03, 0.04, 0.05):
            assert block_grasps(btype, unit) == block_grasps(btype, unit, wide=False)
            assert all(g.span == 1 for g in block_grasps(btype, unit))
    scene = generate_scene(GeneratorConfig(grid=4), seed=1)
    alloc = solve(scene, AllocationParams(time_limit_s=5.0))
    with World(scene) as world:
        for placement in alloc.placements[:3]:
            block = next(b for b in scene.blocks if b.type == placement.type)
            position, yaw = allocated_pose(scene, placement)
            default = plan_action(world, block.id, position, yaw)
            off = plan_action(world, block.id, position, yaw, config=UNIT_ONLY)
            on = plan_action(world, block.id, position, yaw, config=WIDE)
            assert (off.success, off.reason, off.grasp) == (default.success, default.reason, default.grasp)
            assert default.success, default.reason
            # A unit grasp that works is taken before any wide one: the same plan.
            assert on.grasp == default.grasp and on.hand_yaw_deg == default.hand_yaw_deg
            assert np.array_equal(on.final_joints(), default.final_joints())


# ---- a block between neighbours on both sides -------------------------------------------------

U = 0.035
X, Y = 0.45, 0.10
PLACE = (X, Y + U, U / 2)


def _between_rows() -> Scene:
    """Two flat I2s built flush at rows 0 and 2 of a 2 x 3 target, a third on the table for row 1:
    its unit grasps close along y, where the rows stand, and its ends along x are free."""
    blocks = [{'id': 'n0', 'type': 'I2', 'position': [X, Y, U / 2], 'yaw': 0},
              {'id': 'n2', 'type': 'I2', 'position': [X, Y + 2 * U, U / 2], 'yaw': 0},
              {'id': 'm', 'type': 'I2', 'position': [0.45, -0.25, U / 2], 'yaw': 0}]
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': U, 'block_types': {'I2': [[0, 0, 0], [1, 0, 0]]}, 'blocks': blocks,
        'targets': [{'name': 't', 'origin': [X, Y, U / 2], 'size': [2, 3, 1],
                     'filled': [[i, j, 0] for i in range(2) for j in range(3)]}]})


@pytest.fixture(scope='module')
def between():
    scene = _between_rows()
    with World(scene) as world:
        off = plan_action(world, 'm', PLACE, 0, config=UNIT_ONLY)
        on = plan_action(world, 'm', PLACE, 0, config=WIDE)
    return scene, off, on


def test_a_block_flush_between_two_built_rows_is_placed_only_with_wide_grasps(between):
    _, off, on = between
    assert not off.success and off.failure == 'placement' and 'finger hits block n0' in off.reason
    assert on.success, on.reason
    assert on.grasp == Grasp(0, 0, 2)
    grasp = next(g for g in on.motion.gripper if g.action == 'grasp')
    assert grasp.expected_position == pytest.approx(U)              # the row's outer faces, 70 mm apart
    assert grasp.position == pytest.approx(U - 0.001)


def test_the_twin_carries_a_wide_grasped_block_to_its_place(between):
    scene, _, on = between
    with World(scene, twin_world_config()) as world:
        twin = Twin(world)
        results = []
        run = twin.execute_gripper
        twin.execute_gripper = lambda c, *a, **k: results.append((c, run(c, *a, **k))) or results[-1][1]
        assert twin.execute_motion(on.motion) == ''
        got = next(r for c, r in results if c.action == 'grasp')
        assert got.reached_goal and got.position == pytest.approx(U, abs=1.5e-3)
        twin.settle(0.3)
        assert twin.attached is None
        assert np.linalg.norm(world.block_pose('m')[0] - PLACE) < 0.004
        for bid in ('n0', 'n2'):                                    # the neighbours stay
            assert np.linalg.norm(world.block_pose(bid)[0] - scene.block(bid).position) < 0.002


def test_a_2x2_square_at_3_cm_is_picked_and_placed_with_wide_grasps():
    u = 0.03
    scene = Scene.from_dict({
        'format': 'rad-scene/1', 'unit': u, 'block_types': {'O4': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]},
        'blocks': [{'id': 'q', 'type': 'O4', 'position': [0.45, -0.25, u / 2], 'yaw': 0}],
        'targets': [{'name': 't', 'origin': [0.45, 0.15, u / 2], 'size': [2, 2, 1],
                     'filled': [[i, j, 0] for i in range(2) for j in range(2)]}]})
    with World(scene) as world:
        off = plan_action(world, 'q', (0.45, 0.15, u / 2), 90, config=UNIT_ONLY)
        on = plan_action(world, 'q', (0.45, 0.15, u / 2), 90, config=WIDE)
    assert not off.success and 'no top-down grasp' in off.reason
    assert on.success, on.reason
    assert on.grasp.span == 2




@pytest.mark.parametrize('unit, clearance', [(0.03, 0.0), (0.035, 0.0), (0.035, 0.2)])
def test_the_last_block_of_a_solid_box_is_set_down_only_with_wide_grasps(unit, clearance):
    place = (BOX[0] + unit, BOX[1], 1.5 * unit)
    scene = box_but_one(unit, clearance)
    with World(scene) as world:
        off = plan_action(world, 'm', place, 90, config=UNIT_ONLY)
        on = plan_action(world, 'm', place, 90, config=WIDE)
    assert not off.success and 'finger hits block b21' in off.reason
    assert on.success and on.grasp == Grasp(0, 0, 2), on.reason
    if (unit, clearance) != (0.03, 0.0):
        return
    with World(scene, twin_world_config()) as world:
        twin = Twin(world)
        assert twin.execute_motion(on.motion) == ''
        twin.settle(0.3)
        assert twin.attached is None
        assert np.linalg.norm(world.block_pose('m')[0] - place) < 0.004


# ---- the allocation's hand model knows them ------------------------------------------------------

def test_the_hand_model_counts_on_wide_grasps_where_gamp_takes_them():
    from rad_core.allocation.arm import HandBlocked
    from rad_core.allocation.order import scene_state

    unit = 0.03
    scene = box_but_one(unit)
    grid, occupied = scene_state(scene)
    # The last pose: the I2 across the box at column 1 of the top layer, units (1, 0, 1) and (1, 1, 1).
    last = grid.lookup(np.array([[BOX[0] + unit, BOX[1] + j * unit, 1.5 * unit] for j in range(2)]))
    assert (last >= 0).all() and not occupied[last].any()
    assert HandBlocked(scene, grid, UNIT_ONLY).blocked('I2', 90, last, occupied)
    assert not HandBlocked(scene, grid, WIDE).blocked('I2', 90, last, occupied)
    # Its wide grasp's finger columns are the box's outer sides, off the target's grid: no cell that
    # is ever built blocks it, while each unit grasp has built cells in its way at both hand yaws.
    hand = HandBlocked(scene, grid, WIDE)
    ways = dict(zip(hand.grasps['I2'], hand.cells('I2', 90, last)))
    assert [g.span for g in ways] == [1, 1, 2]
    assert all(len(cells) == 0 for g, pair in ways.items() if g.span == 2 for cells in pair)
    assert all(occupied[cells].any() for g, pair in ways.items() if g.span == 1 for cells in pair)


@pytest.mark.parametrize('unit, whole', [(0.03, True), (0.04, False)])
def test_supply_finds_a_cover_of_the_solid_box_the_hand_places_whole_where_rows_fit_the_hand(unit, whole):
    from rad_core.allocation.supply import SupplyParams, choose_blocks
    from rad_core.domain.scene import TargetRegion

    box = TargetRegion('t', (BOX[0], BOX[1], unit / 2), (4, 2, 2),
                       tuple((i, j, k) for i in range(4) for j in range(2) for k in range(2)))
    _, report = choose_blocks([box], unit, {'I2': DEFAULT_LIBRARY['I2'], 'cube': DEFAULT_LIBRARY['cube']},
                              params=SupplyParams(time_limit_s=10.0, drop=False))
    assert report.covered == 16
    assert (report.hand_covered == 16) == whole, report    # at 4 cm: 80 mm rows, wider than the hand takes


def test_a_plate_thinner_than_the_fingertips_reach_is_held_above_its_tight_grasp():
    """A LEGO 2 x 4 plate at a 3 cm pitch is 12 mm thick, less than the 8 mm the pads reach under the
    grasp target plus the plate's half: held at its centre, the fingertips would hit the table. The
    planner raises the grasp so they stay `TIP_FLOOR` over what it rests on, and it is placed."""
    import numpy as np
    from rad_core.allocation.brick_scenes import built_blocks, lattice_of, scene_from_design, target_of
    from rad_core.domain.brick_designs import parse_ldraw
    from rad_core.gamp.action import MotionPlanner, SceneAction
    from rad_core.gamp.grasps import TIP_FLOOR, tip_floor_lift

    assert tip_floor_lift(0.006) == pytest.approx(TIP_FLOOR - 0.006)
    assert tip_floor_lift(0.030) == 0.0
    ldraw = '1 4 0 -24 0 1 0 0 0 1 0 0 0 1 3001.dat\n1 4 0 -32 0 1 0 0 0 1 0 0 0 1 3020.dat\n'
    design = parse_ldraw(ldraw, 'plate.ldr')
    scene, _ = scene_from_design(design, 'lego', 0.03)
    lattice = lattice_of(design, 'lego', 0.03)
    _, region, _ = target_of(design, lattice)
    _, placed = built_blocks(design.normalised(), lattice, region)
    doc = scene.to_dict()
    brick = next(b for b in doc['blocks'] if b['type'] == placed[0].type)
    brick['position'], brick['yaw'] = list(placed[0].position), placed[0].yaw
    scene = type(scene).from_dict(doc)
    plate = next(b for b in scene.blocks if b.type == placed[1].type)
    cell = tuple(int(v) for v in np.round((np.asarray(placed[1].position) - region.origin) / scene.pitch))
    planner = MotionPlanner()
    try:
        result, planned, _ = planner(scene, SceneAction(plate.id, 0, region.name, cell,
                                                        ((placed[1].yaw - plate.yaw) // 90) % 4))
    finally:
        planner.close()
    assert result.success, result.reason
    assert planned == pytest.approx(placed[1].position)

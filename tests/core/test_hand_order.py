"""The hand's own order of an allocation (`allocation.order`): order repair's second chain."""

from __future__ import annotations

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.arm import HandBlocked
from rad_core.allocation.order import hand_order
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Scene
from rad_core.gamp.planner import GampConfig

from scenes import scene as make_scene

U = 0.05
SET_DOWN = GampConfig(drop=False)
"""The hand that only sets blocks down (no drop: `GampConfig.drop`), whose order these tests are about."""


def square(n_cubes: int = 4) -> Scene:
    """A flush 2 x 2 square of cube cells on the table, and cubes on the table for it."""
    blocks = [{'id': f'c{k}', 'type': 'cube', 'position': [0.35 + 0.1 * k, -0.3, U / 2], 'yaw': 0}
              for k in range(n_cubes)]
    return make_scene(blocks=blocks, unit=U, types={'cube': [[0, 0, 0]]},
                      targets=[{'name': 't', 'origin': [0.45, 0.1, U / 2], 'size': [2, 2, 1],
                                'filled': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}])


def replay(scene: Scene, found, gamp=SET_DOWN) -> None:
    """Every pose of the order, placed in turn, has a way of being held that no earlier pose blocks,
    and the order keeps to its precedences."""
    grid = Grid(scene)
    hand = HandBlocked(scene, grid, gamp)
    occupied = np.zeros(grid.num_cells, dtype=bool)
    where = {cells: k for k, cells in enumerate(found.order)}
    for p in found.precedences:
        assert where[p.first] < where[p.then]
    for cells in found.order:
        assert not hand.blocked('cube', 0, cells, occupied), cells
        occupied[list(cells)] = True


def test_a_flush_square_places_three_cubes_in_an_order_the_hand_can_keep():
    # Each cube is taken with the fingers across one of its two neighbours in the square: the last of
    # four would have both built. So three, each before the neighbour its fingers go past.
    scene = square()
    placements = solve(scene).placements
    assert len(placements) == 4
    found = hand_order(scene, placements, gamp=SET_DOWN)
    assert len(found.order) == 3
    replay(scene, found)
    assert found.precedences           # at least one cube goes before a neighbour its fingers pass
    assert all(p.reason == 'hand order' for p in found.precedences)


def test_poses_needing_no_order_give_no_precedences_and_built_cells_count():
    # Two cubes side by side in a one-cell-deep row: the fingers close across the row, both free.
    blocks = [{'id': f'c{k}', 'type': 'cube', 'position': [0.35 + 0.1 * k, -0.3, U / 2], 'yaw': 0}
              for k in range(2)]
    row = make_scene(blocks=blocks, unit=U, types={'cube': [[0, 0, 0]]},
                     targets=[{'name': 't', 'origin': [0.45, 0.1, U / 2], 'size': [2, 1, 1],
                               'filled': [[0, 0, 0], [1, 0, 0]]}])
    found = hand_order(row, solve(row).placements)
    assert len(found.order) == 2 and found.precedences == []
    # The square with one cube already built in a corner: three cells open, two of them beside it.
    scene = square()
    d = scene.to_dict()
    d['blocks'][0]['position'] = [0.45, 0.1, U / 2]          # c0 on cell (0, 0)
    built = Scene.from_dict(d)
    placements = solve(built).placements
    assert len(placements) == 3
    found = hand_order(built, placements, gamp=SET_DOWN)
    grid = Grid(built)
    corner = grid.index(0, (0, 0, 0))
    assert all(corner not in cells for cells in found.order)
    # The cell across from the built corner is hemmed in last: two of the three.
    assert len(found.order) == 2


def test_a_pose_under_a_built_cell_has_no_way_in():
    # An I2 on the bottom layer of a row one cell deep, and a cube over its second unit. The hand can
    # still take the I2 by its first unit, whose column is free, but the carried I2 would come down
    # through the cube: no way of holding it is left, and the hand's order leaves it out.
    from rad_core.allocation.order import hand_ways
    from rad_core.allocation.placements import Placement
    blocks = [{'id': 'i0', 'type': 'I2', 'position': [0.35, -0.3, U / 2], 'yaw': 0},
              {'id': 'c0', 'type': 'cube', 'position': [0.55, 0.1, 1.5 * U], 'yaw': 0}]
    types = {'cube': [[0, 0, 0]], 'I2': [[0, 0, 0], [1, 0, 0]]}
    target = {'name': 't', 'origin': [0.45, 0.1, U / 2], 'size': [3, 1, 2],
              'filled': [[i, 0, k] for i in range(3) for k in range(2)]}
    scene = make_scene(blocks=blocks, unit=U, types=types, targets=[target])
    grid = Grid(scene)
    pose = [grid.index(0, (1, 0, 0)), grid.index(0, (2, 0, 0))]
    occupied = np.zeros(grid.num_cells, dtype=bool)
    assert hand_ways(grid, HandBlocked(scene, grid), occupied, 'I2', 0, pose)
    occupied[grid.index(0, (2, 0, 1))] = True             # the cube, as the scene has it
    assert not HandBlocked(scene, grid).blocked('I2', 0, pose, occupied)   # a grasp is free...
    assert hand_ways(grid, HandBlocked(scene, grid), occupied, 'I2', 0, pose) is None   # ...the way down is not
    assert hand_order(scene, [Placement('I2', 't', 0, ((1, 0, 0), (2, 0, 0)))]).order == []


def test_the_way_down_finds_no_order_for_a_pinwheel_and_supply_asks_for_it():
    # A solid 3 x 3 x 2 box from four stepped pieces around a standing I2, each piece's upper step
    # over the next one's lower step: a cycle, so whichever comes last would come down through the
    # one before. Only the orders that know the carried block's way down see it; supply asks for them.
    from rad_core.allocation.placements import enumerate_candidates
    from rad_core.domain.blocks import DEFAULT_LIBRARY
    lib = {n: [list(o) for o in DEFAULT_LIBRARY[n].offsets] for n in ('S4_up', 'I2_up')}
    blocks = [{'id': f's{k}', 'type': 'S4_up', 'position': [0.3 + 0.12 * k, -0.35, U / 2], 'yaw': 0}
              for k in range(4)] + [{'id': 'i0', 'type': 'I2_up', 'position': [0.35, -0.5, U / 2], 'yaw': 0}]
    target = {'name': 't', 'origin': [0.45, 0.1, U / 2], 'size': [3, 3, 2],
              'filled': [[i, j, k] for i in range(3) for j in range(3) for k in range(2)]}
    scene = make_scene(blocks=blocks, unit=U, types=lib, targets=[target])
    grid = Grid(scene)
    wheel = [{(2, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)}, {(2, 2, 0), (2, 1, 0), (2, 1, 1), (2, 0, 1)},
             {(0, 2, 0), (1, 2, 0), (1, 2, 1), (2, 2, 1)}, {(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 2, 1)},
             {(1, 1, 0), (1, 1, 1)}]
    pick = {frozenset(c.placement.cells): c.placement for c in enumerate_candidates(scene, grid)}
    placements = [pick[frozenset(cells)] for cells in wheel]
    suction = GampConfig(effector='suction')       # nothing beside the block: only the way down orders
    assert len(hand_order(scene, placements, gamp=suction).order) == 5
    found = hand_order(scene, placements, gamp=suction, way_down=True)
    assert len(found.order) == 4 and found.coverage == pytest.approx(14 / 18)
    assert {p.reason for p in found.precedences} == {"the carried block's way down"}
    from rad_core.allocation.cpsat import hand_unplaced
    assert len(hand_unplaced(scene, placements, suction, way_down=True)) == 1


@pytest.mark.slow
def test_order_repair_with_the_hands_order_builds_held_out_spire_cup_whole():
    # Refusals alone taught contradictory precedences here (two tall blocks back to back, each
    # placeable only while the other is not there yet): the default agent stopped at 0.917.
    from rad_core.domain.shapes import shape_scene
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    from rad_core.sequencing.decide.agents import parse
    scene = shape_scene('spire_cup')
    assert hand_order(scene, solve(scene, AllocationParams(support='arm')).placements).precedences
    plan = AgentPlanner('default', time_limit_s=120)(scene, None, 0)
    assert parse('default').repair
    assert plan.predicted_coverage == 1.0 and plan.success
    assert 'repair' in [a['plan'] for a in plan.anytime]


def test_the_ordered_cover_picks_poses_and_an_order_the_hand_can_keep_within_the_blocks():
    # The flush square from two I2s and three cubes: four cells as a cover, but whichever block
    # closes it has a neighbour or its own length in the fingers' way. The ordered cover takes
    # three cells with an order, and never more blocks of a type than the table holds.
    from rad_core.allocation.order import ordered_cover

    from scenes import flush_square
    scene = flush_square()
    cover = ordered_cover(scene, gamp=SET_DOWN)
    assert cover.coverage == pytest.approx(0.75) and len(cover.order) == len(cover.placements)
    grid, hand = Grid(scene), HandBlocked(scene, Grid(scene), SET_DOWN)
    occupied = np.zeros(grid.num_cells, dtype=bool)
    counts: dict = {}
    for cells, p in zip(cover.order, cover.placements):
        assert tuple(sorted(grid.index(0, c) for c in p.cells)) == cells
        assert not occupied[list(cells)].any() and not hand.blocked(p.type, p.yaw, list(
            grid.index(0, c) for c in p.cells), occupied)
        occupied[list(cells)] = True
        counts[p.type] = counts.get(p.type, 0) + 1
    assert counts.get('I2', 0) <= 2 and counts.get('cube', 0) <= 3
    assert cover.value == 3                      # three target cells, no filler


@pytest.mark.slow
def test_order_repairs_fourth_chain_plans_the_ordered_cover_where_the_allocations_leave_cells(monkeypatch):
    # Generated g = 5 seed 12: the first plans stop at 6 of 7 cells; the cover chosen together with an
    # order the hand can keep fills the target. Without that chain (its CP-SAT answering nothing), the
    # agent stops where it did.
    from rad_core.allocation import order as ho
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.sequencing.agent import agent_plan
    scene = generate_scene(GeneratorConfig(grid=5, sides=2), 12)
    planner = agent_plan.AgentPlanner('default', time_limit_s=120)
    plan = planner(scene, None, 0)
    assert plan.predicted_coverage == 1.0 and plan.success
    assert plan.anytime[-1]['plan'] == 'cover'
    cover = ho.ordered_cover(scene, agent_plan.ORDERED_COVER_S)
    assert cover.coverage == 1.0 and cover.precedences
    monkeypatch.setattr(agent_plan, 'ordered_cover', lambda *a, **k: ho.HandOrder())
    without = agent_plan.AgentPlanner('default', time_limit_s=120)(scene, None, 0)   # its solvers made now
    assert without.predicted_coverage < 0.9


# ---- a first answer for thousands of poses ------------------------------------------------------

def _cover_poses(scene, gamp=SET_DOWN):
    from rad_core.allocation.order import candidate_poses, cover_candidates, scene_state
    grid, occupied = scene_state(scene)
    candidates, counts, hand, _ = cover_candidates(scene, grid, gamp)
    poses, items = candidate_poses(grid, hand, occupied, candidates, counts)
    return grid, occupied, poses, items, counts, hand


def test_the_greedy_order_keeps_the_models_rules():
    # Every pose of the sweep: cells no pose before it fills, a way held that no pose before it
    # blocks, resting when its turn comes; and the counts kept. On the flush square, three cubes.
    from rad_core.allocation.constraints import rests_now
    from rad_core.allocation.order import greedy_order
    scene = square(n_cubes=3)
    grid, occupied, poses, _, counts, _ = _cover_poses(scene)
    first = greedy_order(grid, occupied, poses, counts, cover=True, way_down=True)
    assert len(first) == 3
    filled = occupied.copy()
    for n, way in first:
        cells, ways = list(poses[n][0]), poses[n][1]
        assert not filled[cells].any()
        assert way is not None and not filled[ways[way]].any()
        assert rests_now(grid, cells, filled)
        filled[cells] = True


def test_where_cp_sat_finds_no_order_in_its_time_the_greedy_order_is_the_answer(monkeypatch):
    # CP-SAT presolving thousands of poses can spend all its time: made to happen here by a solver
    # that finds nothing. On a large model the answer is then the greedy order, with its precedences.
    from ortools.sat.python import cp_model

    from rad_core.allocation import order as order_module
    from rad_core.allocation.order import greedy_order, solve_order

    class NoAnswer:
        parameters = cp_model.CpSolver().parameters

        def solve(self, model):
            return cp_model.UNKNOWN

    scene = square(n_cubes=3)
    grid, occupied, poses, items, counts, _ = _cover_poses(scene)
    monkeypatch.setattr(order_module, 'cp_solver', lambda seconds: NoAnswer())
    assert solve_order(grid, occupied, poses, items, counts, 1.0, cover=True).order == []   # few poses: none
    monkeypatch.setattr(order_module, 'LARGE_POSES', 0)          # as with thousands of poses
    found = solve_order(grid, occupied, poses, items, counts, 1.0, cover=True)
    first = greedy_order(grid, occupied, poses, counts, cover=True)
    assert found.order == [poses[n][0] for n, _ in first] and len(found.order) == 3
    assert found.coverage == pytest.approx(3 / 4)
    assert found.precedences and all(p.reason == 'hand order' for p in found.precedences)
    replay(scene, found)
    # An answer found before (avoid) is not given again.
    assert solve_order(grid, occupied, poses, items, counts, 1.0, cover=True, avoid=[found.order]).order == []


def test_at_a_2_cm_unit_any_built_neighbour_blocks_a_cube_for_the_planner_not_for_the_bound():
    # The 17.5 mm fingertips closed on a 2 cm cube come within the planner's 2 mm margin of the cubes
    # beside it: the near hand model (the course line's) counts that, the bound's does not; and GAMP
    # refuses to set the cube down beside a built one, but drops it in.
    from rad_core.gamp import plan_action
    from rad_core.sim.world import World
    u = 0.02
    blocks = [{'id': 'c0', 'type': 'cube', 'position': [0.35, -0.3, u / 2], 'yaw': 0},
              {'id': 'c1', 'type': 'cube', 'position': [0.45 + u, 0.1, u / 2], 'yaw': 0}]
    scene = make_scene(blocks=blocks, unit=u, types={'cube': [[0, 0, 0]]},
                       targets=[{'name': 't', 'origin': [0.45, 0.1, u / 2], 'size': [2, 1, 1],
                                 'filled': [[0, 0, 0], [1, 0, 0]]}])
    grid = Grid(scene)
    cell, beside = grid.index(0, (0, 0, 0)), grid.index(0, (1, 0, 0))
    occupied = np.zeros(grid.num_cells, dtype=bool)
    occupied[beside] = True
    assert HandBlocked(scene, grid, SET_DOWN, near=True).blocked('cube', 0, [cell], occupied)
    assert not HandBlocked(scene, grid, SET_DOWN).blocked('cube', 0, [cell], occupied)
    with World(scene) as world:
        down = plan_action(world, 'c0', grid.centres[cell], 0, config=SET_DOWN)
        dropped = plan_action(world, 'c0', grid.centres[cell], 0, config=GampConfig(drop=True))
    assert not down.success and 'hits block c1' in down.reason, down.reason
    assert dropped.success and dropped.drop, dropped.reason


def test_the_large_models_way_of_holding_against_when_cells_fill_finds_the_same_orders(monkeypatch):
    # Above `LARGE_POSES` a way is held against the time its blocking cells are filled; the answers
    # are the small model's: three cubes of the flush square, the corner-built square's two.
    from rad_core.allocation import order as order_module
    scene = square()
    placements = solve(scene).placements
    small = hand_order(scene, placements, gamp=SET_DOWN)
    monkeypatch.setattr(order_module, 'LARGE_POSES', 0)
    large = hand_order(scene, placements, gamp=SET_DOWN)
    assert len(large.order) == len(small.order) == 3
    replay(scene, large)
    d = scene.to_dict()
    d['blocks'][0]['position'] = [0.45, 0.1, U / 2]
    built = Scene.from_dict(d)
    assert len(hand_order(built, solve(built).placements, gamp=SET_DOWN).order) == 2
    cover = order_module.ordered_cover(scene, gamp=SET_DOWN)
    assert cover.coverage == pytest.approx(3 / 4)
    replay(scene, cover)


# ---- the drops' cover of a solid box ------------------------------------------------------------

def solid_box_scene():
    """The solid 3 x 3 x 2 box of `benchmarks/bench_dense.py` at a 3 cm unit, flush, from rad's own
    block set, as `rad scene from-voxels` makes it for the hand."""
    from rad_core.allocation.supply import SupplyParams, supply
    from rad_core.domain.blocks import DEFAULT_LIBRARY
    from rad_core.domain.dense_shapes import solid
    from rad_core.domain.voxels import Model, place_regions
    targets = place_regions([Model('box3x3x2', '', solid((3, 3, 2)))], 0.03)
    scene, report = supply(targets, 0.03, dict(DEFAULT_LIBRARY), params=SupplyParams(time_limit_s=60.0))
    assert report.covered == 18
    return scene


def _comes_down_onto(grid: Grid, order) -> list[tuple]:
    """The pairs (earlier, later) of an order where the later pose has a cell under the earlier one's."""
    return [(a, b) for k, a in enumerate(order) for b in order[k + 1:]
            if set(grid.columns_above(list(b)).tolist()) & set(a)]


def test_the_drops_cover_of_a_solid_box_keeps_each_blocks_way_down():
    # Every way the hand sets a block down leaves the box's last block no room for the fingers; the
    # drops' cover finds all 18 cells. Without the way-down rule it put a block under one placed
    # before it (GAMP: "carried block hits block"), and the plan built 15 of 18 cells.
    from rad_core.allocation.order import ordered_cover
    scene = solid_box_scene()
    grid = Grid(scene)
    drops = GampConfig(drop=True)
    cover = ordered_cover(scene, 5.0, gamp=drops, way_down=True)
    assert cover.coverage == 1.0 and cover.drops and not _comes_down_onto(grid, cover.order)
    assert _comes_down_onto(grid, ordered_cover(scene, 5.0, gamp=drops).order)
    assert ordered_cover(scene, 5.0, gamp=SET_DOWN).coverage < 1.0


@pytest.mark.slow
def test_the_default_agent_builds_the_solid_box_whole_with_the_hand():
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    plan = AgentPlanner('default', time_limit_s=120)(solid_box_scene(), None, 0)
    assert plan.predicted_coverage == 1.0 and plan.success
    assert plan.anytime[-1]['plan'] == 'cover'           # the drops' cover, the stages' last try


@pytest.mark.slow
def test_on_a_few_blocks_a_winning_course_line_leaves_order_repair_to_finish():
    # bricks10-s1 of benchmarks/bench_dense.py: 11 blocks at 3 cm, of so many types that the scene has
    # more candidate poses than `COURSES_ABOVE`. The course line beats the first plan at 43 of 44 cells;
    # order repair of the first allocation after it fills the target (skipped after a winning line
    # before, which left it at 43).
    from rad_core.allocation.supply import SupplyParams, supply
    from rad_core.domain.blocks import BRICK_TYPES, DEFAULT_LIBRARY
    from rad_core.domain.dense_shapes import designs
    from rad_core.domain.voxels import Model, place_regions
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    from rad_core.sequencing.agent.stages import REPLAN_BLOCKS
    types = {**BRICK_TYPES, 'I2': DEFAULT_LIBRARY['I2'], 'cube': DEFAULT_LIBRARY['cube']}
    targets = place_regions([Model('bricks10-s1', '', designs()['bricks']['bricks10-s1'])], 0.03)
    scene, report = supply(targets, 0.03, types, params=SupplyParams(time_limit_s=60.0))
    assert report.hand_covered == report.covered == 44 and len(scene.blocks) <= REPLAN_BLOCKS
    plan = AgentPlanner('default', time_limit_s=120)(scene, None, 0)
    made_by = [a['plan'] for a in plan.anytime]
    assert 'courses' in made_by and made_by[-1] != 'courses'
    assert plan.predicted_coverage == 1.0 and plan.success

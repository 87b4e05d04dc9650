"""rad_core.allocation.supply: the blocks chosen for a target cover it exactly where a stable exact cover
exists, with the fewest (or cheapest) blocks, within an inventory; they lie on the table
within reach, apart and clear of the target; the allocation over them covers as much."""

import json

import numpy as np
import pytest
from rad_core.allocation import supply as sp
from rad_core.allocation.cpsat import AllocationParams, solve
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.coverage import placements_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.shapes import LayoutConfig
from rad_core.domain.voxels import Model, place_regions

UNIT = 0.05


def regions(*grids):
    return place_regions([Model(f'r{n}', '', g) for n, g in enumerate(grids)], UNIT)


def bar(n: int) -> np.ndarray:
    return np.ones((n, 1, 1), dtype=bool)


def types(*names):
    return {n: DEFAULT_LIBRARY[n] for n in names}


def chair() -> np.ndarray:
    g = np.zeros((3, 3, 5), dtype=bool)
    for x in (0, 2):
        for y in (0, 2):
            g[x, y, 0:2] = True
    g[:, :, 2] = True
    g[:, 2, 3:5] = True
    return g


def test_fewest_takes_the_largest_blocks_that_cover_exactly():
    wall = np.ones((3, 1, 2), dtype=bool)
    _, report = sp.choose_blocks(regions(wall), UNIT, types('cube', 'I2', 'I3'))
    assert report.exact and report.counts == {'I3': 2}
    _, report = sp.choose_blocks(regions(bar(2)), UNIT, types('cube', 'I2'))
    assert report.exact and report.counts == {'I2': 1}


def test_cheapest_follows_the_costs():
    params = sp.SupplyParams(objective='cheapest', costs={'I2': 5, 'cube': 1})
    _, report = sp.choose_blocks(regions(bar(2)), UNIT, types('cube', 'I2'), params=params)
    assert report.exact and report.counts == {'cube': 2} and report.cost == 2
    params = sp.SupplyParams(objective='cheapest', costs={'I2': 1.5, 'cube': 1})
    _, report = sp.choose_blocks(regions(bar(2)), UNIT, types('cube', 'I2'), params=params)
    assert report.counts == {'I2': 1} and report.cost == 1.5


def test_an_inventory_caps_the_counts_and_the_report_says_how_much_is_covered():
    placements, report = sp.choose_blocks(regions(bar(5)), UNIT, types('cube', 'I2'), inventory={'I2': 1, 'cube': 2})
    assert report.counts == {'I2': 1, 'cube': 2} and len(placements) == 3
    assert report.covered == 4 and report.target_cells == 5 and not report.exact
    assert '4 of 5 target cells (0.80)' in report.summary()
    scene, report = sp.supply(regions(bar(5)), UNIT, types('cube', 'I2'), inventory={'I2': 1, 'cube': 2})
    assert scene.type_counts() == {'cube': 2, 'I2': 1}


def test_the_stability_rule_applies():
    # A cell over an empty one: three cubes would cover it, but the one on top stands on nothing.
    overhang = np.zeros((2, 1, 2), dtype=bool)
    overhang[0, 0, :] = True
    overhang[1, 0, 1] = True
    placements, report = sp.choose_blocks(regions(overhang), UNIT, types('cube'))
    assert report.covered == 2 and report.filler_cells == 0 and report.stands
    # An L3_up (its long leg on the table) under it holds it up: a filler cell, all targets covered.
    _, report = sp.choose_blocks(regions(overhang), UNIT, types('cube', 'I2', 'L3_up'))
    assert report.covered == 3 and report.stands


def test_no_cover_at_all_is_an_error_that_says_what_to_offer():
    with pytest.raises(RadError, match='no target cell can be covered.*I3.*--types'):
        sp.supply(regions(bar(2)), UNIT, types('I3'))


def test_the_blocks_lie_within_reach_apart_and_clear_of_the_target():
    targets = regions(chair())
    scene, report = sp.supply(targets, UNIT, dict(DEFAULT_LIBRARY))
    assert report.exact and report.stands
    layout = LayoutConfig()
    units = [(b.id, scene.unit_positions(b)) for b in scene.blocks]
    for bid, pts in units:
        r = np.hypot(pts[:, 0], pts[:, 1])
        assert np.all((r >= layout.reach[0] - 1e-9) & (r <= layout.reach[1] + 1e-9)), bid
        assert np.allclose(pts[:, 2].min(), UNIT / 2), bid                       # resting on the table
        lo, hi = targets[0].bounds(UNIT)
        clear = np.any((pts[:, :2] < lo[:2] - layout.region_margin) | (pts[:, :2] > hi[:2] + layout.region_margin),
                       axis=1)
        assert clear.all(), bid
    for n, (a, pa) in enumerate(units):
        for b, pb in units[n + 1:]:
            gap = np.abs(pa[:, None, :2] - pb[None, :, :2]).max(axis=-1).min() - UNIT
            assert gap >= layout.gap - 1e-9, (a, b, gap)                          # room for the fingers


def test_the_allocation_over_the_supplied_blocks_covers_as_much():
    targets = regions(chair())
    scene, report = sp.supply(targets, UNIT, dict(DEFAULT_LIBRARY))
    result = solve(scene, AllocationParams(support='stable'))
    assert result.status == 'OPTIMAL'
    assert placements_coverage(scene, result.placements) == pytest.approx(report.coverage) == 1.0
    assert len(scene.blocks) == sum(report.counts.values())


def test_blocks_that_do_not_fit_on_the_table_wait_in_a_feeder_unless_the_table_is_asked_for():
    big = np.ones((8, 6, 1), dtype=bool)                     # 48 cubes: more than the table holds in reach
    with pytest.raises(RadError, match=r'do not fit on the table within the arm.s reach.*--size'):
        sp.supply(regions(big), UNIT, types('cube'), params=sp.SupplyParams(start='table'))
    scene, report = sp.supply(regions(big), UNIT, types('cube'))
    assert scene.feeder is not None and set(scene.feeder.blocks) == {b.id for b in scene.blocks}
    assert len(scene.blocks) == 48 and report.exact
    small, _ = sp.supply(regions(bar(2)), UNIT, types('I2'), params=sp.SupplyParams(start='feeder'))
    assert small.feeder is not None and small.feeder.station == (0.42, -0.3)
    with pytest.raises(RadError, match='supply must be one of'):
        sp.supply(regions(bar(2)), UNIT, types('I2'), params=sp.SupplyParams(start='tray'))


def test_the_course_by_course_cover_is_feasible_and_rests_as_it_goes():
    """course_cover: disjoint poses, within the counts, each resting on the table or on poses chosen
    before it; on a solid box with cubes offered it covers every cell."""
    from rad_core.allocation.constraints import rests_now
    from rad_core.allocation.placements import enumerate_candidates
    from rad_core.domain.grid import Grid
    from rad_core.domain.scene import Scene
    box = np.ones((3, 3, 3), dtype=bool)
    box[1, 1, 0] = False                                     # a cell under the middle: something must bridge it
    scene = Scene(UNIT, types('cube', 'I3', 'L3'), (), tuple(regions(box)), 0.0)
    grid = Grid(scene)
    candidates = [c for c in enumerate_candidates(scene, grid, positive_only=False) if c.value >= 0]
    counts = {'cube': 2, 'I3': 30, 'L3': 30}
    chosen = sp.course_cover(grid, candidates, counts)
    occupied = np.zeros(grid.num_cells, dtype=bool)
    used = {n: 0 for n in counts}
    for n in chosen:
        ids = list(candidates[n].cell_ids)
        assert not occupied[ids].any() and rests_now(grid, ids, occupied)
        occupied[ids] = True
        used[candidates[n].placement.type] += 1
    assert all(used[k] <= counts[k] for k in counts)
    assert occupied[grid.is_target].sum() >= 24                # all but what two cubes cannot make up
    assert not occupied[~grid.is_target].any()


def test_a_large_target_gets_a_cover_even_when_the_solver_finds_none_in_time():
    """No 'no answer' where blocks can cover: a 300-cell target with a time limit CP-SAT cannot
    answer within gets the course-by-course cover, most of its cells, and a feeder for its blocks."""
    big = np.ones((10, 6, 5), dtype=bool)
    targets = place_regions([Model('big', '', big)], 0.02)
    scene, report = sp.supply(targets, 0.02, types('cube', 'I2', 'I3', 'L3'),
                              params=sp.SupplyParams(time_limit_s=0.05, hand=False))
    assert report.covered >= 0.9 * report.target_cells, report.summary()
    assert scene.feeder is not None and len(scene.blocks) == sum(report.counts.values())


def test_a_same_seed_gives_the_same_scene_and_another_moves_the_blocks():
    targets = regions(np.ones((3, 1, 2), dtype=bool))
    a, _ = sp.supply(targets, UNIT, types('cube', 'I2', 'I3'), params=sp.SupplyParams(seed=1))
    b, _ = sp.supply(targets, UNIT, types('cube', 'I2', 'I3'), params=sp.SupplyParams(seed=1))
    c, _ = sp.supply(targets, UNIT, types('cube', 'I2', 'I3'), params=sp.SupplyParams(seed=2))
    assert a == b and a.blocks != c.blocks and a.type_counts() == c.type_counts()


def test_inventory_files_and_costs_are_checked(tmp_path):
    known = dict(DEFAULT_LIBRARY)
    path = tmp_path / 'inv.json'
    path.write_text(json.dumps({'I2': 3, 'L3': {'count': 2, 'cost': 1.5}}))
    assert sp.read_inventory(str(path), known) == ({'I2': 3, 'L3': 2}, {'L3': 1.5})
    for doc, problem in (({'X9': 1}, "unknown block type 'X9'"), ({'I2': -1}, 'whole number'),
                         ({'I2': {'cost': 1}}, 'expected {"count": N}'), ([], 'JSON object')):
        path.write_text(json.dumps(doc))
        with pytest.raises(RadError, match=problem):
            sp.read_inventory(str(path), known)
    path.write_text('{not json')
    with pytest.raises(RadError, match='not JSON'):
        sp.read_inventory(str(path), known)
    assert sp.parse_costs('I2=1, L3=1.5') == {'I2': 1.0, 'L3': 1.5}
    with pytest.raises(RadError, match='TYPE=COST'):
        sp.parse_costs('I2:1')
    with pytest.raises(RadError, match='needs per-type costs'):
        sp.choose_blocks(regions(bar(2)), UNIT, types('I2'), params=sp.SupplyParams(objective='cheapest'))
    with pytest.raises(RadError, match='unknown block type'):
        sp.pick_types('I2,Q7', known)


def _hand_placeable(placements, targets) -> int:
    """Target cells of `placements` that allocation.order can place in some order."""
    from rad_core.allocation.order import hand_order
    from rad_core.domain.grid import Grid
    from rad_core.domain.scene import Scene
    scene = Scene(UNIT, dict(DEFAULT_LIBRARY), (), tuple(targets))
    found = hand_order(scene, placements)
    grid = Grid(scene)
    return int(sum(grid.is_target[list(cells)].sum() for cells in found.order))


def test_the_cover_is_one_a_top_down_hand_can_place_in_some_order(set_down_hand):
    # A 3 x 2 floor with a step of two cells on it. The fewest blocks (a cube, an L3 and an upright
    # 2 x 2) leave a piece the hand cannot take between its neighbours; three others can all go in.
    step = np.zeros((3, 2, 2), dtype=bool)
    step[:, :, 0] = True
    step[0, :, 1] = True
    targets = regions(step)
    blind, report = sp.choose_blocks(targets, UNIT, dict(DEFAULT_LIBRARY), params=sp.SupplyParams(hand=False))
    assert report.exact and report.hand_covered is None
    assert _hand_placeable(blind, targets) < 8
    placements, report = sp.choose_blocks(targets, UNIT, dict(DEFAULT_LIBRARY))
    assert report.exact and report.hand_covered == 8 and report.rounds >= 2
    assert _hand_placeable(placements, targets) == 8
    assert 'hand' not in report.summary()


def test_where_no_cover_can_be_placed_whole_the_report_says_how_much_can(set_down_hand):
    # A flush 3 x 3 floor at 5 cm: whatever the blocks, the last one has neighbours on both sides both
    # ways, and no row fits the open hand. The rounds' covers fill all nine cells, of which the hand
    # can place at most seven; the order model's cover leaves one out and the hand places all eight.
    floor = regions(np.ones((3, 3, 1), dtype=bool))
    placements, report = sp.choose_blocks(floor, UNIT, dict(DEFAULT_LIBRARY), params=sp.SupplyParams(hand_rounds=3))
    assert report.rounds == 3 and report.ordered
    assert report.covered == report.hand_covered == _hand_placeable(placements, floor) == 8
    assert 'these are the cells it can place in some order' in report.summary()
    assert report.to_dict()['hand_covered'] == report.hand_covered and report.to_dict()['ordered']


def test_hand_rounds_must_be_positive():
    with pytest.raises(RadError, match='hand_rounds'):
        sp.choose_blocks(regions(bar(2)), UNIT, types('cube', 'I2'), params=sp.SupplyParams(hand_rounds=0))


def test_the_scene_keeps_the_cover_as_its_design():
    scene, report = sp.supply(regions(chair()), UNIT, dict(DEFAULT_LIBRARY))
    assert sorted(p.type for p in scene.design) == sorted(b.type for b in scene.blocks)
    cells = [(p.target, c) for p in scene.design for c in p.cells]
    assert len(cells) == len(set(cells)) == report.covered + report.filler_cells
    lowest = [min(c[2] for c in p.cells) for p in scene.design]
    assert lowest == sorted(lowest) and lowest[-1] > 0          # course by course from the bottom

"""Whether a structure stands as a whole (`rad_core.domain.statics`), against PyBullet's verdict."""

import numpy as np
import pytest
from rad_core.domain import support
from rad_core.domain.grid import Grid
from rad_core.domain.statics import (FLOATS, MARGIN, TIPS, Statics, first_failure, order_statics, overhangs,
                                     structure_statics)
from rad_core.sim.physics import PhysicsStability

from scenes import U, scene

SIZE = (8, 2, 6)


@pytest.fixture(scope='module')
def grid():
    cells = [[i, j, k] for i in range(SIZE[0]) for j in range(SIZE[1]) for k in range(SIZE[2])]
    s = scene(targets=[{'name': 't', 'origin': [0.4, 0.1, U / 2], 'size': list(SIZE), 'filled': cells}])
    return Grid(s)


def ids(grid, *cells):
    return [grid.index(0, c) for c in cells]


def plate(grid, x, z, length=2):
    """A plate `length` long along x and two deep, its low end at x, on layer z."""
    return ids(grid, *[(i, j, z) for i in range(x, x + length) for j in (0, 1)])


def staircase(grid, steps):
    """Plates 4 long, each one unit further out than the one below, the lowest on the table."""
    return [plate(grid, k, k, 4) for k in range(steps)]


def weight(grid):
    """Two layers of units over the second plate's back end, clear of the plates above it."""
    return ids(grid, (1, 0, 2), (1, 1, 2), (1, 0, 3), (1, 1, 3))


@pytest.fixture(scope='module')
def physics():
    with PhysicsStability() as check:
        yield check


def physics_stands(physics, grid, pieces):
    centres = [grid.centres[p] for p in pieces]
    return physics(grid.unit, centres[:-1], centres[-1])[0]


def test_a_wall_with_every_unit_on_something_stands_without_a_solve(grid):
    bricks = [plate(grid, 0, 0), plate(grid, 2, 0), plate(grid, 1, 1)]
    assert overhangs(grid, bricks) == [] and structure_statics(grid, bricks).stands


def test_plates_stepping_out_each_rest_on_the_one_below_but_the_stair_tips_as_physics_says(grid, physics):
    occupied = np.zeros(grid.num_cells, dtype=bool)
    stair = staircase(grid, 5)
    for p in stair:                              # each one alone: its centre over the plate under it
        assert support.rests_on_its_own(grid, np.where(occupied, 0, -1), np.asarray(p))
        occupied[p] = True
    assert structure_statics(grid, stair[:3]).stands and physics_stands(physics, grid, stair[:3])
    verdict = structure_statics(grid, stair)
    assert not verdict.stands and verdict.falling
    assert not physics_stands(physics, grid, stair)


def test_a_block_on_the_back_end_holds_the_stair_down_as_in_physics(grid, physics):
    stair = staircase(grid, 4)                     # the second plate tips over the first's edge
    held = stair[:3] + [weight(grid), stair[3]]
    assert not structure_statics(grid, stair).stands
    assert structure_statics(grid, held).stands and physics_stands(physics, grid, held)


def test_ground_built_before_holds_like_the_table(grid):
    stair = staircase(grid, 4)
    ground = np.zeros(grid.num_cells, dtype=bool)
    ground[stair[0] + stair[1]] = True
    assert structure_statics(grid, stair[2:], ground).stands


def test_the_walk_places_a_piece_that_would_tip_once_a_later_one_holds_it_down(grid):
    stair = staircase(grid, 4)
    walk, waiting = order_statics(grid, stair + [weight(grid)])
    assert walk == [0, 1, 2, 4, 3] and waiting == []
    walk, waiting = order_statics(grid, stair)
    assert walk == [0, 1, 2] and waiting == [3]


# ---- clutch: studded bricks that lock --------------------------------------------------------

def bar(grid, length, z=1, x=0):
    """A bar `length` long along x, one deep, its low end at x, on layer z."""
    return ids(grid, *[(i, 0, z) for i in range(x, x + length)])


def column(grid):
    """Ground (built before, fixed) one cell at the grid's corner: the stud a cantilever hangs on."""
    ground = np.zeros(grid.num_cells, dtype=bool)
    ground[ids(grid, (0, 0, 0))] = True
    return ground


def threshold(length):
    """The pull (cell weights) the stud of a bar `length` long on its first unit must hold: moments
    about the edge of the square it rests on, whose corner forces act MARGIN inside the edge, at
    d = 0.5 - MARGIN from the stud at its centre. The bar's weight `length` at (length - 1) / 2 and
    the stud's pull at 0 are held by the push (length + pull) at d:
    (length + pull) * d = length * (length - 1) / 2. Without the margin (d = 0.5): 8 for length 4."""
    d = 0.5 - MARGIN
    return length * ((length - 1) / 2 / d - 1)


def pulls_off(other, need, clutch, studs=1):
    return (f"pulls off its studs: its connection to {other} must hold {need:.2f} times a cell's "
            f"weight over {studs} stud{'s' if studs > 1 else ''}, the clutch gives {studs * clutch:.2f}")


def test_without_clutch_nothing_changes_and_each_falling_piece_says_why(grid):
    stair = staircase(grid, 5)
    verdict = structure_statics(grid, stair)
    assert structure_statics(grid, stair, clutch=None) == verdict
    assert not verdict.stands and verdict.why == (TIPS,) * len(verdict.falling)


def test_a_cantilever_on_one_stud_stands_with_enough_clutch_exactly_past_the_moment_balance(grid):
    pull = threshold(4)
    assert pull == pytest.approx(9.3333333)
    cantilever, ground = [bar(grid, 4)], column(grid)
    assert structure_statics(grid, cantilever, ground) == structure_statics(grid, cantilever, ground, clutch=None)
    assert structure_statics(grid, cantilever, ground).why == (TIPS,)
    assert structure_statics(grid, cantilever, ground, clutch=pull * 1.001).stands
    short = structure_statics(grid, cantilever, ground, clutch=pull * 0.999)
    assert not short.stands and short.falling == (0,)
    assert short.why == (pulls_off('the ground', pull, pull * 0.999),)


def test_the_stud_between_two_pieces_is_what_pulls_off_where_the_table_holds_too(grid):
    column_piece, cantilever = ids(grid, (0, 0, 0)), bar(grid, 4)
    pull = threshold(4)
    # The column's own stud on the table needs less (pull - 1: the column's weight helps).
    assert structure_statics(grid, [column_piece, cantilever], clutch=pull * 1.001, table_clutch=True).stands
    short = structure_statics(grid, [column_piece, cantilever], clutch=pull * 0.999, table_clutch=True)
    assert short.falling == (1,) and short.why == (pulls_off('piece 0', pull, pull * 0.999),)
    # The table holds nothing down by default: column and bar tip over the column's edge together.
    loose = structure_statics(grid, [column_piece, cantilever], clutch=pull * 10)
    assert not loose.stands and loose.why == (TIPS,) * len(loose.falling)


def test_a_long_cantilever_pulls_off_even_with_a_typical_clutch(grid):
    clutch = 20.0                    # e.g. 2 N a stud holding 10 g cells; a 1 x 4 bar needs 9.33
    assert structure_statics(grid, [bar(grid, 4)], column(grid), clutch=clutch).stands
    verdict = structure_statics(grid, [bar(grid, 8)], column(grid), clutch=clutch)
    assert not verdict.stands and verdict.falling == (0,)
    assert threshold(8) == pytest.approx(54.2222222)
    assert verdict.why == (pulls_off('the ground', threshold(8), clutch),)


def test_a_bridge_over_two_columns_stands_with_or_without_clutch(grid):
    bridge = [ids(grid, (0, 0, 0)), ids(grid, (3, 0, 0)), bar(grid, 4)]
    assert overhangs(grid, bridge) == [2]                    # the program is solved
    assert structure_statics(grid, bridge).stands
    assert structure_statics(grid, bridge, clutch=1.0).stands


def test_a_piece_over_nothing_rests_on_nothing_clutch_or_not(grid):
    floating = [ids(grid, (0, 0, 0)), ids(grid, (2, 0, 2))]
    for clutch in (None, 5.0):
        assert structure_statics(grid, floating, clutch=clutch) == Statics(False, (1,), (FLOATS,))


def test_first_failure_names_the_step_and_what_gives_way(grid):
    assert first_failure(grid, staircase(grid, 3)) is None
    step, verdict = first_failure(grid, staircase(grid, 5))
    assert step == 3 and not verdict.stands and verdict.why == (TIPS,) * len(verdict.falling)
    stair = staircase(grid, 4)
    assert first_failure(grid, stair[:3] + [weight(grid), stair[3]]) is None
    # A bar on one stud, then a cube on its far end (it needs 15), then another (20.67).
    loaded = [bar(grid, 4), ids(grid, (3, 0, 2)), ids(grid, (3, 0, 3))]
    assert first_failure(grid, loaded, column(grid), clutch=21.0) is None
    step, verdict = first_failure(grid, loaded, column(grid), clutch=20.0)
    assert step == 2 and verdict.falling == (2,)          # the top cube: its load, relieved, costs least
    need = (4 * 1.5 + 2 * 3) / (0.5 - MARGIN) - 6
    assert verdict.why == ('falls with piece 0, which ' + pulls_off('the ground', need, 20.0),)
    assert first_failure(grid, loaded, column(grid))[0] == 0


def test_the_walk_carries_clutch(grid):
    assert order_statics(grid, [bar(grid, 4)], column(grid)) == ([], [0])
    assert order_statics(grid, [bar(grid, 4)], column(grid), clutch=10.0) == ([0], [])


def test_a_plate_two_studs_wide_needs_the_same_pull_per_stud(grid):
    plate_ = plate(grid, 0, 1, 4)
    ground = np.zeros(grid.num_cells, dtype=bool)
    ground[ids(grid, (0, 0, 0), (0, 1, 0))] = True
    pull = threshold(4)
    assert structure_statics(grid, [plate_], ground, clutch=pull * 1.001).stands
    short = structure_statics(grid, [plate_], ground, clutch=pull * 0.999)
    assert short.why == (pulls_off('the ground', 2 * pull, pull * 0.999, studs=2),)

"""Whether a structure stands as a whole (`rad_core.domain.statics`), against PyBullet's verdict."""

import numpy as np
import pytest
from rad_core.domain import support
from rad_core.domain.grid import Grid
from rad_core.domain.statics import order_statics, overhangs, structure_statics
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

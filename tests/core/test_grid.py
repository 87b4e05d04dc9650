"""The voxel grid's cell look-ups (`rad_core.domain.grid`)."""

import numpy as np
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.grid import Grid


def test_the_cell_below_each_cell_is_the_one_a_layer_down_in_its_region_and_none_on_the_bottom():
    grid = Grid(generate_scene(GeneratorConfig(grid=4, sides=2), 3))
    assert len(grid.regions) == 2
    for c in range(grid.num_cells):
        i, j, k = grid.ijk[c]
        want = -1 if k == 0 else grid.index(int(grid.region_of[c]), (i, j, k - 1))
        assert grid.below_idx[c] == want
    assert (grid.below_idx[grid.on_table] == -1).all() and grid.on_table.any()


def test_points_are_looked_up_together_and_one_off_the_grid_gives_none():
    grid = Grid(generate_scene(GeneratorConfig(grid=3, sides=2), 0))
    some = np.array([0, 5, grid.num_cells - 1])
    assert grid.cells_at(grid.centres[some]).tolist() == some.tolist()
    assert grid.cell_at(grid.centres[5] + 0.2 * grid.unit) is None          # between cells
    off = np.vstack([grid.centres[some], grid.centres[:1] - [0, 0, grid.unit]])   # under the table top
    assert grid.cells_at(off) is None


def test_the_columns_above_cells_run_to_the_regions_top_and_leave_out_the_cells_themselves():
    grid = Grid(generate_scene(GeneratorConfig(grid=4, sides=2), 3))
    assert grid.regions[0].size == (4, 1, 4)
    base = [grid.index(0, (1, 0, 0)), grid.index(0, (2, 0, 0)), grid.index(0, (2, 0, 1))]
    above = grid.columns_above(base).tolist()
    want = sorted([grid.index(0, (1, 0, k)) for k in range(1, 4)] + [grid.index(0, (2, 0, k)) for k in range(2, 4)])
    assert above == want
    assert grid.columns_above([grid.index(0, (0, 0, 3))]).tolist() == []      # the top layer

"""Geometric support rules: fast, conservative answers before physics is asked.

A unit is supported when it rests on the table or on a cell a placed block
fills. These rules look at cells only; PyBullet has the last word on stability.
"""

from __future__ import annotations

import numpy as np

from rad_core.grid import Grid


def _supported_units(grid: Grid, occupancy: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(supported, resting_on_own_unit) per unit of a block about to occupy cells."""
    below = grid.below_idx[cells]
    own = np.isin(below, cells)
    on_block = (below >= 0) & ~own & (occupancy[np.maximum(below, 0)] >= 0)
    return grid.on_table[cells] | on_block, own


def any_support(grid: Grid, occupancy: np.ndarray, cells: np.ndarray) -> bool:
    """False only when no unit rests on anything: the block would surely fall."""
    supported, _ = _supported_units(grid, occupancy, cells)
    return bool(supported.any())


def fully_supported(grid: Grid, occupancy: np.ndarray, cells: np.ndarray) -> bool:
    """Every unit rests on the table, a placed block, or a unit of the same block.

    The paper's HEUR baseline only takes placements that satisfy this.
    """
    supported, own = _supported_units(grid, occupancy, cells)
    return bool(np.all(supported | own))

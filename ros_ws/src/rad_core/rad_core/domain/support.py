"""Geometric support rules: fast, conservative answers before physics is asked.

A unit is supported when it rests on the table or on a cell a placed block
fills. These rules look at cells only; PyBullet has the last word on stability.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from rad_core.domain.grid import Grid


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


def rests_on_its_own(grid: Grid, occupancy: np.ndarray, cells: np.ndarray, margin: float = 0.05) -> bool:
    """Whether the block would stand on its supported units alone (those on the table or on a
    placed block): its centre of mass over their footprint, `margin` units inside (`com_inside`).
    True for a fully supported block and a lintel resting on both ends; False for a cantilever
    that needs something on it, or a counterweight, to stay up."""
    supported, _ = _supported_units(grid, occupancy, cells)
    if not supported.any():
        return False
    xy = grid.centres[cells][:, :2] / grid.unit
    return com_inside(xy[supported], xy.mean(axis=0), margin)


def com_inside(squares: np.ndarray, com: np.ndarray, margin: float = 0.05) -> bool:
    """Whether a block's centre of mass (xy, in cell units) lies inside the convex hull
    of the unit squares centred at `squares` (xy), at least `margin` from its edge:
    a rigid block on those supports alone cannot tip. A centre exactly over an edge
    tips in physics too (see physics.py), hence the margin."""
    corners = np.concatenate([squares + [dx, dy] for dx in (-0.5, 0.5) for dy in (-0.5, 0.5)])
    hull = convex_hull(corners)
    for a, b in zip(hull, np.roll(hull, -1, axis=0)):
        edge = b - a
        # Hull is counter-clockwise: inside is to the left of every edge.
        cross = edge[0] * (com[1] - a[1]) - edge[1] * (com[0] - a[0])
        if cross / np.hypot(*edge) < margin:
            return False
    return True


def convex_hull(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2-D points, counter-clockwise, without collinear points (monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 9))))
    if len(pts) < 3:
        return np.asarray(pts, dtype=float)

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.asarray(lower[:-1] + upper[:-1], dtype=float)


def sufficient_supports(cells: np.ndarray, bottom: list[int], max_bottom: int = 8) -> list[tuple[int, ...]]:
    """Minimal subsets of a block's bottom units (indices into cells, [k, 3] ijk) that
    hold it up on their own: the centre of mass over their convex footprint. More
    than max_bottom bottom units: only the whole bottom is offered."""
    com = cells[:, :2].mean(axis=0)
    if len(bottom) > max_bottom:
        return [tuple(bottom)] if com_inside(cells[bottom, :2].astype(float), com) else []
    found: list[tuple[int, ...]] = []
    for size in range(1, len(bottom) + 1):
        for subset in combinations(bottom, size):
            if any(set(f) <= set(subset) for f in found):
                continue
            if com_inside(cells[list(subset), :2].astype(float), com):
                found.append(subset)
    return found

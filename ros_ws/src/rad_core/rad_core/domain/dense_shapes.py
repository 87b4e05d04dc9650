"""Dense targets: solid boxes, two-deep walls and brick models, the designs labs build.

Unlike the generator's one-cell-deep faces and the hand-made shapes, every cell of these has
neighbours that are built too, most on both sides, so a hand that closes on one unit cannot set
the last blocks down (issue 40). They are given as boolean occupancy grids [i, j, k] (k up), the
form `voxels.Model` carries, so they become scenes as a user's voxel file does
(`voxels.place_regions`, then `allocation.supply.supply`: `benchmarks/bench_dense.py`).

- `BOXES` and `WALLS`: solid boxes and walls two cells deep, by their size in cells.
- `brick_model(n, seed)`: `n` two-wide bricks (2 x 2 and 2 x 4 studs, one unit high) stacked in
  courses and interlaced: each brick above the first course rests with at least half its cells on
  the bricks below and none of it over nothing by more than that; in a course, bricks sit flush side
  by side where they can. Seeded: the same (n, seed) gives the same model.
"""

from __future__ import annotations

import numpy as np

from rad_core.domain.errors import RadError

BOXES: dict[str, tuple[int, int, int]] = {
    'box4x2x2': (4, 2, 2), 'box3x3x2': (3, 3, 2), 'slab4x4': (4, 4, 1), 'tower2x2x3': (2, 2, 3),
    'box5x2x2': (5, 2, 2), 'box3x2x3': (3, 2, 3), 'box4x3x2': (4, 3, 2),
}
WALLS: dict[str, tuple[int, int, int]] = {'wall6x2x3': (6, 2, 3), 'wall8x2x2': (8, 2, 2), 'wall5x2x4': (5, 2, 4)}

FOOTPRINT = 8
"""Brick models stay within FOOTPRINT x FOOTPRINT cells (24 cm at a 3 cm unit)."""

_BRICKS = ((2, 2), (2, 4))


def solid(size: tuple[int, int, int]) -> np.ndarray:
    """A solid box of `size` cells (i, j, k)."""
    return np.ones(size, dtype=bool)


def brick_model(n: int, seed: int) -> np.ndarray:
    """`n` bricks stacked and interlaced (module docstring), cropped to its cells."""
    if not 1 <= n <= 40:
        raise RadError(f'a brick model has 1..40 bricks, got {n}')
    rng = np.random.default_rng(seed)
    grid = np.zeros((FOOTPRINT, FOOTPRINT, n + 1), dtype=bool)
    course, placed, misses = 0, 0, 0
    while placed < n:
        w, length = _BRICKS[int(rng.integers(len(_BRICKS)))]
        if rng.random() < 0.5:
            w, length = length, w
        spot = _spot(grid, course, w, length, rng)
        if spot is None:
            misses += 1
            if misses > 20 or course == 0 and grid[:, :, 0].any():
                course, misses = course + 1, 0       # this course is full enough: the next one
            continue
        i, j = spot
        grid[i:i + w, j:j + length, course] = True
        placed += 1
        # A course of one brick is no wall: two or three per course, then up.
        if grid[:, :, course].sum() >= int(rng.integers(8, 17)):
            course, misses = course + 1, 0
    return _crop(grid)


def _spot(grid: np.ndarray, k: int, w: int, length: int, rng) -> tuple[int, int] | None:
    """A free place for a w x length brick in course k: flush beside a brick of the course where
    there is one, resting on at least half its cells (k > 0), within the footprint."""
    layer = grid[:, :, k]
    options = []
    for i in range(FOOTPRINT - w + 1):
        for j in range(FOOTPRINT - length + 1):
            if layer[i:i + w, j:j + length].any():
                continue
            if k > 0 and grid[i:i + w, j:j + length, k - 1].sum() * 2 < w * length:
                continue
            if k == 0 and layer.any() and not _touches(layer, i, j, w, length):
                continue
            if k == 0 and not layer.any() and (i, j) != ((FOOTPRINT - w) // 2, (FOOTPRINT - length) // 2):
                continue
            options.append((i, j))
    if not options:
        return None
    return options[int(rng.integers(len(options)))]


def _touches(layer: np.ndarray, i: int, j: int, w: int, length: int) -> bool:
    """Whether a brick at (i, j) would sit flush against a brick of the course (side by side)."""
    along_i = layer[max(i - 1, 0):i + w + 1, j:j + length]
    along_j = layer[i:i + w, max(j - 1, 0):j + length + 1]
    return bool(along_i.any() or along_j.any())


def _crop(grid: np.ndarray) -> np.ndarray:
    idx = np.argwhere(grid)
    lo, hi = idx.min(axis=0), idx.max(axis=0) + 1
    return grid[lo[0]:hi[0], lo[1]:hi[1], 0:hi[2]]


def designs(brick_counts=(2, 3, 4, 6, 8, 10, 12), seeds=(0, 1)) -> dict[str, dict[str, np.ndarray]]:
    """The benchmark's designs by set: 'boxes', 'walls' and 'bricks' (name -> cells)."""
    return {
        'boxes': {name: solid(size) for name, size in BOXES.items()},
        'walls': {name: solid(size) for name, size in WALLS.items()},
        'bricks': {f'bricks{n}-s{s}': brick_model(n, s) for n in brick_counts for s in seeds},
    }


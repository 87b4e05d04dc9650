"""Duplo-style brick tasks of rad's own: 2 to 12 bricks (2 x 2 and 2 x 4), stacked course on course,
some bridging two bricks below, some turned, some reaching out past what holds them (clutch holds
them there), as people build with Duplo and as RoboCup's assembly tasks have them.

A task is a `BrickDesign` (`domain.brick_designs`), read as a file of the text format would be, so
it becomes a scene as a user's design does (`rad scene from-bricks`). Each brick is dropped on the
design from above at a place drawn among those where it rests on at least two studs (the table, for
the first course), its course the highest of the columns under it: a 2 x 4 over a 2 x 2 and the
table rests on the 2 x 2 and reaches out. Half of the bricks above the first course take a place
that bridges two bricks below where one is left. Seeded: the same (n, seed) is the same task.
Whether a task stands is the statics' verdict (`allocation.brick_scenes.design_verdict`), not the
generator's.
"""

from __future__ import annotations

import numpy as np

from rad_core.domain.brick_designs import PLATES_PER_BRICK, Brick, BrickDesign
from rad_core.domain.errors import RadError

FOOTPRINT = 6
"""Tasks stay within FOOTPRINT x FOOTPRINT studs."""

MAX_COURSES = 6

SIZES = ((2, 2), (4, 2))


def duplo_task(n: int, seed: int) -> BrickDesign:
    """A task of `n` bricks (module docstring)."""
    if not 2 <= n <= 24:
        raise RadError(f'a task has 2 to 24 bricks, not {n}')
    rng = np.random.default_rng([n, seed])
    height = np.zeros((FOOTPRINT, FOOTPRINT), dtype=int)        # courses filled in each stud column
    owner = np.full((FOOTPRINT, FOOTPRINT), -1, dtype=int)       # the brick on top of each column
    bricks: list[Brick] = []
    for k in range(n):
        shapes = [s if turn else s[::-1] for s in SIZES for turn in (True, False)]
        for i in rng.permutation(len(shapes)):          # the drawn shape, else another that has a place
            length, width = shapes[int(i)]
            places = _places(height, owner, length, width)
            if places:
                break
        else:
            raise RadError(f'task ({n}, {seed}): no place for brick {k} within {FOOTPRINT} x {FOOTPRINT} studs')
        bridging = [p for p in places if p[3] >= 2]
        pool = bridging if bridging and k and rng.random() < 0.5 else places
        lowest = min(p[2] for p in pool)
        pool = [p for p in pool if p[2] <= lowest + int(rng.integers(2))]
        x, y, z, _ = pool[int(rng.integers(len(pool)))]
        bricks.append(Brick(length, width, x, y, z * PLATES_PER_BRICK, PLATES_PER_BRICK, line=k + 1,
                            source=f'duplo_task({n},{seed})'))
        height[x:x + length, y:y + width] = z + 1
        owner[x:x + length, y:y + width] = k
    return BrickDesign(tuple(bricks), 'duplo', f'duplo{n}-s{seed}')


def _places(height: np.ndarray, owner: np.ndarray, length: int, width: int) -> list[tuple[int, int, int, int]]:
    """(x, y, course, bricks under it) of every place a brick can be dropped to: resting on at least
    two studs (or the table), at most MAX_COURSES up."""
    out = []
    for x in range(FOOTPRINT - length + 1):
        for y in range(FOOTPRINT - width + 1):
            columns = height[x:x + length, y:y + width]
            z = int(columns.max())
            if z >= MAX_COURSES:
                continue
            resting = columns == z
            if z and resting.sum() < 2:
                continue
            under = len({int(b) for b in owner[x:x + length, y:y + width][resting]}) if z else 0
            out.append((x, y, z, under))
    return out


def duplo_tasks(counts=range(2, 13), seeds=range(2)) -> list[BrickDesign]:
    """A task per brick count and seed."""
    return [duplo_task(n, s) for n in counts for s in seeds]

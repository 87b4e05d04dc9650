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

And LEGO-style designs of 24 to 186 bricks (`lego_designs`), in the text format, built course by
course (`Builder`): walls one and two studs deep in running bond whose top courses corbel out past
an end, a tower of four bonded walls, the letters T, E, F, P standing up, an arch whose lintel steps
out past a pillar, a chair, and two cantilevers too long for their clutch. Every brick rests on at
least one stud of the course under it, so a robot can press it home from above; the overhangs stand
by the bricks' clutch. benchmarks/bench_statics_twin.py judges their intermediate structures.
"""

from __future__ import annotations

import itertools
import math

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


LENGTHS = (4, 2, 3, 6, 8, 1, 10)
"""Brick lengths (studs) a row is tiled with, fours preferred: 1 x N and 2 x N bricks LEGO makes."""


class Builder:
    """A design in the text format, course by course, every brick resting on at least one stud of
    the course under it (or the table): a design a robot presses together from above. A row of
    studs is tiled with bricks of `LENGTHS`, the cheapest tiling: a brick costs 0.5, 0.25 a stud it is
    longer or shorter than four, 1 where its end falls over a joint of the course under it (so
    courses run in bond), and 0.05 for each of its studs over nothing, more the further they reach
    out (`hangs`)."""

    def __init__(self):
        self.owner: dict[tuple[int, int, int], int] = {}
        self.lines: list[str] = []

    def row(self, z: int, studs, depth: int = 1, at: int = 0, along: str = 'x', lengths=LENGTHS) -> None:
        """Tile the studs (along `along`) of course z, `depth` studs deep from `at` on the other axis,
        with bricks of these lengths."""
        for a, b in _runs(studs):
            self._run(z, a, b, depth, at, along, lengths)

    @staticmethod
    def _cell(along: str, i: int, j: int, z: int) -> tuple[int, int, int]:
        return (i, j, z) if along == 'x' else (j, i, z)

    def _run(self, z: int, a: int, b: int, depth: int, at: int, along: str, lengths) -> None:
        def cells(start, n, zz=z):
            return [self._cell(along, start + i, at + j, zz) for i in range(n) for j in range(depth)]

        def held(start, n) -> list[bool]:
            """Per stud along the brick: whether the course under it holds it there."""
            return [z == 0 or any(self._cell(along, start + i, at + j, z - 1) in self.owner for j in range(depth))
                    for i in range(n)]

        def hangs(start, n) -> float:
            """What the brick's studs over nothing cost: each run of them squared at an end of the
            brick (a cantilever's moment grows so), a half run squared between two held studs;
            infinite where none is held."""
            under = held(start, n)
            if not any(under):
                return math.inf
            cost, i = 0.0, 0
            for key, run in itertools.groupby(under):
                k = len(list(run))
                if not key:
                    cost += k * k if i == 0 or i + k == n else (k / 2) ** 2
                i += k
            return cost

        def over_joint(x):
            """Whether a joint at x (between studs x - 1 and x) lies over a joint of the course under it."""
            for j in range(depth):
                lo = self.owner.get(self._cell(along, x - 1, at + j, z - 1))
                hi = self.owner.get(self._cell(along, x, at + j, z - 1))
                if lo is not None and hi is not None and lo != hi:
                    return True
            return False

        n = b - a
        best = [(math.inf, None)] * (n + 1)
        best[0] = (0.0, None)
        for i in range(n):
            if best[i][0] == math.inf:
                continue
            for k in lengths:
                hanging = hangs(a + i, k) if i + k <= n else math.inf
                if hanging == math.inf:
                    continue
                cost = best[i][0] + 0.5 + 1.0 * (i > 0 and over_joint(a + i)) + 0.25 * abs(k - 4) + 0.05 * hanging
                if cost < best[i + k][0]:
                    best[i + k] = (cost, (i, k))
        if best[n][0] == math.inf:
            raise ValueError(f'course {z}: studs {a}..{b - 1} cannot all rest on the course under them')
        pieces, i = [], n
        while i:
            i, k = best[i][1]
            pieces.append((i, k))
        for i, k in sorted(pieces):
            if along == 'x':
                self.lines.append(f'{k}x{depth} ({a + i},{at},{z})')
            else:
                self.lines.append(f'{depth}x{k} ({at},{a + i},{z})')
            for cell in cells(a + i, k):
                self.owner[cell] = len(self.lines) - 1

    def text(self) -> str:
        """The design in the text format."""
        return '\n'.join(self.lines) + '\n'


def _runs(xs) -> list[tuple[int, int]]:
    """Sorted integers as (start, end) runs of consecutive values, end exclusive."""
    out: list[tuple[int, int]] = []
    for x in sorted(xs):
        if out and out[-1][1] == x:
            out[-1] = (out[-1][0], x + 1)
        else:
            out.append((x, x + 1))
    return out


def wall(length: int, courses: int, depth: int = 1, reach: int = 0, corbel: int = 0) -> str:
    """A wall `length` studs long, `depth` deep, in running bond; its top `corbel` courses step out
    past its right end, one stud a course (more where `reach` asks more), to `reach` studs out."""
    build = Builder()
    for z in range(courses):
        k = z - (courses - corbel)
        out = 0 if k < 0 else round(reach * (k + 1) / corbel)
        build.row(z, range(length + out), depth)
    return build.text()


def box_tower(width: int, depth: int, courses: int, reach: int = 0, corbel: int = 0) -> str:
    """Four walls one stud thick round a width x depth footprint, their corners bonded (the front and
    back walls run through the corners on even courses, the sides on odd ones); the top `corbel`
    courses of the front wall (y = 0) step out past the right side, to `reach` studs at the top (an
    odd course as far as the even one under it)."""
    build = Builder()
    for z in range(courses):
        k = z - z % 2 - (courses - corbel)
        out = 0 if k < 0 else round(reach * (k + 1) / corbel)
        if z % 2 == 0:
            build.row(z, range(width + out), 1, 0)
            build.row(z, range(width), 1, depth - 1)
            for x in (0, width - 1):
                build.row(z, range(1, depth - 1), 1, x, along='y')
        else:
            for x in (0, width - 1):
                build.row(z, range(depth), 1, x, along='y')
            build.row(z, [*range(1, width - 1), *range(width, width + out)], 1, 0)
            build.row(z, range(1, width - 1), 1, depth - 1)
    return build.text()


LETTERS = {
    # Rows top first; each character `stroke` studs wide and `rows` courses high where '#'.
    'T': ['###',
          '.#.',
          '.#.',
          '.#.',
          '.#.'],
    'F': ['###',
          '#..',
          '##.',
          '#..',
          '#..'],
    'E': ['###',
          '#..',
          '##.',
          '#..',
          '###'],
    'P': ['###',
          '#.#',
          '###',
          '#..',
          '#..'],
}


def letter(ch: str, stroke: int = 4, rows: int = 4) -> str:
    """The letter standing up, two studs deep: each character of `LETTERS[ch]` is `stroke` studs wide
    and `rows` courses high."""
    pattern = LETTERS[ch]
    build = Builder()
    for z in range(len(pattern) * rows):
        row = pattern[len(pattern) - 1 - z // rows]
        build.row(z, [c * stroke + i for c, v in enumerate(row) if v == '#' for i in range(stroke)], 2)
    return build.text()


def arch(pillar: int = 4, gap: int = 8, legs: int = 10, lintel: int = 3, reach: int = 6) -> str:
    """Two pillars `pillar` studs wide, two deep, `legs` courses high, `gap` studs apart; a lintel of
    `lintel` courses across them stepping out past the right pillar, `reach` studs at its top."""
    build = Builder()
    span = 2 * pillar + gap
    for z in range(legs):
        build.row(z, [*range(pillar), *range(pillar + gap, span)], 2)
    for k in range(lintel):
        build.row(legs + k, range(span + round(reach * k / max(1, lintel - 1))), 2)
    return build.text()


def chair(size: int = 10, legs: int = 8, back: int = 7) -> str:
    """Four legs of 2 x 2 studs at the corners of a size x size seat (at most 10), `legs` courses high;
    the seat: two beams along x bridging the legs, bricks along y bridging the beams, a course along
    x on top; a backrest one stud deep along the back edge, `back` courses high."""
    build = Builder()
    for z in range(legs):
        for x in (0, size - 2):
            build.row(z, [*range(2), *range(size - 2, size)], 2, x, along='y')
    for y in (0, size - 2):
        build.row(legs, range(size), 2, y, lengths=(size,))
    for x in range(0, size, 2):
        build.row(legs + 1, range(size), 2, x, along='y', lengths=(size,))
    for y in range(0, size, 2):
        build.row(legs + 2, range(size), 2, y)
    for z in range(back):
        build.row(legs + 3 + z, range(size), 1, size - 1)
    return build.text()


def diving_board(base: int = 8, courses: int = 10, reach: int = 14, steps: int = 4) -> str:
    """A wall `base` studs long, two deep, `courses` high, and on it a board of `steps` courses, each
    reaching further past the wall's right end, `reach` studs at the top: too far. Its last brick
    tips the whole on the table where the wall is light (6, 14, 18, 6), pulls off its studs where the
    wall is heavy (10, 8, 14, 2)."""
    build = Builder()
    for z in range(courses):
        build.row(z, range(base), 2)
    for k in range(steps):
        build.row(courses + k, range(base + round(reach * (k + 1) / steps)), 2)
    return build.text()


def lego_designs(quick: bool = False) -> dict[str, list[tuple[str, str]]]:
    """Set -> (name, text) of the generated LEGO-style designs."""
    sets = {
        'walls': [('wall-1x', wall(12, 18, 1, reach=12, corbel=6)),
                  ('wall-2x', wall(16, 20, 2, reach=8, corbel=5)),
                  ('tower', box_tower(13, 8, 20, reach=8, corbel=6))],
        'letters': [(f'letter-{ch}', letter(ch)) for ch in 'TEFP'],
        'arch, chair, cantilevers': [('arch', arch(5, 6, 14, 4, 6)), ('chair', chair()),
                                     ('cantilever-too-long', diving_board(6, 14, 18, 6)),
                                     ('board-too-long', diving_board(10, 8, 14, 2))],
    }
    if quick:
        sets = {'walls': sets['walls'][:1], 'letters': sets['letters'][:1],
                'arch, chair, cantilevers': sets['arch, chair, cantilevers'][2:3]}
    return sets

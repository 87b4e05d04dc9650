"""Large hand-made targets, 45 to 100 blocks, with every block in a feeder.

Structures this size do not fit on the table within the arm's reach (a g = 5 scene's
ten blocks already fill much of it), so their blocks arrive from a feeder at a pick
station (`rad_core.domain.scene.Feeder`, order `request`). The targets are drawn as the other
hand-made shapes are (`rad_core.domain.shapes.face`, `layers`) at a 4 cm unit, so the largest
stays within the reach of a top-down hand (the far cells at 0.72 m from the base):

- `cavity_wall`: a cavity wall, two leaves 12 x 8 with a two-cell cavity between them, with a
  door and two windows under lintels;
- `tower`: a hollow square tower, 4 x 4 in plan, 10 layers high;
- `cavity_viaduct`: a bridge, two leaves 12 x 6 around a cavity, on four piers with three
  openings, its deck on lintels;
- `cavity_steps`: a cavity wall that steps down from 8 layers to 2, a staircase;
- `tall_cavity_wall`: the cavity wall with three more courses above its lintels, 100 blocks.

And three with the two leaves flush, back to back (the generator's two-sided layout, filled):
`wall_openings`, `viaduct` and `stepped_wall`. A parallel gripper setting blocks down from above cannot
fill such a wall whatever the order: every full course loses a cell (`FLUSH_LIMIT`). The hand fills
them by dropping the last block of a course into its place (`gamp.planner.GampConfig.drop`).

Their block multisets are exact stable tilings by small types plus a few spares: for the
faces a bond drawn course by course (`coursed_tiling`: bars of three and two, joints staggered
between courses, a four-bar over each two-cell opening, resting on both sides), for the
tower `shapes.tile_exact` (a backtracking search, too slow on the faces' 96 cells with
openings). None is used in training: they are for measuring how planning scales with the
structure's size.
"""

from __future__ import annotations

from functools import lru_cache

from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene, feeder_of
from rad_core.domain.shapes import (
    RegionSpec,
    ShapeSpec,
    block_multiset,
    face,
    layers,
    one_sided,
    target_regions,
    two_sided,
)

UNIT = 0.04
STATION = (0.42, -0.32)
"""Where the feeder presents blocks: right of the structures, within reach."""
CAVITY = 2
"""The cavity between the two leaves of a cavity wall, in cells: 8 cm at a 4 cm unit, room for a
finger (the hand closes across a bar of a leaf, one finger outside, one in the cavity)."""

FLUSH_LIMIT = """Why a two-deep flush wall cannot be filled by top-down parallel-jaw grasps that set each block
down (GAMP's drop, held by its top and let go over its place, gets around it). Take any course
and the block placed last in it. The hand closes either across the wall, with one finger where
the other leaf's block of this course lies, or along the wall, with a finger where the block
beside it in its own leaf lies (and a bar of two or more cells, 8 cm and up, does not fit the
8 cm opening that way anyway). When the course is otherwise full, both are filled: no course
of such a wall can be completed (unless an opening leaves its last cell free on two opposite
sides). A cavity wall's leaves have a free side each, the cavity."""

_WALL_ROWS = (
    '############',
    '############',
    '##..####..##',
    '##..####..##',
    '#####..#####',
    '#####..#####',
    '#####..#####',
    '#####..#####')
_WALL = face(*_WALL_ROWS)
_TALL = face(*['############'] * 3, *_WALL_ROWS)
_VIADUCT = face(
    '############',
    '############',
    '#..##..##..#',
    '#..##..##..#',
    '#..##..##..#',
    '#..##..##..#')
_STEPS = face(
    '##..........',
    '####........',
    '######......',
    '########....',
    '##########..',
    '############',
    '############',
    '############')
_RING = ('####', '#..#', '#..#', '####')
SMALL_TYPES = ('cube', 'I2', 'I3', 'bar4')


def cavity(drawn, gap: int = CAVITY) -> tuple[RegionSpec, ...]:
    """A face drawn with `face` as a cavity wall: one region, its two leaves the face at depth 0 and
    at depth gap + 1, the cavity between them empty."""
    (w, _, h), cells = drawn
    return one_sided(((w, gap + 2, h), [(i, j, k) for i, _, k in cells for j in (0, gap + 1)]))

LARGE_SPECS = {
    spec.name: spec for spec in (
        ShapeSpec('wall_openings', 'wall', two_sided(_WALL, _WALL), SMALL_TYPES, ('cube', 'I2'), n_spare=6,
                  why='a wall with a door and two windows, each under a lintel'),
        ShapeSpec('tower', 'tower', one_sided(layers(*[_RING] * 10)), ('cube', 'I2', 'I3', 'L3'),
                  ('cube', 'I2'), n_spare=5, why='a hollow tower: each layer a closed ring, the last piece '
                                                  'of a ring taken by its free sides'),
        ShapeSpec('viaduct', 'bridge', two_sided(_VIADUCT, _VIADUCT), SMALL_TYPES, ('cube', 'I2'), n_spare=5,
                  why='three openings bridged by four-bars, two deep'),
        ShapeSpec('stepped_wall', 'stairs', two_sided(_STEPS, _STEPS), ('cube', 'I2', 'I3'), ('cube', 'I2'),
                  n_spare=5, why='a staircase wall, tall at the far end'),
        ShapeSpec('cavity_wall', 'wall', cavity(_WALL), SMALL_TYPES, ('cube', 'I2'), n_spare=6,
                  why='a cavity wall with a door and two windows, each under a lintel'),
        ShapeSpec('tall_cavity_wall', 'wall', cavity(_TALL), SMALL_TYPES, ('cube', 'I2'), n_spare=8,
                  why='the cavity wall three courses taller: 100 blocks, 0.44 m high'),
        ShapeSpec('cavity_viaduct', 'bridge', cavity(_VIADUCT), SMALL_TYPES, ('cube', 'I2'), n_spare=5,
                  why='three openings bridged by four-bars, in two leaves around a cavity'),
        ShapeSpec('cavity_steps', 'stairs', cavity(_STEPS), ('cube', 'I2', 'I3'), ('cube', 'I2'),
                  n_spare=5, why='a staircase cavity wall, tall at the far end'),
    )
}
FLUSH = ('wall_openings', 'viaduct', 'stepped_wall')
"""The two-deep flush ones (`FLUSH_LIMIT`)."""


def coursed_tiling(cells) -> list[str]:
    """The types of a bond tiling a one-cell-deep face (cells (i, 0, k)) course by course: where a
    course spans a two-cell opening in the course below, a four-bar lintel rests on both sides of
    it; the rest of each run is bars of three (of two and cubes at its end), odd courses starting
    with a bar of two so the joints are staggered."""
    cells = {(int(i), int(k)) for i, _, k in cells}
    kinds = []
    for k in sorted({k for _, k in cells}):
        row = sorted(i for i, kk in cells if kk == k)
        taken = set()
        if k > 0:
            for i in row:        # a two-cell gap below, walls on both sides of it: a lintel
                gap = [(i + d, k - 1) not in cells for d in (1, 2)]
                sides = (i, k - 1) in cells and (i + 3, k - 1) in cells
                span = {i, i + 1, i + 2, i + 3}
                if all(gap) and sides and span <= set(row) and not span & taken:
                    taken |= span
                    kinds.append('bar4')
        runs, run = [], []
        for i in row:
            if i in taken:
                continue
            if run and i != run[-1] + 1:
                runs.append(run)
                run = []
            run.append(i)
        if run:
            runs.append(run)
        for run in runs:
            n, first = len(run), k % 2 == 1 and len(run) > 3
            if first:
                kinds.append('I2')
                n -= 2
            kinds += ['I3'] * (n // 3) + [{0: None, 1: 'cube', 2: 'I2'}[n % 3]] * (n % 3 > 0)
    return kinds


def _multiset(spec: ShapeSpec) -> list[str]:
    if spec.name == 'tower':
        return block_multiset(spec)
    kinds = [kind for region in spec.regions for j in sorted({c[1] for c in region.cells})    # leaf by leaf
             for kind in coursed_tiling([c for c in region.cells if c[1] == j])]
    spares = spec.spare_types
    return kinds + [spares[n % len(spares)] for n in range(spec.n_spare)]


@lru_cache(maxsize=None)
def large_scene(name: str) -> Scene:
    """The target with every block of its multiset in a feeder at `STATION` (one scene per shape: a
    feeder has no layout to vary)."""
    try:
        spec = LARGE_SPECS[name]
    except KeyError:
        raise RadError(f'unknown large shape {name!r} (known: {", ".join(LARGE_SPECS)})') from None
    return feeder_scene(spec)


def feeder_scene(spec: ShapeSpec, unit: float = UNIT) -> Scene:
    """A shape drawn as the large ones are, with every block of its multiset in a feeder at `STATION`;
    at `UNIT` or the unit (m) given."""
    kinds = _multiset(spec)
    blocks, feeder = feeder_of(kinds, spec.types, STATION, unit)
    used = [n for n in spec.types if n in set(kinds)]
    scene = Scene(unit, {n: spec.types[n] for n in used}, tuple(blocks), target_regions(spec, unit), feeder=feeder)
    return Scene.from_dict(scene.to_dict())

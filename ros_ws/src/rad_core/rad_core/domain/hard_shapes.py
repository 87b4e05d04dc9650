"""Hard hand-made scenes: the shapes the hard-shape figures are measured on.

`rad_core.domain.shapes` draws targets unlike the generator's, but at one unit (5 cm), one
place (0.5 m in front of the robot), with blocks 5 cm apart on the table and only
types the open hand can take. The cases here keep its drawing and tiling machinery
and add what makes a build hard for the arm rather than for the sequencer alone:

- flat blocks wider than one unit: pentominoes (P5, L5, T5) that lie on the table and
  can be taken only by the one unit whose sides are free, and 2x2 squares (O4) that the
  open hand cannot take from above at all (`gamp.grasps.block_grasps` is empty). O4s are
  DECOYS: a blind allocation uses them (one block covers four cells), an arm-aware one
  must route around them, so every scene with them also carries a tiling without them;
- targets two cells deep (the paper's back-to-back faces, and solids drawn in plan), where
  the fingers of a top-down grasp need the cells beside the grasped unit still empty:
  bridges, arches, a pyramid on a box, decks over gaps, overhangs;
- blocks packed tight on the table (2 cm apart instead of 5), and blocks laid out to
  0.70 m from the base instead of 0.63 m;
- targets moved to the edge of reach (their far cells 0.70-0.75 m from the base, where a
  top-down hand still reaches, measured with `gamp.ik.solve_top_down`) or off to one side;
- 4 cm units beside 5 cm ones.

Every case is buildable in principle at the level of cells: `buildable_tiling` finds an
exact tiling of the target by its (graspable) tiling types together with an order in which
every piece rests stably when placed, comes down from above through empty columns and is
held by a unit whose two finger sides are still free (what GAMP needs on a flush scene:
`gamp.grasps.block_grasps` and fingers that stand in the neighbouring cells). That rules
out some drawings: a flush solid whose top is 2x2 cells or more can never be finished, as
its last piece has neighbours on every side; such tops here carry a one-cell-deep ridge,
kerb or span that upright pieces rise into. This cell model leaves out the arm and the
palm, so GAMP may still refuse a step it allows; the exact planner measures that.

`HARD_SPLITS` keeps at least ten cases out of training; those are what reports measure.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Mapping, Sequence

import numpy as np

from rad_core.domain.blocks import BlockType
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene, TargetRegion
from rad_core.domain.shapes import (
    LAYOUT_ATTEMPTS,
    LIBRARY,
    STRUCTURE_X,
    Cell,
    LayoutConfig,
    ShapeSpec,
    face,
    lay_out,
    layers,
    one_sided,
    rests_stably,
    target_regions,
    two_sided,
)

# Flat block types no other scene set has. Each lies on the table; P5, L5, T5 and I5 keep
# one unit with both sides of one axis free (so the hand takes them there); O4 and O6 have
# none: every unit has a neighbour along x and along y.
HARD_TYPES: dict[str, BlockType] = {
    name: BlockType.from_cells(name, cells) for name, cells in {
        'P5': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 2, 0]],
        'L5': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [0, 1, 0]],
        'T5': [[1, 0, 0], [1, 1, 0], [0, 2, 0], [1, 2, 0], [2, 2, 0]],
        'I5': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [4, 0, 0]],
        'O4': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
        'O6': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]],
    }.items()
}
HARD_LIBRARY: dict[str, BlockType] = {**LIBRARY, **HARD_TYPES}
UNGRASPABLE = ('O4', 'O6')
"""Types the open hand cannot take from above: never part of a tiling, only decoys."""

# Families of types a case tiles with.
FLAT = ('cube', 'I2', 'I3', 'L3', 'T4')
UPRIGHT = ('I2_up', 'L3_up', 'T4_up', 'S4_up')
PENTO = ('P5', 'L5', 'T5')

TIGHT = LayoutConfig(gap=0.02)
"""Blocks 2 cm apart on the table: the open hand (8 cm) barely fits between two."""
FAR = LayoutConfig(reach=(0.34, 0.70), jitter=0.12)
"""Blocks spread out to 0.70 m from the base (a top-down hand reaches about 0.75 m at the table)."""
TIGHT_FAR = LayoutConfig(reach=(0.34, 0.70), gap=0.02, jitter=0.12)

EDGE_RADIUS = 0.75
"""No target cell centre lies farther than this (m, in plan) from the base: measured, a
top-down hand reaches the table at 0.75 m and no longer at 0.80 m (`solve_top_down`)."""


@dataclass(frozen=True)
class HardSpec(ShapeSpec):
    """A ShapeSpec whose types may be the flat ones above, plus decoys.

    decoys: blocks added on top of the tiling and the spares, of types the hand cannot
    take (O4, O6): the target can be filled without them, a blind allocation would not.
    """

    decoys: tuple[str, ...] = ()

    def __post_init__(self):
        names = tuple(dict.fromkeys(self.tiling_types + self.spare_types + self.decoys))
        unknown = [n for n in names if n not in HARD_LIBRARY]
        if unknown:
            raise RadError(f'hard shape {self.name!r}: unknown block types {unknown} '
                           f'(known: {", ".join(HARD_LIBRARY)})')
        bad = [n for n in self.tiling_types + self.spare_types if n in UNGRASPABLE]
        if bad:
            raise RadError(f'hard shape {self.name!r}: {bad} cannot be grasped; list them as decoys, not as '
                           'tiling or spare types')
        object.__setattr__(self, 'types', {n: HARD_LIBRARY[n] for n in names})


@dataclass(frozen=True)
class HardCase:
    """One scene: a shape, its unit, how its blocks lie and where the target stands.

    at: (x, y) of the target's footprint centre (m); shapes.py puts it at (0.5, 0).
    hard: what makes the case hard, for the report.
    """

    spec: HardSpec
    unit: float = 0.05
    layout: LayoutConfig = LayoutConfig()
    at: tuple[float, float] = (STRUCTURE_X, 0.0)
    hard: str = ''

    @property
    def name(self) -> str:
        return self.spec.name


# ---- tiling, blocks and the scene -------------------------------------------

Piece = tuple[str, int, tuple[Cell, ...]]


def region_shifts(spec: ShapeSpec) -> list[tuple[int, int, int]]:
    """Each region's offset (cells) on one lattice shared by all regions: back-to-back
    faces are one cell apart in y, so a finger beside one face's cell is in the other's."""
    origins = np.asarray([t.origin for t in target_regions(spec, 1.0)])
    return [tuple(int(v) for v in np.rint(o - origins.min(axis=0))) for o in origins]


def _orientations(types: Mapping[str, BlockType], rng: np.random.Generator) -> list[tuple[str, int, list[Cell]]]:
    """Every distinct orientation, shifted so its lowest cell (z, x, y order) is at 0; large first."""
    shapes = []
    for name, t in types.items():
        for yaw in t.distinct_yaws():
            offs = t.rotated(yaw)
            low = min(offs.tolist(), key=lambda c: (c[2], c[0], c[1]))
            shapes.append((name, yaw, [tuple(int(v) for v in o - np.asarray(low)) for o in offs]))
    order = rng.permutation(len(shapes))
    return sorted((shapes[n] for n in order), key=lambda s: -len(s[2]))


@lru_cache(maxsize=None)
def buildable_tiling(spec: ShapeSpec, max_nodes: int = 200_000) -> tuple[tuple[int, Piece], ...]:
    """An exact tiling of the target by the tiling types, in an order a top-down hand can
    build: (region index, piece in world-lattice cells), in build order.

    A depth-first search that always covers the lowest free cell (z, x, y) with a piece
    that rests stably (`shapes.rests_stably`) and can be brought in now (`_free_grasp`),
    and remembers dead ends. Unlike `shapes.tile_exact` followed by an order, the tiling
    it finds is one the hand can finish: in a flush solid two cells deep the last piece of
    a layer has neighbours on every side, and only an upright piece whose top unit stands
    above the layer can still be held. Pieces stay within one region, as allocations do.
    """
    rng = np.random.default_rng(spec.tiling_seed)
    shapes = _orientations({n: HARD_LIBRARY[n] for n in spec.tiling_types}, rng)
    owner = {}
    for r, (region, shift) in enumerate(zip(spec.regions, region_shifts(spec))):
        for c in region.cells:
            owner[(c[0] + shift[0], c[1] + shift[1], c[2] + shift[2])] = r
    free, occupied = set(owner), set()
    out: list[tuple[int, Piece]] = []
    dead: set[frozenset] = set()
    nodes = 0

    def search() -> bool:
        nonlocal nodes
        if not free:
            return True
        key = frozenset(free)
        if key in dead:
            return False
        nodes += 1
        if nodes > max_nodes:
            raise RadError(f'hard shape {spec.name!r}: the buildable tiling search gave up after {max_nodes} nodes')
        seed = min(free, key=lambda c: (c[2], c[0], c[1]))
        for name, yaw, offs in shapes:
            placed = tuple((seed[0] + o[0], seed[1] + o[1], seed[2] + o[2]) for o in offs)
            if not all(p in free and owner[p] == owner[seed] for p in placed):
                continue
            if not rests_stably(placed, occupied) or not _free_grasp(placed, occupied):
                continue
            free.difference_update(placed)
            occupied.update(placed)
            out.append((owner[seed], (name, yaw, placed)))
            if search():
                return True
            out.pop()
            occupied.difference_update(placed)
            free.update(placed)
        dead.add(key)
        return False

    if not search():
        raise RadError(f'hard shape {spec.name!r}: no exact tiling with {sorted(spec.tiling_types)} that a top-down '
                       'hand can build in order; add upright types or change the drawing')
    return tuple(out)


def hard_tiling(spec: HardSpec) -> list[list[Piece]]:
    """The buildable tiling's pieces per region, in region cells (as `shapes.tiling`)."""
    shifts = region_shifts(spec)
    out: list[list[Piece]] = [[] for _ in spec.regions]
    for r, (name, yaw, cells) in buildable_tiling(spec):
        s = shifts[r]
        out[r].append((name, yaw, tuple((c[0] - s[0], c[1] - s[1], c[2] - s[2]) for c in cells)))
    return out


def hard_multiset(spec: HardSpec) -> list[str]:
    """The tiling's types, region by region, then the spares, then the decoys (fixed per spec)."""
    rng = np.random.default_rng(spec.tiling_seed + 1)
    kinds = [name for pieces in hard_tiling(spec) for name, _, _ in pieces]
    spares = spec.spare_types or spec.tiling_types
    kinds += [str(spares[int(rng.integers(len(spares)))]) for _ in range(spec.n_spare)]
    return kinds + list(spec.decoys)


def hard_regions(case: HardCase) -> tuple[TargetRegion, ...]:
    """shapes.target_regions at the case's unit, moved so the footprint centre is at `case.at`."""
    dx, dy = case.at[0] - STRUCTURE_X, case.at[1]
    return tuple(TargetRegion(t.name, (round(t.origin[0] + dx, 6), round(t.origin[1] + dy, 6), t.origin[2]),
                              t.size, t.filled) for t in target_regions(case.spec, case.unit))


def build_hard_scene(case: HardCase, seed: int = 0) -> Scene:
    """The case's scene; the seed only moves the blocks on the table (as shapes.build_scene)."""
    rng = np.random.default_rng(seed)
    kinds = hard_multiset(case.spec)
    rng.shuffle(kinds)
    targets = hard_regions(case)
    for attempt in range(LAYOUT_ATTEMPTS):
        last = attempt == LAYOUT_ATTEMPTS - 1
        config = replace(case.layout, jitter=0.0 if last else case.layout.jitter / 2 ** attempt)
        try:
            blocks = lay_out(kinds, case.spec.types, targets, rng, case.unit, config)
            break
        except RadError as e:
            if last:
                raise RadError(f'hard shape {case.name!r}: {e}; give the layout more reach or a smaller gap, '
                               'or the scene fewer spares') from None
    used = [n for n in case.spec.types if n in set(kinds)]
    scene = Scene(case.unit, {n: case.spec.types[n] for n in used}, tuple(blocks), targets)
    return Scene.from_dict(scene.to_dict())


# ---- what a flush top-down hand can do ---------------------------------------

def _column_clear(cells: Sequence[Cell], occupied: set[Cell]) -> bool:
    """Whether nothing built lies above any of the piece's cells: it comes down vertically."""
    top = max(c[2] for c in cells) + 8
    return not any((x, y, k) in occupied for x, y, z in cells for k in range(z + 1, top))


def _finger_room(cells: Sequence[Cell], occupied: set[Cell]) -> bool:
    """Whether some unit with no own unit above it has both sides along x, or both along y,
    free of own units and built cells at its level and the next (the fingers stand there,
    as `gamp.grasps.block_grasps` and a flush scene's neighbours allow)."""
    own = set(cells)
    for x, y, z in cells:
        if (x, y, z + 1) in own:
            continue
        for dx, dy in ((1, 0), (0, 1)):
            beside = [(x + s * dx, y + s * dy, z + k) for s in (1, -1) for k in (0, 1)]
            if not any(c in own or c in occupied for c in beside):
                return True
    return False


def _free_grasp(cells: Sequence[Cell], occupied: set[Cell]) -> bool:
    """Whether a flush top-down hand can bring the piece down onto these cells now."""
    return _column_clear(cells, occupied) and _finger_room(cells, occupied)


def order_problem(pieces: Sequence[Sequence[Cell]]) -> str:
    """'' if the pieces, placed in this order, each rest stably and can be brought in by a
    top-down hand, else which piece cannot and why (a check independent of the search)."""
    occupied: set[Cell] = set()
    for n, cells in enumerate(pieces):
        cells = [tuple(c) for c in cells]
        if occupied & set(cells):
            return f'piece {n} overlaps an earlier piece'
        if not rests_stably(cells, occupied):
            return f'piece {n} does not rest stably when placed'
        if not _column_clear(cells, occupied):
            return f'piece {n} cannot come down from above: a cell over it is already built'
        if not _finger_room(cells, occupied):
            return f'piece {n} has no unit with free finger sides when placed'
        occupied.update(cells)
    return ''


def edge_distance(case: HardCase) -> float:
    """The farthest target cell centre from the base, in plan (m)."""
    return max(float(np.linalg.norm(t.cell_center(c, case.unit)[:2])) for t in hard_regions(case) for c in t.filled)


# ---- the cases --------------------------------------------------------------

def _case(name, family, regions, tiling, unit=0.05, layout=LayoutConfig(), at=(STRUCTURE_X, 0.0), spare=(),
          n_spare=3, decoys=(), seed=0, why='') -> HardCase:
    spec = HardSpec(name, family, regions, tuple(tiling), tuple(spare), n_spare, why, seed, decoys=tuple(decoys))
    return HardCase(spec, unit, layout, tuple(at), why)


_CASES = [
    # ---- a pyramid on a box --------------------------------------------------
    _case('pyramid_box', 'pyramid', one_sided(layers(
        ['#####', '#####'],
        ['#####', '#####'],
        ['.###.', '.###.'],
        ['..#..', '..#..'])), FLAT + ('I2_up',) + PENTO, unit=0.04, layout=TIGHT, decoys=('O4', 'O4'),
        why='a box two deep and two high under a stepped pyramid; 4 cm units, blocks 2 cm apart, two O4 decoys'),
    _case('step_pyramid', 'pyramid', one_sided(layers(
        ['#####', '#####', '#####'],
        ['.###.', '.###.', '.###.'],
        ['.....', '.###.', '.....'])), FLAT + UPRIGHT + PENTO, decoys=('O4',),
        why='a 5x3 base, a 3x3 step and a ridge: the middle row is boxed in on both sides'),
    # ---- arches and bridges two cells deep -------------------------------------
    _case('deep_arch', 'arch', one_sided(layers(
        ['##.##', '##.##'],
        ['##.##', '##.##'],
        ['#####', '.....'])), FLAT + UPRIGHT + ('I5',),
        why='an arch on piers two cells deep: the span rests on the back half of both piers'),
    _case('deep_bridge', 'bridge', one_sided(layers(
        ['.#..#.', '.#..#.'],
        ['.#..#.', '.#..#.'],
        ['######', '......'])), FLAT + UPRIGHT + ('I5', 'bar4'), at=(0.62, 0.0), layout=FAR,
        why='a deck on piers two deep, overhanging both ends, its far end 0.745 m out; blocks to 0.70 m'),
    _case('twin_arch', 'arch', two_sided(face(
        '#####',
        '#...#',
        '#...#'), face(
        '#####',
        '##.##')), FLAT + UPRIGHT + ('I5', 'A5'), unit=0.04, layout=TIGHT, decoys=('O4',),
        why='the paper\'s two faces back to back: a 3-wide arch against a lower 1-wide one; 4 cm, tight, an O4'),
    _case('span_deck', 'bridge', one_sided(layers(
        ['#...#', '#...#'],
        ['#...#', '#...#'],
        ['#####', '.....'])), ('I5', 'I2_up', 'L3_up', 'I2', 'cube', 'L3'), spare=('I5', 'I3', 'cube'),
        why='a 5-long bar over a three-cell gap on piers two deep: it is held only by its middle'),
    _case('viaduct', 'bridge', two_sided(face(
        '#######',
        '#.#.#.#',
        '#.#.#.#'), face(
        '#######',
        '#..#..#')), FLAT + UPRIGHT + ('I5',), unit=0.04, at=(0.6, 0.0), layout=FAR,
        why='seven cells of deck on piers back to back, 4 cm units, at 0.6 m: the far piers 0.72 m out'),
    # ---- tees and overhangs --------------------------------------------------------
    _case('twin_tee', 'tee', two_sided(face(
        '#####',
        '#####',
        '..#..',
        '..#..'), face(
        '.###.',
        '..#..')), FLAT + UPRIGHT + ('I5',), layout=TIGHT,
        why='a tall tee with a 5x2 top back to back with a short one, on one-cell stems: every arm balances'),
    _case('deep_tee', 'tee', one_sided(layers(
        ['.#.', '.#.'],
        ['.#.', '.#.'],
        ['###', '###'],
        ['###', '...'])), FLAT + UPRIGHT + PENTO, unit=0.04, at=(0.5, -0.22), decoys=('O4',),
        why='a thick tee two deep, 22 cm to the robot\'s right; 4 cm units, an O4'),
    _case('overhang_edge', 'overhang', one_sided(layers(
        ['###.', '###.'],
        ['####', '####'],
        ['#####', '.....'])), FLAT + UPRIGHT + PENTO, at=(0.63, 0.0), layout=TIGHT_FAR,
        why='cantilevers stepping out towards the edge of reach (far cells 0.73 m), blocks tight and far'),
    # ---- stairs ------------------------------------------------------------------
    _case('deep_stairs', 'stairs', one_sided(layers(
        ['#####', '#####'],
        ['#####', '.####'],
        ['.####', '..###'],
        ['..###', '...##'],
        ['...##', '....#'])), FLAT + UPRIGHT + PENTO, unit=0.04, decoys=('O4', 'O6'),
        why='stairs two deep whose back row runs a step ahead, five steps, 4 cm units, an O4 and an O6'),
    _case('side_stairs', 'stairs', two_sided(face(
        '...#',
        '..##',
        '.###',
        '####'), face(
        '#...',
        '##..',
        '###.',
        '####')), FLAT + UPRIGHT, at=(0.48, 0.24), layout=TIGHT,
        why='two flights back to back rising in opposite directions, 24 cm to the robot\'s left'),
    # ---- flat pentomino solids and slabs ----------------------------------------
    _case('pento_floor', 'pento', one_sided(layers(
        ['#####', '#####', '#####', '#####'],
        ['.....', '#####', '.....', '.....'])), PENTO + UPRIGHT + ('I2', 'cube'), unit=0.04, layout=TIGHT,
        spare=PENTO, decoys=('O4', 'O4'),
        why='a 5x4 floor of flat pentominoes under a ridge: each is held by its one free unit; two O4s'),
    _case('pento_ring', 'pento', one_sided(layers(
        ['#####', '#...#', '#...#', '#####'],
        ['#####', '#...#', '#...#', '#####'])), PENTO + ('I3', 'I2', 'cube'), spare=PENTO, decoys=('O4',),
        why='a hollow rectangle two high from pentominoes: a hole seen from above'),
    _case('large_slab', 'slab', one_sided(layers(
        ['#######', '#######', '#######', '#######'],
        ['#######', '.......', '.......', '#######'])), FLAT + UPRIGHT + PENTO, unit=0.04, at=(0.6, 0.0),
        layout=TIGHT, n_spare=11, decoys=('O4', 'O4', 'O6'),
        why='a 7x4 slab with a kerb along both long sides (42 cells, 28 blocks), from 0.48 to 0.72 m; tight'),
    _case('slab_edge', 'slab', one_sided(layers(
        ['######', '######', '######'],
        ['......', '######', '......'])), FLAT + UPRIGHT + PENTO, at=(0.6, 0.0), layout=FAR, n_spare=4,
        decoys=('O4',), why='a 6x3 slab with a ridge reaching 0.72 m out; blocks spread to 0.70 m'),
    _case('wide_tee', 'tee', one_sided(layers(
        ['..#..', '..#..', '..#..'],
        ['..#..', '..#..', '..#..'],
        ['#####', '.....', '#####'])), FLAT + UPRIGHT + ('I5',), unit=0.04, decoys=('O4', 'O6'),
        why='two 5-wide beams on one wall, each overhanging it by two cells both ways; 4 cm units'),
    _case('cross_deck', 'bridge', one_sided(layers(
        ['##.##', '##.##', '##.##'],
        ['#####', '.....', '#####'])), FLAT + UPRIGHT + PENTO + ('I5',), at=(0.5, -0.2), layout=TIGHT,
        decoys=('O4',), why='two beams over a channel between two solid piers, 20 cm to the right, tight layout'),
]

CASES: dict[str, HardCase] = {c.name: c for c in _CASES}

# Held out (reported): every family, the largest slab, both units, the edge and side
# placements and the decoys; training keeps one or more of each family too.
HARD_SPLITS: dict[str, list[str]] = {
    'train': ['step_pyramid', 'span_deck', 'deep_tee', 'side_stairs', 'pento_ring', 'slab_edge', 'cross_deck'],
    'holdout': ['pyramid_box', 'deep_arch', 'deep_bridge', 'twin_arch', 'viaduct', 'twin_tee', 'overhang_edge',
                'deep_stairs', 'pento_floor', 'large_slab', 'wide_tee'],
}


def hard_scene(name: str, seed: int = 0) -> Scene:
    """The named case's scene (seed: the layout on the table)."""
    try:
        case = CASES[name]
    except KeyError:
        raise RadError(f'unknown hard shape {name!r} (known: {", ".join(CASES)})') from None
    return build_hard_scene(case, seed)


def split_scenes(split: str, seed: int = 0) -> list[tuple[str, Scene]]:
    """(name, scene) of a split, 'train' or 'holdout' (or 'all')."""
    names = list(CASES) if split == 'all' else HARD_SPLITS.get(split)
    if names is None:
        raise RadError(f'unknown hard split {split!r} (known: {", ".join(HARD_SPLITS)}, all)')
    return [(name, hard_scene(name, seed)) for name in names]


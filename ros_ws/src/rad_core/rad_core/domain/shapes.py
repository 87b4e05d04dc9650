"""Hand-designed target shapes, to test whether a sequencing policy generalizes.

The random generator (rad_core.domain.generator) only ever draws convex-ish polygons one
cell deep on two back-to-back faces, and lays the blocks out in rows. A policy
trained on those can look good without ever having met a span over a gap, an
overhang that needs its counterweight first, a hole, a solid several cells deep,
columns packed so tightly that the hand barely fits, or a block type it has never
seen. The shapes here are those cases, drawn by hand, at the generator's unit and
structure position and at sizes comparable to its g = 3..6 scenes.

Every scene carries a block multiset that tiles its target exactly (so a perfect
assembly exists, as in generated scenes) plus spare blocks. The multiset is fixed
per shape: only the layout on the table depends on the seed, so results on
different seeds differ in the picking problem, never in the target or the blocks.

`SPLITS` fixes which shapes a learned policy may train on and which are kept
back to measure generalization; both halves cover the families (arches and
bridges, overhangs, towers, frames, thick solids, clusters, custom types), and
the held-out half has shapes and custom block types the training half lacks.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from rad_core.domain import support
from rad_core.domain.blocks import BRICK_TYPES, DEFAULT_LIBRARY, YAWS, BlockType
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Block, Scene, TargetRegion

UNIT = 0.05
# Where the generator puts its structure (GeneratorConfig.structure_x), so both
# kinds of scene present the target at the same place in front of the robot.
STRUCTURE_X = 0.5

Cell = tuple[int, int, int]

# Block types no generated scene has. A5 is an arch piece whose anchor is the top
# middle cube (the natural grasp point, above the gap), so it is the one type
# whose anchor does not rest on the table: the layout must lift it by a unit.
CUSTOM_TYPES: dict[str, BlockType] = {
    name: BlockType.from_cells(name, cells) for name, cells in {
        'A5': [[1, 0, 1], [0, 0, 1], [2, 0, 1], [0, 0, 0], [2, 0, 0]],
        'U5_up': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 1], [2, 0, 1]],
        'P5_up': [[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1], [0, 0, 2]],
        'L5_up': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [0, 0, 1]],
        'bar4': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]],
    }.items()
}
LIBRARY: dict[str, BlockType] = {**DEFAULT_LIBRARY, **CUSTOM_TYPES, **BRICK_TYPES}
"""Every named block type: the predecessor's, the hand-made shapes' and the two-wide plates."""

# Types that lie in the x-z plane at yaw 0/180, the only ones a one-cell-deep face takes.
PLANAR = ('cube', 'I2', 'I3', 'I2_up', 'L3_up', 'T4_up', 'O4_up', 'S4_up')
SOLID = PLANAR + ('L3', 'T4')


# ---- drawing targets -------------------------------------------------------

def face(*rows: str) -> tuple[tuple[int, int, int], list[Cell]]:
    """A one-cell-deep face drawn as text, top row first, '#' for a target cell.

    Drawing the shapes keeps them reviewable: the file shows what the robot sees.
    """
    h, w = len(rows), max(len(r) for r in rows)
    cells = [(i, 0, h - 1 - r) for r, row in enumerate(rows) for i, ch in enumerate(row) if ch == '#']
    return (w, 1, h), cells


def layers(*plan: Sequence[str]) -> tuple[tuple[int, int, int], list[Cell]]:
    """A solid drawn as plan views, bottom layer first; in each the top row is +y
    (the robot's left) and x runs to the right, as seen from above."""
    h = len(plan)
    d = max(len(layer) for layer in plan)
    w = max(len(row) for layer in plan for row in layer)
    cells = [(i, d - 1 - r, k) for k, layer in enumerate(plan) for r, row in enumerate(layer)
             for i, ch in enumerate(row) if ch == '#']
    return (w, d, h), cells


@dataclass(frozen=True)
class RegionSpec:
    name: str
    size: tuple[int, int, int]
    cells: tuple[Cell, ...]


@dataclass(frozen=True)
class ShapeSpec:
    """One hand-designed target and the block types that may tile it.

    tiling_types are tried largest first, so a type listed here is used where it
    fits (e.g. a bar4 as a bridge deck) rather than replaced by small pieces.
    spare_types are drawn for the spare blocks; n_spare of them are added, so
    the allocation has a choice, as in generated scenes. family groups shapes
    that test the same thing (the splits draw on each); why says what that is.
    """

    name: str
    family: str
    regions: tuple[RegionSpec, ...]
    tiling_types: tuple[str, ...]
    spare_types: tuple[str, ...] = ()
    n_spare: int = 0
    why: str = ''
    tiling_seed: int = 0
    types: Mapping[str, BlockType] = field(default_factory=dict, compare=False)

    def __post_init__(self):
        names = tuple(dict.fromkeys(self.tiling_types + self.spare_types))
        object.__setattr__(self, 'types', {n: LIBRARY[n] for n in names})

    @property
    def num_target_cells(self) -> int:
        return sum(len(r.cells) for r in self.regions)

    @property
    def custom(self) -> bool:
        return any(n in CUSTOM_TYPES for n in self.types)


def one_sided(drawn) -> tuple[RegionSpec, ...]:
    size, cells = drawn
    return (RegionSpec('front', size, tuple(sorted(cells))),)


def two_sided(left, right) -> tuple[RegionSpec, ...]:
    """The generator's two back-to-back faces; both get one box so they align."""
    (lsize, lcells), (rsize, rcells) = left, right
    size = (max(lsize[0], rsize[0]), 1, max(lsize[2], rsize[2]))
    return (RegionSpec('left', size, tuple(sorted(lcells))), RegionSpec('right', size, tuple(sorted(rcells))))


# ---- exact tiling ----------------------------------------------------------

def _key(c) -> tuple[int, int, int]:
    return (int(c[2]), int(c[0]), int(c[1]))


def tile_exact(cells, types: Mapping[str, BlockType], rng: np.random.Generator, stable: bool = True,
               max_nodes: int = 200_000) -> list[tuple[str, int, tuple[Cell, ...]]]:
    """An exact tiling of the cells by the types (any number of each), as
    (type, yaw, cells) triples, or RadError if there is none.

    Unlike generator.tile_cells, which is greedy and patches what is left with
    single cubes, this backtracks: a hand-drawn shape is often tileable by its
    intended pieces (pentominoes, arch blocks) only in a few ways, and a greedy
    pass would miss them. Only yaws about +z are used, as in the allocation, so
    whatever tiling this finds the allocation can find too. Larger pieces are
    tried first, ties in random order, so the tiling uses few blocks. With
    stable, a tiling counts only if it can be built block by block without a
    block tipping (`stable_order`): a target whose only tilings need a cube
    floating over a gap would test nothing but the physics.
    """
    free = {tuple(int(v) for v in c) for c in cells}
    # Each distinct orientation, shifted so its lowest cell (in z, x, y order) is at 0:
    # the lowest free cell can only be covered by a piece's lowest cell.
    shapes = []
    for name, t in types.items():
        for yaw in t.distinct_yaws():
            offs = t.rotated(yaw)
            low = min(offs.tolist(), key=_key)
            shapes.append((name, yaw, [tuple(int(v) for v in o - np.asarray(low)) for o in offs]))
    order = rng.permutation(len(shapes))
    shapes = sorted((shapes[n] for n in order), key=lambda s: -len(s[2]))
    nodes = 0
    out: list[tuple[str, int, tuple[Cell, ...]]] = []

    def search() -> bool:
        nonlocal nodes
        if not free:
            return not stable or stable_order([p for _, _, p in out]) is not None
        nodes += 1
        if nodes > max_nodes:
            raise RadError(f'tiling search gave up after {max_nodes} nodes')
        seed = min(free, key=_key)
        for name, yaw, offs in shapes:
            placed = tuple((seed[0] + o[0], seed[1] + o[1], seed[2] + o[2]) for o in offs)
            if all(p in free for p in placed):
                free.difference_update(placed)
                out.append((name, yaw, placed))
                if search():
                    return True
                out.pop()
                free.update(placed)
        return False

    if not search():
        kind = 'stable exact' if stable else 'exact'
        raise RadError(f'no {kind} tiling of {len(cells)} cells with types {sorted(types)}')
    return out


# ---- static stability of a build order -------------------------------------

# How far inside its support polygon (in cells) a block's centre of mass must be:
# a block balanced exactly on an edge tips either way in simulation.
STABILITY_MARGIN = 0.05


def rests_stably(piece: Sequence[Cell], occupied: set[Cell]) -> bool:
    """Whether a block would stay put on the table and the occupied cells alone.

    Its centre of mass must lie inside the convex hull of the unit squares it
    rests on (units on the table or on an occupied cell), with a margin. This
    ignores that a supporting block may itself tip under the new load; the
    physics checks have the last word, this only rules out the hopeless tilings.
    """
    own = set(piece)
    feet = [c for c in piece if c[2] == 0 or ((c[0], c[1], c[2] - 1) in occupied and
                                              (c[0], c[1], c[2] - 1) not in own)]
    if not feet:
        return False
    com = np.asarray(piece, dtype=float)[:, :2].mean(axis=0)
    return support.com_inside(np.asarray(feet, dtype=float)[:, :2], com, STABILITY_MARGIN)


def stable_order(pieces: Sequence[Sequence[Cell]]) -> list[int] | None:
    """An order in which every piece rests stably when it is placed, or None.

    Placing a piece only adds support, so taking any piece that rests stably
    now never spoils a later choice: the greedy walk finds an order whenever
    one exists.
    """
    left, occupied, order = list(range(len(pieces))), set(), []
    while left:
        for n in left:
            if rests_stably(pieces[n], occupied):
                break
        else:
            return None
        left.remove(n)
        order.append(n)
        occupied.update(tuple(c) for c in pieces[n])
    return order


def tiling(spec: ShapeSpec, rng: np.random.Generator | None = None) -> list[list[tuple[str, int, tuple[Cell, ...]]]]:
    """The shape's stable exact tiling, one list of pieces per region.

    Blocks never span regions (the allocation keeps each pose in one region),
    so each region is tiled on its own.
    """
    rng = np.random.default_rng(spec.tiling_seed) if rng is None else rng
    tiling_types = {n: LIBRARY[n] for n in spec.tiling_types}
    return [tile_exact(region.cells, tiling_types, rng) for region in spec.regions]


def block_multiset(spec: ShapeSpec) -> list[str]:
    """The tiling's block types, region by region, then the spares.

    Seeded by the shape alone so every layout seed gets the same blocks.
    """
    rng = np.random.default_rng(spec.tiling_seed)
    kinds = [name for pieces in tiling(spec, rng) for name, _, _ in pieces]
    spares = spec.spare_types or spec.tiling_types
    kinds += [str(spares[int(rng.integers(len(spares)))]) for _ in range(spec.n_spare)]
    return kinds


# ---- regions and the layout on the table -----------------------------------

def target_regions(spec: ShapeSpec, unit: float = UNIT) -> tuple[TargetRegion, ...]:
    """Regions centred on (STRUCTURE_X, 0) standing on the table, as the generator's.

    Two faces sit back to back, left (+y) and right (-y) of the plane y = 0; a
    single region of depth d is centred on it.
    """
    out = []
    for r in spec.regions:
        w, d, _ = r.size
        x0 = STRUCTURE_X - unit * (w - 1) / 2
        y0 = {'left': unit / 2, 'right': -unit / 2}.get(r.name, -unit * (d - 1) / 2)
        origin = tuple(round(float(v), 6) for v in (x0, y0, unit / 2))
        out.append(TargetRegion(r.name, origin, r.size, r.cells))
    return tuple(out)


@dataclass(frozen=True)
class LayoutConfig:
    """Where spare and needed blocks may lie.

    reach: radial range (m) from the robot base for every unit centre: nearer
        than 0.3 m the Panda folds onto itself, beyond 0.65 m top-down grasps
        run out of reach.
    max_bearing_deg: blocks stay in front of the robot, within this angle of +x.
    gap: free space between blocks, so the open gripper fits between them.
    region_margin: free space around the target regions, for the hand and the
        arm when placing at the structure's edge.
    step: lattice of candidate anchor positions (m).
    jitter: random slack (m) added to each candidate's distance from the base;
        0 packs the blocks tightly around the base, larger spreads them.
    """

    reach: tuple[float, float] = (0.32, 0.63)
    max_bearing_deg: float = 75.0
    gap: float = 0.05
    region_margin: float = 0.07
    step: float = 0.025
    jitter: float = 0.08


def lay_out(kinds: Sequence[str], types: Mapping[str, BlockType], targets: Sequence[TargetRegion],
            rng: np.random.Generator, unit: float = UNIT, config: LayoutConfig = LayoutConfig(),
            course: float | None = None) -> list[Block]:
    """Blocks lying on the table in random order and yaw, at random places in reach (`course`: the
    lattice's z pitch, the unit where None).

    The generator's rows run out to 0.75 m, beyond a top-down grasp's reach once
    a dozen blocks (some of them 0.2 m bars) need rows; here every block takes
    the free place on a lattice closest to the base (plus random slack), on the
    robot's right (-y) like the generator's while one is free there, else on its
    left. The seed so changes the order, yaws and places without leaving reach.
    """
    grid, boxes = _lattice(config), _region_boxes(targets, unit, config)
    course = unit if course is None else course
    taken = np.zeros((0, 2))
    blocks = []
    for n, kind in enumerate(kinds):
        # The yaw is drawn first and kept when the block fits that way, so yaws stay
        # uniform; only a block that fits no other way on the right goes left.
        options = {}
        for yaw in rng.permutation(YAWS):
            offs = types[kind].rotated(int(yaw))
            pts = grid[:, None, :] + unit * offs[None, :, :2]          # (candidates, units, 2)
            ok = _free(pts, boxes, taken, unit + config.gap, config)
            right = ok & np.all(pts[..., 1] < 0, axis=1)
            options[int(yaw)] = (offs, pts, right if right.any() else ok, bool(right.any()))
            if right.any():
                break
        fitting = [y for y, o in options.items() if o[2].any()]
        if not fitting:
            raise RadError(f'no free place within reach for block {n} ({kind}) of {len(kinds)}')
        yaw = next((y for y in fitting if options[y][3]), fitting[0])
        offs, pts, pool, _ = options[yaw]
        score = np.linalg.norm(pts.mean(axis=1), axis=-1) + rng.uniform(0, config.jitter, len(grid))
        cand = int(np.argmin(np.where(pool, score, np.inf)))
        z = course / 2 - int(offs[:, 2].min()) * course        # lowest unit rests on the table
        pos = (grid[cand][0], grid[cand][1], z)
        blocks.append(Block(f'b{n}', kind, tuple(round(float(v), 6) for v in pos), yaw))
        taken = np.concatenate([taken, grid[cand] + unit * offs[:, :2]])
    return blocks


def _lattice(config: LayoutConfig) -> np.ndarray:
    """(candidates, 2) anchor positions on the table where a layout may put a block."""
    xs = np.arange(0.0, config.reach[1] + 1e-9, config.step)
    ys = np.arange(-config.reach[1], config.reach[1] + 1e-9, config.step)
    return np.stack(np.meshgrid(xs, ys, indexing='ij'), axis=-1).reshape(-1, 2)


def _region_boxes(targets: Sequence[TargetRegion], unit: float, config: LayoutConfig) -> list:
    """The target regions' xy boxes, padded by half a unit and the layout's margin."""
    pad = unit / 2 + config.region_margin
    return [(lo[:2] - pad, hi[:2] + pad) for lo, hi in (t.bounds(unit) for t in targets)]


def _free(pts: np.ndarray, boxes, taken: np.ndarray, sep: float, config: LayoutConfig) -> np.ndarray:
    """Which candidates (pts: (candidates, units, 2) unit centres) lie within reach, in front of
    the robot, outside the boxes and less than `sep` (m, per axis) from no point of `taken`."""
    r = np.linalg.norm(pts, axis=-1)
    ok = np.all((r >= config.reach[0]) & (r <= config.reach[1]), axis=1)
    bearing = np.degrees(np.abs(np.arctan2(pts[..., 1], pts[..., 0])))
    ok &= np.all(bearing <= config.max_bearing_deg, axis=1)
    for lo, hi in boxes:
        ok &= ~np.any(np.all((pts > lo) & (pts < hi), axis=-1), axis=1)
    return ok & ~_near(pts, taken, sep)


def _near(pts: np.ndarray, taken: np.ndarray, sep: float) -> np.ndarray:
    """Which candidates have a unit less than `sep` (m, per axis) from a point of `taken`."""
    if not len(taken):
        return np.zeros(len(pts), dtype=bool)
    return np.all(np.abs(pts[:, :, None, :] - taken[None, None, :, :]) < sep - 1e-9, axis=-1).any(axis=(1, 2))


def footprint(block: Block, types: Mapping[str, BlockType], unit: float) -> np.ndarray:
    """(units, 2) xy centres of a block's units (its yaw rounded to a quarter turn)."""
    yaw = int(round(block.yaw / 90.0)) * 90 % 360
    return np.asarray(block.position[:2], dtype=float) + unit * types[block.type].rotated(yaw)[:, :2]


def move_aside_spot(scene: Scene, block_id: str, config: LayoutConfig = LayoutConfig(), clear_of: Sequence[str] = (),
                   hand: float = 0.12) -> tuple | None:
    """Where to put a block that lies in another's way: a free place on the table under the rules
    `lay_out` lays blocks out by (within reach, in front of the robot, clear of the target regions,
    `config.gap` from every other block so the open gripper fits) and `hand` (m) from the blocks in
    `clear_of` (the ones it was moved to free: the hand comes down on them next), with the block's
    own yaw, the one nearest to where it lies (a short carry). (position, yaw), or None."""
    block = scene.block(block_id)
    types, unit = scene.block_types, scene.unit
    yaw = int(round(block.yaw / 90.0)) * 90 % 360
    offs = types[block.type].rotated(yaw)
    grid = _lattice(config)
    pts = grid[:, None, :] + unit * offs[None, :, :2]
    others = [footprint(b, types, unit) for b in scene.blocks if b.id != block_id]
    taken = np.concatenate([*others, *[np.asarray(o.position[:2], dtype=float)[None] for o in scene.obstacles]]
                           or [np.zeros((0, 2))])
    ok = _free(pts, _region_boxes(scene.targets, unit, config), taken, unit + config.gap, config)
    for bid in clear_of:
        ok &= ~_near(pts, footprint(scene.block(bid), types, unit), unit + hand)
    if not ok.any():
        return None
    distance = np.linalg.norm(grid - np.asarray(block.position[:2]), axis=-1)
    cand = int(np.argmin(np.where(ok, distance, np.inf)))
    z = scene.course / 2 - int(offs[:, 2].min()) * scene.course
    return (round(float(grid[cand][0]), 6), round(float(grid[cand][1]), 6), round(z, 6)), yaw


LAYOUT_ATTEMPTS = 4


def build_scene(spec: ShapeSpec, seed: int = 0, unit: float = UNIT,
                config: LayoutConfig = LayoutConfig()) -> Scene:
    """The shape's scene; the seed only moves the blocks on the table."""
    rng = np.random.default_rng(seed)
    kinds = block_multiset(spec)
    rng.shuffle(kinds)
    targets = target_regions(spec, unit)
    # Long blocks can box each other out of reach; retrying with less slack packs
    # them tighter, and the rng carries on, so the result is still one per seed.
    for attempt in range(LAYOUT_ATTEMPTS):
        last = attempt == LAYOUT_ATTEMPTS - 1
        try:
            blocks = lay_out(kinds, spec.types, targets, rng, unit,
                             replace(config, jitter=0.0 if last else config.jitter / 2 ** attempt))
            break
        except RadError:
            if last:
                raise
    used = [n for n in spec.types if n in set(kinds)]
    scene = Scene(unit, {n: spec.types[n] for n in used}, tuple(blocks), targets)
    # Through the validator, so a shape that breaks a scene rule fails here, by name.
    return Scene.from_dict(scene.to_dict())


# ---- the shapes ------------------------------------------------------------

_SPECS = [
    # Arches and bridges: spans over gaps. A conservative "every unit rests on
    # something" rule cannot build them; physics can.
    ShapeSpec('arch', 'arch', one_sided(face(
        '###',
        '#.#')), ('cube', 'I2', 'I3', 'I2_up', 'L3_up'), n_spare=2,
        why='the smallest span: a bar over a one-cell gap'),
    ShapeSpec('corbel_arch', 'arch', one_sided(face(
        '######',
        '##..##',
        '##..##')), PLANAR, n_spare=3,
        why='a two-cell opening closed by two cantilevers meeting in the middle'),
    ShapeSpec('bridge', 'bridge', one_sided(face(
        '######',
        '.#..#.',
        '.#..#.')), PLANAR, n_spare=3,
        why='a deck on two piers, overhanging both ends; the deck pieces balance on the piers'),
    ShapeSpec('aqueduct', 'arch', one_sided(face(
        '######',
        '#.##.#',
        '######')), ('A5', 'I3', 'I2', 'I2_up', 'cube'), spare_types=('A5', 'I2', 'cube'), n_spare=3,
        why='two arch blocks, a type with its anchor in the air, on a base course'),
    # Towers: tall and narrow, so a tipped block is costly.
    ShapeSpec('tower', 'tower', one_sided(face(
        '##',
        '##',
        '##',
        '##',
        '##',
        '##')), ('cube', 'I2', 'I2_up', 'O4_up'), n_spare=3,
        why='six cells high: the top is placed at 0.3 m'),
    ShapeSpec('stairs', 'stairs', one_sided(face(
        '...#',
        '..##',
        '.###',
        '####')), PLANAR, n_spare=3,
        why='a staircase: the order is forced from the low end up'),
    # Overhangs and T-shapes: parts that stand only once their counterweight is in.
    ShapeSpec('tee', 'tee', one_sided(face(
        '###',
        '###',
        '.#.',
        '.#.')), PLANAR, n_spare=3,
        why='a heavy top on a one-cell stem: each bar balances on one cube'),
    ShapeSpec('corbel', 'overhang', one_sided(face(
        '####',
        '###.',
        '##..')), PLANAR, n_spare=3,
        why='a cantilever stepping out one cell a layer'),
    # Frames: holes that must stay empty.
    ShapeSpec('window', 'frame', one_sided(face(
        '###',
        '#.#',
        '###',
        '#.#',
        '###')), PLANAR, n_spare=3,
        why='two panes stacked: two lintels over holes, the upper one five cells up'),
    # Two-sided, like the generator's scenes, but with different faces.
    ShapeSpec('arch_stairs', 'two-sided', two_sided(face(
        '###',
        '#.#',
        '#.#'), face(
        '...#',
        '..##',
        '.###',
        '####')), PLANAR, n_spare=4,
        why='an arch on one face and stairs on the other: the faces lean on each other'),
    ShapeSpec('spire_cup', 'two-sided', two_sided(face(
        '..#..',
        '..#..',
        '.###.',
        '#####'), face(
        '#...#',
        '#...#',
        '#####',
        '#####')), PLANAR, n_spare=4,
        why='a spire and a cup back to back: tall thin parts beside a hollow'),
    ShapeSpec('twin_bridge', 'two-sided', two_sided(face(
        '######',
        '.#..#.',
        '.#..#.'), face(
        '######',
        '##..##',
        '##..##')), PLANAR, n_spare=4,
        why='a bridge on piers back to back with a corbelled portal: two spans, two ways'),
    ShapeSpec('overhangs', 'two-sided', two_sided(face(
        '####',
        '###.',
        '##..'), face(
        '####',
        '.###',
        '..##')), PLANAR, n_spare=4,
        why='cantilevers out to opposite sides on the two faces'),
    # Thick solids: regions two or three cells deep, where flat pieces fit too.
    ShapeSpec('slab', 'solid', one_sided(layers(
        ['####', '####'],
        ['####', '####'])), SOLID, n_spare=4,
        why='a 4x2x2 solid: inner cells are reachable only from above'),
    ShapeSpec('cube3', 'solid', one_sided(layers(
        ['###', '###', '###'],
        ['###', '###', '###'],
        ['###', '###', '###'])), SOLID, n_spare=4,
        why='a 3x3x3 cube: the middle column is boxed in on all sides'),
    ShapeSpec('thick_stairs', 'stairs', one_sided(layers(
        ['####', '####'],
        ['.###', '.###'],
        ['..##', '..##'],
        ['...#', '...#'])), SOLID, n_spare=4,
        why='a staircase two cells deep'),
    ShapeSpec('thick_tee', 'tee', one_sided(layers(
        ['.#.', '.#.'],
        ['.#.', '.#.'],
        ['###', '###'])), SOLID, n_spare=3,
        why='a T two cells deep: the arms overhang on both sides of the stem'),
    ShapeSpec('ring', 'frame', one_sided(layers(
        ['###', '#.#', '###'],
        ['###', '#.#', '###'])), SOLID, n_spare=4,
        why='a hollow square two high: a hole seen from above'),
    # Tight clusters: target cells next to other blocks, little room for the hand.
    ShapeSpec('pillars', 'cluster', one_sided(layers(
        ['#.#', '.#.', '#.#'],
        ['#.#', '.#.', '#.#'])), SOLID, n_spare=3,
        why='five columns one cell apart: each gap is one unit, about the open gripper'),
    ShapeSpec('cluster', 'cluster', one_sided(layers(
        ['###.', '####', '.###'],
        ['.#..', '.##.', '..#.'])), SOLID, n_spare=4,
        why='an irregular heap: pieces pressed against each other on all sides'),
    # Custom block types only these scenes define.
    ShapeSpec('pento_wall', 'solid', one_sided(face(
        '#####',
        '#####',
        '#####')), ('U5_up', 'P5_up', 'L5_up', 'I2_up', 'cube'), spare_types=('U5_up', 'P5_up', 'L5_up', 'cube'),
        n_spare=3, why='a wall of interlocking pentominoes, the gaps they leave filled by small pieces'),
    ShapeSpec('span4', 'bridge', one_sided(layers(
        ['#..#', '#..#'],
        ['#..#', '#..#'],
        ['####', '####'])), ('bar4', 'O4_up', 'I2_up', 'cube'), spare_types=('bar4', 'I2', 'cube'), n_spare=3,
        why='a deck of long bars over a two-cell gap, two cells deep'),
    ShapeSpec('log_cabin', 'frame', one_sided(layers(
        ['####', '....', '....', '####'],
        ['#..#', '#..#', '#..#', '#..#'],
        ['####', '....', '....', '####'])), ('bar4', 'I2', 'cube'), spare_types=('bar4', 'I3', 'cube'),
        n_spare=3, why='crossed courses of long bars round a hole, like a log cabin'),
]

SPECS: dict[str, ShapeSpec] = {s.name: s for s in _SPECS}


def shape_scene(name: str, seed: int = 0) -> Scene:
    try:
        spec = SPECS[name]
    except KeyError:
        raise RadError(f'unknown shape {name!r} (known: {", ".join(SPECS)})') from None
    return build_scene(spec, seed)


SHAPES: dict[str, Callable[[], Scene]] = {name: (lambda name=name: shape_scene(name)) for name in SPECS}

# Held out: at least one of each family the training half has, plus what it lacks
# entirely: the arch block A5, the bar4 log cabin, a 3x3x3 solid, columns packed
# one cell apart, a two-level T.
SPLITS: dict[str, list[str]] = {
    'train': ['arch', 'bridge', 'tower', 'stairs', 'corbel', 'arch_stairs', 'twin_bridge', 'slab',
              'thick_stairs', 'thick_tee', 'ring', 'cluster', 'pento_wall', 'span4'],
    'holdout': ['corbel_arch', 'aqueduct', 'tee', 'window', 'spire_cup', 'overhangs', 'cube3', 'pillars',
                'log_cabin'],
}

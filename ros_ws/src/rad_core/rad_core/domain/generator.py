"""Random scenes like the paper's: polygon target shapes and a heap of blocks.

Each side's target shape is a random planar polygon with 3 to 5 corners, at most
g cells wide and g cells high, standing on the table in a vertical x-z plane (the
predecessor's sampler). A cell is a target cell when its centre lies inside the
polygon. One side gives one region g x 1 x g; two sides give the paper's two-sided
structure: two such regions back to back, one cell deep each, so the structure is
two cells deep with one polygon on its face towards the robot's left (+y) and one
on its face towards the robot's right (-y).

The blocks on the table are a random tiling of the target cells (so a perfect
assembly exists) plus extras, laid out in rows on the robot's right; a block the
arm could not reach there (`GeneratorConfig.reach`) goes to rows on its left.
Where the table within reach cannot hold them all (g = 8 and more), the scene gets a
feeder instead (`GeneratorConfig.supply`, `rad_core.domain.scene.Feeder`): every block waits in
it and is presented at a station on the robot's right, in the order the plan asks for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rad_core.domain.blocks import DEFAULT_LIBRARY, BlockType
from rad_core.domain.errors import RadError
from rad_core.domain.scene import FEEDER_ORDERS, MAX_CLEARANCE, Block, Scene, TargetRegion, feeder_of

SUPPLIES = ('auto', 'table', 'feeder')

# Types that fit a one-cell-deep region at yaw 0 or 180 (they lie in the x-z plane).
PLANAR_TYPES = ('cube', 'I2', 'I3', 'I2_up', 'L3_up', 'T4_up', 'O4_up', 'S4_up')


@dataclass(frozen=True)
class GeneratorConfig:
    """Scene generator parameters.

    grid: g, the largest width and height of a target shape, in cells.
    sides: 1 (one face) or 2 (the paper's two-sided structure).
    unit: cube edge in metres (0.05, the predecessor's cubes).
    structure_x: distance of the structure's centre from the robot base along +x.
    min_cells_per_side: a face with fewer target cells is resampled.
    min_cells: a scene with fewer target cells in all is resampled (tiny targets).
    extra_fraction: extra blocks on the table, as a fraction of the blocks needed.
    table_x: x range (m) of the rows of blocks on the table.
    first_row_y: y (m) of the first row's near edge; rows go on towards -y.
    gap: free space between neighbouring blocks on the table (m).
    reach: horizontal distance (m) from the robot base (the origin) that every unit
        centre of a block on the table must be within; the Panda's top-down grasp
        of a cube on the table works to about 0.78 m and fails beyond 0.80 m. A
        block whose place in the rows on the right is beyond it goes to rows on
        the left (+y, from y = -first_row_y on), which end early at the reach;
        every other block keeps its place, and no random draw changes. math.inf
        gives the layout of before reach existed (everything on the right).
    clearance: the scenes' clearance, a fraction of the unit (`rad_core.domain.scene`): 0
        (flush blocks, the default) or e.g. 0.2, the predecessor's 1 cm between
        neighbouring 5 cm cells. It changes no random draw: a seed gives the same
        layout with either.
    supply: where the blocks start: 'table' (laid out in rows; an error where they do
        not fit within reach), 'feeder' (all in a feeder presenting them at
        `station`), or 'auto' (the table where they fit, else the feeder). The target
        of a seed is the same with each.
    station: (x, y) (m) of the feeder's station: right of the structure, within reach.
    feeder_order: 'request' (the plan takes any block) or 'queue' (the feeder's
        order, a random one, with a window of `feeder_window` blocks to take from).
    """

    grid: int = 3
    sides: int = 2
    unit: float = 0.05
    structure_x: float = 0.5
    min_cells_per_side: int = 1
    min_cells: int = 4
    extra_fraction: float = 0.5
    table_x: tuple[float, float] = (0.3, 0.75)
    first_row_y: float = -0.12
    gap: float = 0.05
    reach: float = 0.77
    clearance: float = 0.0
    supply: str = 'auto'
    station: tuple[float, float] = (0.42, -0.3)
    feeder_order: str = 'request'
    feeder_window: int = 3

    def validate(self) -> None:
        if not (isinstance(self.grid, int) and 1 <= self.grid <= 12):
            raise RadError(f'grid must be an integer in 1..12, got {self.grid!r}')
        if self.sides not in (1, 2):
            raise RadError(f'sides must be 1 or 2, got {self.sides!r}')
        if not 0.01 <= self.unit <= 0.2:
            raise RadError(f'unit must be in 0.01..0.2 m, got {self.unit!r}')
        if not 1 <= self.min_cells_per_side <= self.grid * self.grid:
            raise RadError(f'min_cells_per_side must be in 1..{self.grid * self.grid}')
        if not (isinstance(self.reach, (int, float)) and not isinstance(self.reach, bool) and self.reach > 0):
            raise RadError(f'reach must be a positive distance in metres (or math.inf for no limit), '
                           f'got {self.reach!r}')
        if not (isinstance(self.clearance, (int, float)) and math.isfinite(self.clearance)
                and 0 <= self.clearance < MAX_CLEARANCE):
            raise RadError(f'clearance must be a fraction of the unit in 0 <= clearance < {MAX_CLEARANCE}, '
                           f'got {self.clearance!r}')
        if self.supply not in SUPPLIES:
            raise RadError(f'supply must be one of {", ".join(SUPPLIES)}, got {self.supply!r}')
        if self.feeder_order not in FEEDER_ORDERS:
            raise RadError(f'feeder_order must be one of {", ".join(FEEDER_ORDERS)}, got {self.feeder_order!r}')
        if not (isinstance(self.feeder_window, int) and self.feeder_window >= 1):
            raise RadError(f'feeder_window must be a positive integer, got {self.feeder_window!r}')


def sample_polygon(g: int, rng: np.random.Generator) -> np.ndarray:
    """Corners (x, z) in cell units of a random 3-5 corner shape standing on z = 0.

    x spans [0, g] with the shape centred at g/2; heights are at most g. The
    corners are in counter-clockwise order when seen with x right and z up.
    """
    c, half = g / 2, g / 2
    n = int(rng.choice([3, 4, 5]))
    left_bottom = (c - rng.uniform(0, half), 0.0)
    right_bottom = (c + rng.uniform(0, half), 0.0)
    if n == 3:
        top = (rng.uniform(0, g), rng.uniform(0, g))
        return np.array([left_bottom, right_bottom, top])
    left_top = (c - rng.uniform(0, half), rng.uniform(0, g))
    right_top = (c + rng.uniform(0, half), rng.uniform(0, g))
    if n == 4:
        return np.array([left_bottom, right_bottom, right_top, left_top])
    # A fifth corner on top, between the two side edges.
    for _ in range(100):
        mid = (rng.uniform(left_top[0], right_top[0]), rng.uniform(0, g))
        if _left_of(right_bottom, right_top, mid) and _left_of(left_top, left_bottom, mid):
            return np.array([left_bottom, right_bottom, right_top, mid, left_top])
    return np.array([left_bottom, right_bottom, right_top, left_top])


def _left_of(a, b, p) -> bool:
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) > 0


def inside_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test for (n, 2) points."""
    x, y = points[:, 0], points[:, 1]
    inside = np.zeros(len(points), dtype=bool)
    for k in range(len(poly)):
        (x1, y1), (x2, y2) = poly[k], poly[(k + 1) % len(poly)]
        crosses = (y1 > y) != (y2 > y)
        with np.errstate(divide='ignore', invalid='ignore'):
            xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (x < xc)
    return inside


def sample_face(g: int, rng: np.random.Generator, min_cells: int) -> list[tuple[int, int]]:
    """Target cells (i, k) of one face; resampled until it has min_cells cells."""
    i, k = np.meshgrid(np.arange(g), np.arange(g), indexing='ij')
    centres = np.stack([i.ravel() + 0.5, k.ravel() + 0.5], axis=1)
    while True:
        mask = inside_polygon(centres, sample_polygon(g, rng))
        if mask.sum() >= min_cells:
            return [(int(a), int(b)) for a, b in centres[mask] - 0.5]


def tile_cells(cells: set[tuple[int, int, int]], rng: np.random.Generator,
               library: dict[str, BlockType], type_names=PLANAR_TYPES) -> list[str]:
    """Block types of a random exact tiling of the cells (bottom-up, greedy).

    Falls back to a single cube where nothing bigger fits, so it always succeeds.
    """
    free = set(cells)
    needed = []
    while free:
        seed_cell = min(free, key=lambda c: (c[2], c[0], c[1]))
        options = []
        for name in type_names:
            for yaw in library[name].distinct_yaws():
                offs = library[name].rotated(yaw)
                for anchor_unit in range(len(offs)):
                    placed = {tuple(int(v) for v in seed_cell + o - offs[anchor_unit]) for o in offs}
                    if placed <= free:
                        options.append((name, placed))
        bigger = [o for o in options if len(o[1]) > 1]
        pick = bigger if bigger and rng.random() < 0.85 else options
        name, placed = pick[int(rng.integers(len(pick)))]
        free -= placed
        needed.append(name)
    return needed


def generate_scene(config: GeneratorConfig = GeneratorConfig(), seed: int = 0) -> Scene:
    config.validate()
    rng = np.random.default_rng(seed)
    g, u = config.grid, config.unit
    x0 = config.structure_x - u * (g - 1) / 2
    faces = [('left', u / 2), ('right', -u / 2)] if config.sides == 2 else [('front', 0.0)]
    while True:
        shapes = [[(i, 0, k) for i, k in sample_face(g, rng, config.min_cells_per_side)] for _ in faces]
        if sum(len(s) for s in shapes) >= min(config.min_cells, len(faces) * g * g):
            break
    targets, needed = [], []
    for (name, y), cells in zip(faces, shapes):
        targets.append(TargetRegion(name, (x0, y, u / 2), (g, 1, g), tuple(sorted(cells))))
        needed += tile_cells(set(cells), rng, DEFAULT_LIBRARY)
    n_extra = int(np.ceil(config.extra_fraction * len(needed)))
    extras = [str(rng.choice(sorted(DEFAULT_LIBRARY))) for _ in range(n_extra)]
    kinds = needed + extras
    rng.shuffle(kinds)
    feeder = None
    if config.supply == 'feeder':
        blocks = None
    else:
        try:
            blocks = _lay_out(kinds, config, rng)
        except RadError:
            if config.supply == 'table':
                raise
            blocks = None
    if blocks is None:
        # Every block in the feeder, presented at the station; the queue's order is the shuffled one.
        blocks, feeder = feeder_of(kinds, DEFAULT_LIBRARY, config.station, u, config.feeder_order,
                                   config.feeder_window if config.feeder_order == 'queue' else 1)
    used = sorted({b.type for b in blocks})
    scene = Scene(u, {n: DEFAULT_LIBRARY[n] for n in used}, tuple(blocks), tuple(targets), float(config.clearance),
                  feeder=feeder)
    return Scene.from_dict(scene.to_dict()) if feeder is not None else scene


def _lay_out(kinds: list[str], config: GeneratorConfig, rng: np.random.Generator) -> list[Block]:
    """Rows of blocks on the table, each with a random yaw, at least `gap` apart.

    Every block takes its place in the rows on the right; one with a unit centre
    beyond `config.reach` there takes the next place within reach in the rows on
    the left instead (its place on the right stays empty, so the others keep theirs).
    """
    u = config.unit
    right, left = _Rows(config, config.first_row_y, -1), _Rows(config, -config.first_row_y, +1)
    blocks = []
    for n, kind in enumerate(kinds):
        yaw = int(rng.choice([0, 90, 180, 270]))
        offs = DEFAULT_LIBRARY[kind].rotated(yaw)
        pos = right.place(offs)
        right.advance(offs)
        if _reach_of(pos, offs, u) > config.reach:
            pos = left.place(offs)
            if _reach_of(pos, offs, u) > config.reach and left.x > config.table_x[0]:
                left.new_row()
                pos = left.place(offs)
            if _reach_of(pos, offs, u) > config.reach:
                raise RadError(
                    f'the {len(kinds)} blocks of a g={config.grid} scene do not fit on the table within '
                    f'the reach of {config.reach} m (block {n}, a {kind}, fits in no row on either side); '
                    f'use a smaller extra_fraction (now {config.extra_fraction}) or a feeder (supply \'feeder\' or '
                    f'\'auto\')')
            left.advance(offs)
        blocks.append(Block(f'b{n}', kind, pos, yaw))
    return blocks


class _Rows:
    """Rows of footprints on the table: along +x from table_x[0], each row `gap`
    beyond the last one, from near_y on towards side (-1: -y, +1: +y)."""

    def __init__(self, config: GeneratorConfig, near_y: float, side: int):
        self.config, self.side = config, side
        self.x, self.row_y, self.row_depth = config.table_x[0], near_y, 0.0

    def new_row(self) -> None:
        # row_y + side * ... is exactly the right side's original row_y - depth - gap.
        self.x = self.config.table_x[0]
        self.row_y = self.row_y + self.side * self.row_depth + self.side * self.config.gap
        self.row_depth = 0.0

    def place(self, offs: np.ndarray) -> tuple[float, float, float]:
        """The block's position at the cursor, in a new row where it would pass table_x[1];
        advance() then moves the cursor past it."""
        u = self.config.unit
        lo, width, depth = self._extent(offs)
        if self.x + width > self.config.table_x[1] and self.x > self.config.table_x[0]:
            self.new_row()
        # The footprint spans x..x+width and, in y, row_y-depth..row_y (right) or row_y..row_y+depth (left).
        near = self.row_y - depth if self.side < 0 else self.row_y
        pos = (self.x + u / 2 - lo[0] * u, near + u / 2 - lo[1] * u, u / 2 - lo[2] * u)
        return tuple(round(float(v), 6) for v in pos)

    def advance(self, offs: np.ndarray) -> None:
        _, width, depth = self._extent(offs)
        self.x += width + self.config.gap
        self.row_depth = max(self.row_depth, depth)

    def _extent(self, offs: np.ndarray) -> tuple[np.ndarray, float, float]:
        u = self.config.unit
        lo, hi = offs.min(axis=0), offs.max(axis=0)
        return lo, u * (hi[0] - lo[0] + 1), u * (hi[1] - lo[1] + 1)


def _reach_of(position, offs: np.ndarray, unit: float) -> float:
    """The largest horizontal distance of a block's unit centres from the robot base."""
    centres = np.asarray(position) + unit * offs
    return float(np.hypot(centres[:, 0], centres[:, 1]).max())


def target_statistics(config: GeneratorConfig, n: int, seed: int = 0) -> dict:
    """Mean / min / max target cells and blocks over n generated scenes."""
    cells, blocks = [], []
    for s in range(n):
        scene = generate_scene(config, seed + s)
        cells.append(scene.num_target_cells)
        blocks.append(len(scene.blocks))
    cells, blocks = np.array(cells), np.array(blocks)
    return {'grid': config.grid, 'sides': config.sides, 'scenes': n,
            'target_cells_mean': float(cells.mean()), 'target_cells_min': int(cells.min()),
            'target_cells_max': int(cells.max()), 'blocks_mean': float(blocks.mean())}

"""Scenes from brick designs, keeping their bricks: the design's cells are the target, its own
bricks the blocks, laid out on the table (or waiting in a feeder where they do not fit).

A design (`brick_designs`) counts in studs and plates; a scene in metres on a lattice of the stud
pitch (``unit``) by the course height (`studs`). The course is the coarsest one every brick sits
on: a brick's height where the design has bricks only, a plate's where plates shift them (a LEGO
brick is then three cells high). The target stands where `voxels.fit_target` puts a model of its
height in metres, turned a quarter where only that fits the reach (``yaw`` fixes it). The scene keeps
the bricks' places as its design (`Scene.design`, `design_poses`), in the file's order.

A design that does not stand even with the bricks' clutch, placed brick by brick in the file's
order or in any order the statics walk finds, is refused naming the brick that falls
(`design_verdict`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from rad_core.allocation.supply import feeder_blocks, lay_out_blocks
from rad_core.domain.blocks import BlockType
from rad_core.domain.brick_designs import PLATES_PER_BRICK, Brick, BrickDesign
from rad_core.domain.errors import RadError
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Block, Feeder, Placement, Scene, TargetRegion
from rad_core.domain.statics import Statics, first_failure, order_statics
from rad_core.domain.studs import GRAVITY, SYSTEMS, Studs
from rad_core.domain.voxels import fit_target


@dataclass(frozen=True)
class BrickLattice:
    """How a design's studs and plates become a scene's lattice: the system, the stud pitch (m), the
    course in plates and in metres, the clutch (N per stud), the mass of a cell (kg)."""

    system: str
    unit: float
    course_plates: int
    course: float
    clutch: float
    mass: float
    baseplate: bool = False
    """Whether the table is a baseplate (``studs.baseplate``): the first course is held by its studs."""

    @property
    def studs(self) -> Studs:
        return Studs(self.system, round(self.course, 9), self.clutch, round(self.mass, 9), self.baseplate)


def lattice_of(design: BrickDesign, system: str | None = None, unit: float | None = None,
               clutch: float | None = None, baseplate: bool = False) -> BrickLattice:
    """The lattice a design is built on: its own system (or `system` where the format cannot say),
    the system's real pitch unless `unit` scales it, the system's clutch unless `clutch` is given;
    on a baseplate where `baseplate` says so."""
    name = design.system or system
    if design.system and system and design.system != system:
        raise RadError(f'{design.name or "the design"} is made of {design.system} parts, not {system}')
    if name is None:
        raise RadError(f'{design.name or "the design"} does not say its brick system: give --system '
                       f'({" or ".join(SYSTEMS)})')
    if name not in SYSTEMS:
        raise RadError(f'unknown brick system {name!r}: rad knows {", ".join(SYSTEMS)}')
    known = SYSTEMS[name]
    unit = known.pitch if unit is None else float(unit)
    if not (math.isfinite(unit) and 0.005 <= unit <= 0.2):
        raise RadError(f'--unit {unit} m is outside 0.005..0.2 m (the stud pitch)')
    if clutch is not None and not (math.isfinite(clutch) and 0 < clutch <= 100):
        raise RadError(f'--clutch {clutch} N is outside 0 < clutch <= 100 N per stud connection')
    plates = design.course_plates()
    course = unit * known.brick / PLATES_PER_BRICK * plates / known.pitch
    return BrickLattice(name, unit, plates, course, known.clutch if clutch is None else float(clutch),
                        known.cell_mass(unit, course), bool(baseplate))


def brick_type(brick: Brick, course_plates: int) -> tuple[BlockType, int]:
    """The block type of a brick (its long side along x) and the yaw (0 or 90) that lays it as the
    design has it."""
    long, short = max(brick.length, brick.width), min(brick.length, brick.width)
    courses = brick.height // course_plates
    if brick.height == PLATES_PER_BRICK:
        name = f'brick{short}x{long}'
    elif brick.height == 1:
        name = f'plate{short}x{long}'
    else:
        name = f'brick{short}x{long}h{brick.height}'
    cells = [[i, j, k] for k in range(courses) for j in range(short) for i in range(long)]
    return BlockType.from_cells(name, cells), (0 if brick.length >= brick.width else 90)


def turned(design: BrickDesign, yaw: int) -> BrickDesign:
    """The design turned `yaw` degrees (a multiple of 90) counter-clockwise seen from above, its
    smallest x and y at 0 again."""
    quarter = (yaw // 90) % 4
    bricks = []
    for b in design.bricks:
        corners = np.array([[b.x, b.y], [b.x + b.length - 1, b.y + b.width - 1]])
        for _ in range(quarter):
            corners = np.stack([-corners[:, 1], corners[:, 0]], axis=1)
        lo = corners.min(axis=0)
        length, width = (b.width, b.length) if quarter % 2 else (b.length, b.width)
        bricks.append(replace(b, x=int(lo[0]), y=int(lo[1]), length=length, width=width))
    return replace(design, bricks=tuple(bricks)).normalised()


def target_of(design: BrickDesign, lattice: BrickLattice,
              yaw: int | None = None) -> tuple[BrickDesign, TargetRegion, int]:
    """(the design as it stands, turned; its cells as a target region; the turn, degrees) where the
    arm builds it best: `voxels.fit_target` of a model as high in metres as the design."""
    design = design.normalised()
    cells = np.array(sorted(design.cells(lattice.course_plates)))
    w, d, h = (int(v) for v in cells.max(axis=0) + 1)
    high = int(math.ceil(h * lattice.course / lattice.unit - 1e-9))
    fit = fit_target([(w, d, high)], lattice.unit, yaw=yaw)
    design = turned(design, fit.yaw) if fit.yaw else design
    cells = np.array(sorted(design.cells(lattice.course_plates)))
    size = tuple(int(v) for v in cells.max(axis=0) + 1)
    origin = (fit.x - lattice.unit * (size[0] - 1) / 2, -lattice.unit * (size[1] - 1) / 2, lattice.course / 2)
    region = TargetRegion(design.name or 'design', tuple(round(float(v), 6) for v in origin), size,
                          tuple(tuple(int(v) for v in c) for c in cells))
    return design, region, fit.yaw


def built_blocks(design: BrickDesign, lattice: BrickLattice, region: TargetRegion) -> tuple[dict, list[Block]]:
    """(the block types, every brick as a block at its place in the target, ids b0, b1, ... in the
    design's order)."""
    types: dict[str, BlockType] = {}
    blocks = []
    pitch = np.array([lattice.unit, lattice.unit, lattice.course])
    for n, brick in enumerate(design.bricks):
        btype, yaw = brick_type(brick, lattice.course_plates)
        types.setdefault(btype.name, btype)
        rotated = btype.rotated(yaw)
        corner = np.array([brick.x, brick.y, brick.z // lattice.course_plates])
        anchor = corner - rotated.min(axis=0)
        position = np.asarray(region.origin) + pitch * anchor
        blocks.append(Block(f'b{n}', btype.name, tuple(round(float(v), 6) for v in position), yaw))
    return types, blocks


def design_poses(placed: list[Block], types: Mapping[str, BlockType], region: TargetRegion,
                 lattice: BrickLattice) -> tuple[Placement, ...]:
    """The bricks at their places in the target (`built_blocks`) as the scene's design (`Scene.design`),
    in the design's order."""
    pitch = np.array([lattice.unit, lattice.unit, lattice.course])
    poses = []
    for block in placed:
        anchor = np.rint((np.asarray(block.position) - np.asarray(region.origin)) / pitch).astype(int)
        cells = tuple(tuple(int(v) for v in anchor + o) for o in types[block.type].rotated(block.yaw))
        poses.append(Placement(block.type, region.name, block.yaw, cells))
    return tuple(poses)


def design_verdict(design: BrickDesign, lattice: BrickLattice, clutch: bool = True) -> tuple[str, str]:
    """('stands' or 'falls', a line saying why): whether the design stands with its bricks' clutch
    (`clutch` False: held by gravity alone), placed in the file's order, and if not there, whether
    some order keeps every step standing."""
    design = design.normalised()
    cells = np.array(sorted(design.cells(lattice.course_plates)))
    size = tuple(int(v) for v in cells.max(axis=0) + 1)
    region = TargetRegion('design', (0.5, 0.0, lattice.course / 2), size,
                          tuple(tuple(int(v) for v in c) for c in cells))
    types, blocks = built_blocks(design, lattice, region)
    scene = Scene(lattice.unit, types, tuple(blocks), (region,), studs=lattice.studs)
    grid = Grid(scene)
    pieces = [grid.cells_at(scene.unit_positions(b)) for b in blocks]
    limit = lattice.studs.clutch_in_weights if clutch else None
    weight = lattice.mass * GRAVITY
    failure = first_failure(grid, pieces, clutch=limit)
    if failure is None:
        words = f'stands: every one of its {len(pieces)} bricks, placed in the file\'s order'
    else:
        fall = _falls(design, failure[0], failure[1], weight)
        if order_statics(grid, pieces, clutch=limit, press=False)[1]:
            return 'falls', f'falls: no order keeps every step standing; in the file\'s order, placing {fall}'
        words = f'stands once built, but not in the file\'s order: placing {fall}; rad builds it in another order'
    if limit is not None:
        _, waiting = order_statics(grid, pieces, clutch=limit)
        if waiting:
            words += (f'; but no order presses every brick home without breaking what is built ('
                      f'{len(waiting)} left over, the {design.bricks[waiting[0]].describe()} first): rad builds '
                      f'what it can')
    return 'stands', words


def _falls(design: BrickDesign, step: int, verdict: Statics, weight: float) -> str:
    """Words for the brick placed at `step` and what falls then, and why (bricks named, not pieces;
    forces in N, `weight` the weight of a cell)."""
    def name(n: int) -> str:
        b = design.bricks[n]
        return f'the {b.describe()}' + (f' (line {b.line})' if b.line else '')
    placed = design.bricks[step]
    where = f'{placed.source}:{placed.line}: ' if placed.line else ''
    parts = [('it' if n == step else name(n)) + f' {why}' for n, why in verdict.told(name, weight)]
    return f'{where}the {placed.describe()}: ' + '; '.join(parts or ['it does not stand'])


def feeder_station(region: TargetRegion, unit: float) -> tuple[float, float]:
    """Where a feeder presents the bricks: right of the target (-y), within reach."""
    lo = np.asarray(region.origin) - unit / 2
    return (round(float(region.origin[0]), 6), round(float(min(-0.3, lo[1] - 0.12)), 6))


def scene_from_design(design: BrickDesign, system: str | None = None, unit: float | None = None,
                      clutch: float | None = None, yaw: int | None = None, seed: int = 0,
                      start: str = 'auto', baseplate: bool = False) -> tuple[Scene, list[str]]:
    """The scene of a design (module docstring) and lines for the user saying what was chosen.
    start: 'table', 'feeder', or 'auto' (the table where the bricks fit within reach, else a feeder).
    baseplate: the table is a baseplate (``studs.baseplate``), whose studs hold the first course.
    RadError where the design does not stand even with clutch, naming the brick that falls."""
    if not design.bricks:
        raise RadError(f'no bricks in {design.name or "the design"}')
    lattice = lattice_of(design, system, unit, clutch, baseplate)
    verdict, words = design_verdict(design, lattice)
    if verdict == 'falls':
        raise RadError(f'{design.name or "the design"} {words}')
    design, region, turn = target_of(design, lattice, yaw)
    types, placed = built_blocks(design, lattice, region)
    kinds = [b.type for b in placed]
    blocks, feeder = _supply(kinds, types, region, lattice, seed, start)
    scene = Scene.from_dict(Scene(lattice.unit, types, tuple(blocks), (region,), feeder=feeder,
                                  studs=lattice.studs, design=design_poses(placed, types, region, lattice)).to_dict())
    lines = [f'{len(design.bricks)} {lattice.system} bricks, {len(region.filled)} cells on a '
             f'{lattice.unit * 1000:g} mm pitch and {lattice.course * 1000:.2f} mm courses '
             f'({lattice.course_plates} plate{"s" if lattice.course_plates > 1 else ""}), clutch '
             f'{lattice.clutch:g} N a stud' + (', on a baseplate' if lattice.baseplate else ''),
             f'the target stands at x = {region.origin[0] + lattice.unit * (region.size[0] - 1) / 2:.3f} m'
             + (f', turned {turn} deg' if turn else ''),
             words]
    if feeder is not None:
        lines.append(f'the {len(blocks)} bricks wait in a feeder at {feeder.station}')
    return scene, lines


def _supply(kinds, types, region, lattice, seed, start) -> tuple[list[Block], Feeder | None]:
    if start not in ('auto', 'table', 'feeder'):
        raise RadError(f"start must be 'auto', 'table' or 'feeder', got {start!r}")
    if start != 'feeder':
        try:
            return lay_out_blocks(kinds, types, (region,), lattice.unit, seed, course=lattice.course), None
        except RadError:
            if start == 'table':
                raise
    return feeder_blocks(kinds, types, (region,), lattice.unit, feeder_station(region, lattice.unit),
                         course=lattice.course)

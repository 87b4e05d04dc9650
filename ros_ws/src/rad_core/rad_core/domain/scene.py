"""Scenes: the blocks on the table and the target regions, and the rad-scene/1 format.

A scene is validated once, when it is built from a document (`Scene.from_dict`),
so every other module can trust it. Validation errors name the offending field
the way a user would find it in the JSON file, e.g. ``blocks[3].yaw``.

Block geometry: by default blocks are flush, every unit cube exactly one grid cell
(cube edge == grid pitch == ``unit``). The optional ``clearance`` (a fraction of
the unit, 0 <= clearance < 0.5, absent = 0) makes every block smaller than its
cells on its outer side faces (x and y): each such face is set back by
``clearance / 2`` unit, so two neighbouring blocks leave ``clearance`` unit
between them for the fingers, the predecessor's robot scenes (0.05 m cubes on a
0.06 m pitch are ``unit`` 0.06, ``clearance`` 1/6; 0.2 at the default 5 cm unit
is their 1 cm gap). A block stays one solid: faces between units of the same
block do not move (the predecessor's filler slabs), and top and bottom faces do
not move either, so heights and stacking are unchanged. `unit_boxes` in
rad_core.domain.blocks turns this into boxes for physics, rendering and Rerun.

A scene registered from motion capture may also say what the lattice cannot
(optional ``measured_offsets``): block id -> [dx, dy] (m), how far from the pose
the scene gives it motion capture saw a block that registration snapped onto its
target cell (a real placement is a few millimetres off), or, as [0, 0, turn], how
far (deg) a block lying on the table is turned from the yaw the scene gives it (a
block that slipped lands anyhow). Only the motion planning
world uses them: it puts those blocks where they were seen, so the next block is
placed and its fingers planned against the real neighbours
(`rad_core.gamp.action.seat_shift`); the grid, the allocation, the MDP and coverage
use the cells. Likewise ``obstacles``: blocks registration had to set aside (fallen
on a side, turned off the 90-degree yaws), each with its type and measured pose
(position, quaternion x y z w). They are no blocks of the scene (nothing plans to
pick or count them), but the motion planning world holds them where they lie, so
no arm motion is planned through them.

A scene may also have a ``feeder`` (optional): blocks that do not lie on the table at the
start but arrive at a pick station, as in cells with a part feeder or a tray refilled
between picks. ``feeder.blocks`` lists the ids of the blocks still in it, in the order it
holds them; ``feeder.station`` is the (x, y) on the table (m) where it presents one block
at a time, footprint centred there, at ``feeder.yaw``. Each such block's scene pose is its
pose at the station (the parser computes it: ``position`` may be left out, and a given
one must match), so the allocation, the MDP and the network see where the robot will
take it. The physics world keeps the blocks in the feeder out of the way until one is
presented (`rad_core.sim.world.World.present`). ``feeder.order``: ``request`` (the plan
asks for any block, as a feeder with a magazine per type) or ``queue`` (the feeder
dictates: only the first ``feeder.window`` blocks of the list can be taken next, a tray of
that many places refilled from the queue). A block placed leaves the feeder.

A scene of studded bricks names its stud system in ``studs`` (optional, absent or
``"none"``: blocks that only rest): ``{"system": "duplo"}`` or with its ``course`` (m,
the lattice's z pitch: a brick's height without studs), ``clutch`` (N, the pull one
stud connection holds) and ``mass`` (kg, of one lattice cell of a brick) given; a named
system (`rad_core.domain.studs.SYSTEMS`) fills in what is left out, its course and mass in
proportion to the unit (the stud pitch); ``baseplate`` (default false) says the table is a
plate of the system's studs, which hold the first course as bricks hold the bricks on them. The lattice is
then ``unit`` along x and y and ``course`` along z (`Scene.pitch`): a block type's cells
are studs by courses, and every position of the scene, a block's and a region's, lies on
that lattice. Blocks sit on the table with their lowest cells' centres ``course / 2`` up.

A scene made from a design may also say how the design fills its targets (``design``, optional): a
list of poses, each ``{type, target, yaw, cells}`` as an allocation answers them (the region's cells
[i, j, k] the block fills, its type's cells turned by ``yaw`` and moved), in the order they were
designed to go in. `rad scene from-voxels` and `from-mesh` write the cover supply chose for the blocks
they lay out, `rad scene from-bricks` the design's own bricks. It is a proposal, not an instruction:
the planner plans it as one more allocation (`sequencing.agent.stages`, the design stage) beside its
own, and keeps whichever plan fills more. The poses must be disjoint and inside their regions; a pose
whose cells are filled already, or one more of a type than the scene has blocks of, is left out then.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from rad_core.domain import jsonfmt
from rad_core.domain.blocks import BlockType, canonical_shape
from rad_core.domain.errors import SceneError
from rad_core.domain.studs import SYSTEMS, Studs, stud_height

FORMAT = 'rad-scene/1'

# Hard limits: big enough for any table-top assembly a Panda can reach, small
# enough that allocation and the MDP stay interactive. A scene beyond them is
# rejected with a message instead of hanging a solver.
MAX_REGION_AXIS = 24
MAX_GRID_CELLS = 4096
MAX_TARGETS = 16
MAX_BLOCKS = 1024
MAX_BLOCK_TYPES = 64
MAX_TYPE_UNITS = 48
MAX_TYPE_EXTENT = 12
UNIT_RANGE = (0.005, 1.0)
MAX_COORD = 100.0
# Fraction of a unit within which a block counts as sitting on a grid cell.
GRID_SNAP_TOL = 0.1
# Clearance is a fraction of the unit in [0, MAX_CLEARANCE): at half a unit a
# block's outer faces would meet at its unit centres.
MAX_CLEARANCE = 0.5


@dataclass(frozen=True)
class Block:
    id: str
    type: str
    position: tuple[float, float, float]
    yaw: int

    def to_dict(self) -> dict:
        return {'id': self.id, 'type': self.type, 'position': list(self.position), 'yaw': self.yaw}


@dataclass(frozen=True)
class Placement:
    """A block type at a pose in one region: cells = anchor + R(yaw) offsets (the region's cells
    [i, j, k]). What an allocation answers (`allocation.placements`), and a scene's design is made of
    (module docstring)."""

    type: str
    target: str
    yaw: int
    cells: tuple[tuple[int, int, int], ...]

    def to_dict(self) -> dict:
        return {'type': self.type, 'target': self.target, 'yaw': self.yaw, 'cells': [list(c) for c in self.cells]}


@dataclass(frozen=True)
class Obstacle:
    """A block that is there but no block of the scene: its measured pose, for motion planning only."""

    id: str
    type: str
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]

    def to_dict(self) -> dict:
        return {'id': self.id, 'type': self.type, 'position': list(self.position),
                'quaternion': list(self.quaternion)}


FEEDER_ORDERS = ('request', 'queue')


@dataclass(frozen=True)
class Feeder:
    """Blocks that arrive at a pick station (module docstring)."""

    station: tuple[float, float]
    blocks: tuple[str, ...]
    yaw: int = 0
    order: str = 'request'
    window: int = 1

    def available(self) -> tuple[str, ...]:
        """The ids the robot may take next: any in the feeder, or the queue's first `window`."""
        return self.blocks if self.order == 'request' else self.blocks[:self.window]

    def without(self, block_id: str) -> 'Feeder':
        return Feeder(self.station, tuple(b for b in self.blocks if b != block_id), self.yaw, self.order,
                      self.window)

    def to_dict(self) -> dict:
        doc = {'station': list(self.station), 'yaw': self.yaw, 'order': self.order, 'blocks': list(self.blocks)}
        if self.order == 'queue':
            doc['window'] = self.window
        return doc


def station_position(btype: BlockType, station, yaw: int, unit: float,
                     course: float | None = None) -> tuple[float, float, float]:
    """Anchor position of a block presented at a station: its footprint centred on `station`
    (x, y), its lowest units on the table (`course`: the lattice's z pitch, the unit where None)."""
    course = unit if course is None else course
    offs = btype.rotated(yaw)
    lo, hi = offs.min(axis=0), offs.max(axis=0)
    centre = (lo + hi) / 2
    return (round(float(station[0] - centre[0] * unit), 6), round(float(station[1] - centre[1] * unit), 6),
            round(float(course / 2 - lo[2] * course), 6))


def feeder_of(kinds, types: Mapping[str, BlockType], station, unit: float, order: str = 'request',
              window: int = 1, course: float | None = None) -> tuple[list['Block'], Feeder]:
    """Blocks of these kinds, ids b0, b1, ... in this order, each waiting in a feeder that presents it
    at `station` (x, y) at yaw 0; and that feeder."""
    blocks = [Block(f'b{n}', kind, station_position(types[kind], station, 0, unit, course), 0)
              for n, kind in enumerate(kinds)]
    return blocks, Feeder(tuple(float(v) for v in station), tuple(b.id for b in blocks), 0, order, window)


@dataclass(frozen=True)
class TargetRegion:
    name: str
    origin: tuple[float, float, float]
    size: tuple[int, int, int]
    filled: tuple[tuple[int, int, int], ...]

    @property
    def num_cells(self) -> int:
        return self.size[0] * self.size[1] * self.size[2]

    def contains_index(self, ijk) -> bool:
        return all(0 <= int(ijk[a]) < self.size[a] for a in range(3))

    def cell_center(self, ijk, pitch) -> np.ndarray:
        """pitch: the scene's lattice pitch, `Scene.pitch` (a number where the cells are cubes)."""
        return np.asarray(self.origin) + pitch * np.asarray(ijk, dtype=float)

    def bounds(self, pitch) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box covered by the region's cells (lower, upper corner); pitch as `cell_center`."""
        lo = np.asarray(self.origin) - np.asarray(pitch) / 2
        return lo, lo + pitch * np.asarray(self.size, dtype=float)

    def to_dict(self) -> dict:
        return {'name': self.name, 'origin': list(self.origin), 'size': list(self.size),
                'filled': [list(c) for c in self.filled]}


@dataclass(frozen=True)
class Scene:
    unit: float
    block_types: Mapping[str, BlockType]
    blocks: tuple[Block, ...]
    targets: tuple[TargetRegion, ...]
    clearance: float = 0.0
    """Gap left between neighbouring blocks, a fraction of the unit (module docstring); 0 = flush."""
    measured_offsets: Mapping[str, tuple[float, ...]] = field(default_factory=dict, compare=False)
    """Block id -> (dx, dy) m: where motion capture saw a block snapped onto its cell; (0, 0, turn deg)
    for one lying on the table turned off the 90-degree yaws (module docstring)."""
    obstacles: tuple[Obstacle, ...] = field(default=(), compare=False)
    """Blocks set aside by registration, where they lie (module docstring)."""
    feeder: Feeder | None = None
    """Blocks that arrive at a pick station instead of lying on the table (module docstring)."""
    studs: Studs | None = None
    """The blocks' stud system, None for blocks that only rest (module docstring)."""
    design: tuple[Placement, ...] = ()
    """How the design these blocks were chosen for fills the targets, in its order (module docstring)."""
    _by_id: dict = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, '_by_id', {b.id: b for b in self.blocks})

    # ---- lookups ---------------------------------------------------------
    def block(self, block_id: str) -> Block:
        try:
            return self._by_id[block_id]
        except KeyError:
            raise SceneError('block', f'unknown block id {block_id!r}') from None

    def target(self, name: str) -> TargetRegion:
        for t in self.targets:
            if t.name == name:
                return t
        raise SceneError('target', f'unknown target region {name!r}')

    @property
    def course(self) -> float:
        """The lattice's z pitch (m): the stud system's course height, else the unit."""
        return self.studs.course if self.studs is not None else self.unit

    @property
    def stud_height(self) -> float:
        """How high (m) the studs stand (0 without studs): a brick not pressed home stands this much
        above its seat (`domain.studs.stud_height`)."""
        return stud_height(self.studs.system, self.unit) if self.studs is not None else 0.0

    @property
    def pitch(self) -> np.ndarray:
        """The lattice's pitch along x, y, z (m): cell [i, j, k] lies pitch * [i, j, k] from a
        region's origin."""
        return np.array([self.unit, self.unit, self.course])

    def unit_positions(self, block: Block) -> np.ndarray:
        """World centres of the block's unit cells, shape (n, 3)."""
        offsets = self.block_types[block.type].rotated(block.yaw)
        return np.asarray(block.position) + self.pitch * offsets

    def offset(self, block_id: str) -> np.ndarray:
        """The block's measured x/y offset from its scene pose as a 3-vector (m; zeros when none)."""
        dx, dy = self.measured_offsets.get(block_id, (0.0, 0.0))[:2]
        return np.array([dx, dy, 0.0])

    def turn(self, block_id: str) -> float:
        """How far (deg) the block is measured turned from its scene yaw (0 when not)."""
        values = self.measured_offsets.get(block_id, ())
        return float(values[2]) if len(values) > 2 else 0.0

    def in_feeder(self, block_id: str) -> bool:
        return self.feeder is not None and block_id in self.feeder.blocks

    def at_station(self, block_id: str, position) -> bool:
        """Whether a block in the feeder at `position` (anchor, m) lies where the feeder presents it:
        within half a unit of its station pose, so not taken."""
        return self.in_feeder(block_id) and bool(
            np.linalg.norm(np.asarray(position, dtype=float) - np.asarray(self.block(block_id).position))
            < 0.5 * self.unit)

    def with_clearance(self, clearance: float) -> 'Scene':
        """This scene with another clearance, validated as a document would be."""
        return Scene.from_dict({**self.to_dict(), 'clearance': clearance})

    def type_counts(self) -> dict[str, int]:
        counts = {name: 0 for name in self.block_types}
        for b in self.blocks:
            counts[b.type] += 1
        return counts

    @property
    def num_target_cells(self) -> int:
        return sum(len(t.filled) for t in self.targets)

    # ---- serialisation ---------------------------------------------------
    def to_dict(self) -> dict:
        doc = {'format': FORMAT, 'unit': self.unit}
        if self.clearance:
            # Only when set: flush scenes keep the exact documents they always had.
            doc['clearance'] = self.clearance
        if self.studs is not None:
            doc['studs'] = self.studs.to_dict()
        doc.update({
            'block_types': {n: [list(o) for o in t.offsets] for n, t in self.block_types.items()},
            'blocks': [b.to_dict() for b in self.blocks],
            'targets': [t.to_dict() for t in self.targets],
        })
        if self.measured_offsets:
            doc['measured_offsets'] = {k: list(v) for k, v in self.measured_offsets.items()}
        if self.obstacles:
            doc['obstacles'] = [o.to_dict() for o in self.obstacles]
        if self.feeder is not None:
            doc['feeder'] = self.feeder.to_dict()
        if self.design:
            doc['design'] = [p.to_dict() for p in self.design]
        return doc

    def dumps(self) -> str:
        return jsonfmt.dumps(self.to_dict())

    @classmethod
    def loads(cls, text: str) -> 'Scene':
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            raise SceneError('', f'not valid JSON: {e.msg} at line {e.lineno} column {e.colno}') from None
        except RecursionError:
            raise SceneError('', 'not valid JSON: nested too deeply') from None
        return cls.from_dict(doc)

    @classmethod
    def load(cls, path: str | Path) -> 'Scene':
        try:
            text = Path(path).read_text()
        except OSError as e:
            raise SceneError('', f'cannot read scene file {str(path)!r}: {e.strerror}') from None
        except UnicodeDecodeError:
            raise SceneError('', f'scene file {str(path)!r} is not UTF-8 text') from None
        return cls.loads(text)

    @classmethod
    def from_dict(cls, doc: Any) -> 'Scene':
        return _parse_scene(doc)


# ---- parsing and validation ---------------------------------------------

def _expect(cond: bool, where: str, problem: str) -> None:
    if not cond:
        raise SceneError(where, problem)


def _check_keys(obj: Mapping, where: str, required: set[str], optional: set[str] = frozenset()) -> None:
    missing = sorted(required - obj.keys())
    _expect(not missing, where, f'missing field {missing[0]!r}' if missing else '')
    unknown = sorted(set(obj.keys()) - required - set(optional))
    _expect(not unknown, where, f'unknown field {unknown[0]!r}' if unknown else '')


def _number(v: Any, where: str) -> float:
    # (the messages are made only for a value that fails: these run for every number of a scene)
    if not (isinstance(v, (int, float)) and not isinstance(v, bool)):
        raise SceneError(where, f'expected a number, got {_show(v)}')
    if not math.isfinite(v):
        raise SceneError(where, f'must be finite, got {v}')
    if not abs(v) <= MAX_COORD:
        raise SceneError(where, f'{v} is out of range (|value| <= {MAX_COORD} m)')
    return float(v)


def _integer(v: Any, where: str) -> int:
    if isinstance(v, float) and math.isfinite(v) and v.is_integer():
        v = int(v)
    if not (isinstance(v, int) and not isinstance(v, bool)):
        raise SceneError(where, f'expected an integer, got {_show(v)}')
    return v


def _vec3(v: Any, where: str, conv) -> tuple:
    if not (isinstance(v, (list, tuple)) and len(v) == 3):
        raise SceneError(where, f'expected a list of 3 numbers, got {_show(v)}')
    return tuple(conv(x, f'{where}[{i}]') for i, x in enumerate(v))


def _name(v: Any, where: str) -> str:
    if not (isinstance(v, str) and v.strip() != ''):
        raise SceneError(where, f'expected a non-empty string, got {_show(v)}')
    _expect(len(v) <= 128, where, 'longer than 128 characters')
    return v


def _show(v: Any) -> str:
    text = json.dumps(v) if isinstance(v, (dict, list, str, int, float, bool, type(None))) else repr(v)
    return text if len(text) <= 40 else text[:37] + '...'


def _clearance(v: Any) -> float:
    _expect(isinstance(v, (int, float)) and not isinstance(v, bool), 'clearance',
            f'expected a fraction of the unit as a number, got {_show(v)}')
    _expect(math.isfinite(v), 'clearance', f'must be finite, got {v}')
    _expect(0 <= v < MAX_CLEARANCE, 'clearance',
            f'{v} is outside 0 <= clearance < {MAX_CLEARANCE} (a fraction of the unit: the gap between '
            f'neighbouring blocks)')
    return float(v)


def _parse_studs(doc: Any, unit: float) -> Studs | None:
    """``studs``: 'none', a system's name, or {system, course?, clutch?, mass?, baseplate?}; a named
    system fills in its course height (its brick's, in proportion to the unit), clutch and mass."""
    if doc == 'none':
        return None
    if isinstance(doc, str):
        doc = {'system': doc}
    _expect(isinstance(doc, dict), 'studs', f"expected 'none', a system name ({', '.join(SYSTEMS)}) or "
                                            f"{{system, course, clutch}}, got {_show(doc)}")
    _check_keys(doc, 'studs', {'system'}, {'course', 'clutch', 'mass', 'baseplate'})
    name = _name(doc['system'], 'studs.system')
    known = SYSTEMS.get(name)
    for key in ('course', 'clutch', 'mass'):
        _expect(known is not None or key in doc, 'studs',
                f"system {name!r} is not one rad knows ({', '.join(SYSTEMS)}): give its {key}")
    course = _number(doc['course'], 'studs.course') if 'course' in doc else unit * known.course_ratio()
    _expect(0.2 * unit <= course <= 3.0 * unit, 'studs.course',
            f'{course} m is outside 0.2..3 units ({0.2 * unit:g}..{3 * unit:g} m): the course height of the lattice')
    clutch = _number(doc['clutch'], 'studs.clutch') if 'clutch' in doc else known.clutch
    _expect(0 < clutch <= 100, 'studs.clutch', f'{clutch} N is outside 0 < clutch <= 100 N per stud connection')
    mass = _number(doc['mass'], 'studs.mass') if 'mass' in doc else round(known.cell_mass(unit, course), 9)
    _expect(1e-5 <= mass <= 1.0, 'studs.mass', f'{mass} kg is outside 0.00001..1 kg (one lattice cell of a brick)')
    baseplate = doc.get('baseplate', False)
    _expect(isinstance(baseplate, bool), 'studs.baseplate', f'expected true or false, got {_show(baseplate)}')
    return Studs(name, round(course, 9), clutch, mass, baseplate)


def _parse_block_types(doc: Any) -> dict[str, BlockType]:
    _expect(isinstance(doc, dict), 'block_types', 'expected an object mapping type names to cell lists')
    _expect(0 < len(doc) <= MAX_BLOCK_TYPES, 'block_types', f'needs 1 to {MAX_BLOCK_TYPES} types, got {len(doc)}')
    types = {}
    for name, cells in doc.items():
        where = f'block_types.{name}'
        _name(name, where)
        _expect(isinstance(cells, list) and 0 < len(cells) <= MAX_TYPE_UNITS, where,
                f'expected a list of 1 to {MAX_TYPE_UNITS} cells [x, y, z]')
        cells = [_vec3(c, f'{where}[{i}]', _integer) for i, c in enumerate(cells)]
        _expect(len(set(cells)) == len(cells), where, 'lists the same cell twice')
        t = BlockType.from_cells(name, cells)
        extent = max(max(abs(v) for v in o) for o in t.offsets)
        _expect(extent <= MAX_TYPE_EXTENT, where,
                f'cells reach {extent} units from the anchor (limit {MAX_TYPE_EXTENT})')
        _expect(t.is_connected(), where, 'cells are not face-connected (a block must be one piece)')
        types[name] = t
    return types


def _yaw(yaw: Any, where: str) -> int:
    _expect(isinstance(yaw, (int, float)) and not isinstance(yaw, bool) and math.isfinite(yaw), where,
            f'expected degrees as a number, got {_show(yaw)}')
    _expect(float(yaw) % 90 == 0, where, f'{yaw} is not a multiple of 90 degrees')
    return int(yaw) % 360


def _parse_block(doc: Any, i: int, types: Mapping[str, BlockType], feeder: dict | None, unit: float,
                 course: float) -> Block:
    """A block; one in the feeder (`feeder`: its station, yaw and ids) gets its pose at the station."""
    where = f'blocks[{i}]'
    _expect(isinstance(doc, dict), where, 'expected an object')
    bid = _name(doc.get('id'), f'{where}.id') if 'id' in doc else None
    fed = feeder is not None and bid in feeder['ids']
    _check_keys(doc, where, {'id', 'type'} if fed else {'id', 'type', 'position', 'yaw'}, {'position', 'yaw'})
    btype = _name(doc['type'], f'{where}.type')
    _expect(btype in types, f'{where}.type', f'unknown block type {btype!r} (not in block_types)')
    if not fed:
        return Block(bid, btype, _vec3(doc['position'], f'{where}.position', _number), _yaw(doc['yaw'], f'{where}.yaw'))
    yaw = feeder['yaw']
    _expect(_yaw(doc.get('yaw', yaw), f'{where}.yaw') == yaw, f'{where}.yaw',
            f'block {bid!r} is in the feeder, which presents it at yaw {yaw}, not {doc.get("yaw")}')
    pos = station_position(types[btype], feeder['station'], yaw, unit, course)
    if 'position' in doc:
        given = _vec3(doc['position'], f'{where}.position', _number)
        _expect(max(abs(a - b) for a, b in zip(given, pos)) <= 1e-4, f'{where}.position',
                f'block {bid!r} is in the feeder: its pose is the station\'s, {list(pos)}, not {list(given)} '
                f'(leave position out)')
    return Block(bid, btype, pos, yaw)


def _parse_feeder(doc: Any) -> dict:
    """The feeder's fields, checked; its ids are checked against the blocks later."""
    _expect(isinstance(doc, dict), 'feeder', 'expected an object {station, blocks, yaw?, order?, window?}')
    _check_keys(doc, 'feeder', {'station', 'blocks'}, {'yaw', 'order', 'window'})
    st = doc['station']
    _expect(isinstance(st, (list, tuple)) and len(st) == 2, 'feeder.station',
            f'expected [x, y] (m) on the table, got {_show(st)}')
    station = tuple(_number(v, f'feeder.station[{i}]') for i, v in enumerate(st))
    ids = doc['blocks']
    _expect(isinstance(ids, list), 'feeder.blocks', 'expected a list of block ids')
    for k, b in enumerate(ids):
        _name(b, f'feeder.blocks[{k}]')
    _expect(len(set(ids)) == len(ids), 'feeder.blocks', 'lists the same block twice')
    order = doc.get('order', 'request')
    _expect(order in FEEDER_ORDERS, 'feeder.order', f'expected one of {list(FEEDER_ORDERS)}, got {_show(order)}')
    window = _integer(doc.get('window', 1), 'feeder.window')
    _expect(window >= 1, 'feeder.window', f'the robot must be able to take at least one block, got {window}')
    _expect(order == 'queue' or 'window' not in doc, 'feeder.window',
            'only a queue feeder has a window (a request feeder presents any block)')
    return {'station': station, 'ids': tuple(ids), 'yaw': _yaw(doc.get('yaw', 0), 'feeder.yaw'), 'order': order,
            'window': window}


def _parse_target(doc: Any, i: int) -> TargetRegion:
    where = f'targets[{i}]'
    _expect(isinstance(doc, dict), where, 'expected an object')
    _check_keys(doc, where, {'name', 'origin', 'size', 'filled'})
    name = _name(doc['name'], f'{where}.name')
    origin = _vec3(doc['origin'], f'{where}.origin', _number)
    size = _vec3(doc['size'], f'{where}.size', _integer)
    for a, n in enumerate(size):
        _expect(1 <= n <= MAX_REGION_AXIS, f'{where}.size[{a}]', f'{n} cells is outside 1..{MAX_REGION_AXIS}')
    filled = doc['filled']
    _expect(isinstance(filled, list), f'{where}.filled', 'expected a list of cells [i, j, k]')
    _expect(len(filled) > 0, f'{where}.filled', 'is empty: a target region needs at least one target cell')
    cells = []
    for k, c in enumerate(filled):
        cell = _vec3(c, f'{where}.filled[{k}]', _integer)
        _expect(all(0 <= cell[a] < size[a] for a in range(3)), f'{where}.filled[{k}]',
                f'cell {list(cell)} is outside the box of size {list(size)}')
        cells.append(cell)
    _expect(len(set(cells)) == len(cells), f'{where}.filled', 'lists the same cell twice')
    return TargetRegion(name, origin, size, tuple(sorted(cells)))


def _parse_scene(doc: Any) -> Scene:
    _expect(isinstance(doc, dict), '', 'a scene must be a JSON object')
    _check_keys(doc, '', {'format', 'unit', 'block_types', 'blocks', 'targets'},
                {'clearance', 'measured_offsets', 'obstacles', 'feeder', 'studs', 'design'})
    _expect(doc['format'] == FORMAT, 'format', f'expected {FORMAT!r}, got {_show(doc["format"])}')
    unit = _number(doc['unit'], 'unit')
    _expect(UNIT_RANGE[0] <= unit <= UNIT_RANGE[1], 'unit', f'{unit} m is outside {UNIT_RANGE[0]}..{UNIT_RANGE[1]} m')
    clearance = _clearance(doc.get('clearance', 0.0))
    studs = _parse_studs(doc.get('studs', 'none'), unit)
    course = unit if studs is None else studs.course
    types = _parse_block_types(doc['block_types'])

    blocks_doc = doc['blocks']
    _expect(isinstance(blocks_doc, list), 'blocks', 'expected a list')
    _expect(len(blocks_doc) <= MAX_BLOCKS, 'blocks', f'{len(blocks_doc)} blocks exceed the limit of {MAX_BLOCKS}')
    feeder = _parse_feeder(doc['feeder']) if 'feeder' in doc else None
    blocks = tuple(_parse_block(b, i, types, feeder, unit, course) for i, b in enumerate(blocks_doc))
    seen = {}
    for i, b in enumerate(blocks):
        _expect(b.id not in seen, f'blocks[{i}].id', f'duplicate id {b.id!r} (also blocks[{seen.get(b.id)}])')
        seen[b.id] = i
    if feeder is not None:
        unknown = [b for b in feeder['ids'] if b not in seen]
        _expect(not unknown, 'feeder.blocks', f'unknown block id {unknown[0]!r}' if unknown else '')
        feeder = Feeder(feeder['station'], feeder['ids'], feeder['yaw'], feeder['order'], feeder['window'])

    targets_doc = doc['targets']
    _expect(isinstance(targets_doc, list) and len(targets_doc) > 0, 'targets', 'expected a non-empty list of regions')
    _expect(len(targets_doc) <= MAX_TARGETS, 'targets', f'{len(targets_doc)} regions exceed the limit of {MAX_TARGETS}')
    targets = tuple(_parse_target(t, i) for i, t in enumerate(targets_doc))
    names = [t.name for t in targets]
    for i, n in enumerate(names):
        _expect(names.index(n) == i, f'targets[{i}].name', f'duplicate region name {n!r}')
    total = sum(t.num_cells for t in targets)
    _expect(total <= MAX_GRID_CELLS, 'targets', f'{total} grid cells exceed the limit of {MAX_GRID_CELLS}')

    offsets = _parse_offsets(doc.get('measured_offsets', {}), seen, unit)
    obstacles = _parse_obstacles(doc.get('obstacles', []), seen, types)
    if feeder is not None:
        _expect(not any(b in offsets for b in feeder.blocks), 'measured_offsets',
                'a block in the feeder has no measured offset (it is not on the table)')
    design = _parse_design(doc.get('design', []), types, targets)
    scene = Scene(unit, types, blocks, targets, clearance, offsets, obstacles, feeder, studs, design)
    _check_geometry(scene)
    return scene


def _parse_design(doc: Any, types: Mapping[str, BlockType], targets) -> tuple[Placement, ...]:
    """``design``: poses {type, target, yaw, cells}, each its type's cells turned by yaw, inside its
    region, no cell in two poses."""
    _expect(isinstance(doc, list), 'design', 'expected a list of poses {type, target, yaw, cells}')
    _expect(len(doc) <= MAX_BLOCKS, 'design', f'{len(doc)} poses exceed the limit of {MAX_BLOCKS}')
    regions = {t.name: t for t in targets}
    poses, taken = [], {}
    for i, pose in enumerate(doc):
        where = f'design[{i}]'
        _expect(isinstance(pose, dict), where, 'expected an object {type, target, yaw, cells}')
        _check_keys(pose, where, {'type', 'target', 'yaw', 'cells'})
        kind = _name(pose['type'], f'{where}.type')
        _expect(kind in types, f'{where}.type', f'unknown block type {kind!r} (not in block_types)')
        region = regions.get(_name(pose['target'], f'{where}.target'))
        _expect(region is not None, f'{where}.target', f'unknown target region {pose["target"]!r}')
        yaw = _yaw(pose['yaw'], f'{where}.yaw')
        cells = pose['cells']
        _expect(isinstance(cells, list) and len(cells) == len(types[kind].offsets), f'{where}.cells',
                f'expected the {len(types[kind].offsets)} cells [i, j, k] a {kind} fills')
        cells = tuple(_vec3(c, f'{where}.cells[{k}]', _integer) for k, c in enumerate(cells))
        _expect(canonical_shape(cells) == canonical_shape(types[kind].rotated(yaw)), f'{where}.cells',
                f'are not the cells of a {kind} at yaw {yaw}')
        for cell in cells:
            _expect(region.contains_index(cell), f'{where}.cells',
                    f'cell {list(cell)} is outside region {region.name!r} (size {list(region.size)})')
            other = taken.setdefault((region.name, cell), i)
            _expect(other == i, f'{where}.cells', f'cell {list(cell)} of {region.name!r} is also in design[{other}]')
        poses.append(Placement(kind, region.name, yaw, cells))
    return tuple(poses)


def _parse_obstacles(doc: Any, ids: Mapping[str, int], types) -> tuple[Obstacle, ...]:
    _expect(isinstance(doc, list), 'obstacles', 'expected a list of {id, type, position, quaternion}')
    _expect(len(doc) <= MAX_BLOCKS, 'obstacles', f'{len(doc)} obstacles exceed the limit of {MAX_BLOCKS}')
    out, names = [], set()
    for i, o in enumerate(doc):
        where = f'obstacles[{i}]'
        _expect(isinstance(o, dict), where, 'expected an object')
        _check_keys(o, where, {'id', 'type', 'position', 'quaternion'}, set())
        oid = o['id']
        _expect(isinstance(oid, str) and oid, f'{where}.id', f'expected a non-empty string, got {_show(oid)}')
        _expect(oid not in ids and oid not in names, f'{where}.id', f'{oid!r} is also a block or another obstacle')
        names.add(oid)
        _expect(isinstance(o['type'], str) and o['type'] in types, f'{where}.type',
                f'unknown block type {_show(o["type"])}')
        pos, quat = o['position'], o['quaternion']
        _expect(isinstance(pos, list) and len(pos) == 3, f'{where}.position', 'expected [x, y, z] (m)')
        _expect(isinstance(quat, list) and len(quat) == 4, f'{where}.quaternion', 'expected [x, y, z, w]')
        position = tuple(_number(v, f'{where}.position') for v in pos)
        q = np.array([_number(v, f'{where}.quaternion') for v in quat])
        norm = float(np.linalg.norm(q))
        _expect(abs(norm - 1.0) < 1e-3, f'{where}.quaternion', f'not unit length (norm {norm:.4f})')
        out.append(Obstacle(oid, o['type'], position, tuple(float(v) for v in q / norm)))
    return tuple(out)


def _parse_offsets(doc: Any, ids: Mapping[str, int], unit: float) -> dict[str, tuple[float, float]]:
    _expect(isinstance(doc, dict), 'measured_offsets', 'expected an object: block id -> [dx, dy] (m)')
    out = {}
    for block_id, v in doc.items():
        where = f'measured_offsets.{block_id}'
        _expect(block_id in ids, where, f'unknown block id {block_id!r}')
        _expect(isinstance(v, (list, tuple)) and len(v) in (2, 3), where,
                f'expected [dx, dy] (m) or [dx, dy, turn] (m, m, deg), got {_show(v)}')
        values = tuple(_number(x, where) for x in v)
        _expect(all(abs(x) < unit / 2 for x in values[:2]), where,
                f'{list(values[:2])} m is half a unit ({unit / 2} m) or more off: that is another cell, not an offset')
        if len(values) == 3:
            _expect(abs(values[2]) <= 45, where, f'a turn of {values[2]} deg is more than 45: that is another yaw, '
                                                 f'not an offset')
        out[block_id] = values
    return out


def _check_geometry(scene: Scene) -> None:
    """Regions must not overlap; blocks must not overlap, sink into the table,
    or sit in a region off its grid."""
    u, course = scene.pitch, scene.course
    boxes = [t.bounds(u) for t in scene.targets]
    for a in range(len(boxes)):
        for b in range(a + 1, len(boxes)):
            overlap = np.all(boxes[a][0] < boxes[b][1] - 1e-9) and np.all(boxes[b][0] < boxes[a][1] - 1e-9)
            _expect(not overlap, f'targets[{b}]', f'region {scene.targets[b].name!r} overlaps region '
                    f'{scene.targets[a].name!r}')

    centres, owner, fed = [], [], []
    for i, block in enumerate(scene.blocks):
        pts = scene.unit_positions(block)
        if scene.in_feeder(block.id):
            # At the station only when presented, one at a time: checked against the regions and
            # the table's blocks below, not against each other.
            for t in scene.targets:
                lo, hi = t.bounds(u)
                _expect(not np.any(np.all((pts + u / 2 > lo + 0.01 * u) & (pts - u / 2 < hi - 0.01 * u), axis=1)),
                        'feeder.station', f'block {block.id!r} presented at the station would stick into target '
                                          f'region {t.name!r}')
            fed.append((i, pts))
            continue
        low = pts[:, 2].min()
        _expect(low >= course / 2 - 0.25 * course, f'blocks[{i}].position',
                f'block {block.id!r} reaches below the table top (lowest unit centre z={low:.4f} m, '
                f'needs >= {course / 2:.4f})')
        _check_block_vs_regions(scene, i, pts)
        centres.append(pts)
        owner.extend([i] * len(pts))
    if not centres:
        return
    pts = np.concatenate(centres)
    owner = np.asarray(owner)
    reach = 0.99 * u * np.array([1.0 - scene.clearance, 1.0 - scene.clearance, 1.0])
    for i, units in fed:
        close = np.all(np.abs(pts[None, :, :] - units[:, None, :]) < reach, axis=2).any(axis=0)
        if close.any():
            raise SceneError('feeder.station', f'block {scene.blocks[owner[np.argmax(close)]].id!r} lies on the '
                             f'feeder\'s station, where block {scene.blocks[i].id!r} would be presented')
    # Axis-aligned unit cubes (yaw is a multiple of 90) overlap iff their centres
    # are closer than one unit on every axis (`reach`); units of two blocks face each other
    # with outer faces, so with a clearance they may come that much closer sideways.
    for k in range(len(pts)):
        close = np.all(np.abs(pts[k + 1:] - pts[k]) < reach, axis=1) & (owner[k + 1:] != owner[k])
        if close.any():
            j = owner[k + 1:][np.argmax(close)]
            raise SceneError(f'blocks[{j}]', f'block {scene.blocks[j].id!r} overlaps block '
                             f'{scene.blocks[owner[k]].id!r}')


def _check_block_vs_regions(scene: Scene, i: int, pts: np.ndarray) -> None:
    """A block lies either clear of every region box or with all units on grid cells.

    Units may be spread over adjacent regions; a block half in a region and half
    out, or inside one but off its grid, is rejected.
    """
    u = scene.pitch
    where, name = f'blocks[{i}].position', scene.blocks[i].id
    in_some = np.zeros(len(pts), dtype=bool)
    for t in scene.targets:
        lo, hi = t.bounds(u)
        inside = np.all((pts > lo + 0.01 * u) & (pts < hi - 0.01 * u), axis=1)
        touching = np.all((pts + u / 2 > lo + 0.01 * u) & (pts - u / 2 < hi - 0.01 * u), axis=1)
        _expect(not (touching & ~inside).any(), where,
                f'block {name!r} sticks into target region {t.name!r} without being on its grid')
        if inside.any():
            idx = (pts[inside] - np.asarray(t.origin)) / u
            _expect(np.all(np.abs(idx - np.round(idx)) <= GRID_SNAP_TOL), where,
                    f'block {name!r} is inside target region {t.name!r} but not on its grid '
                    f'(more than {GRID_SNAP_TOL:g} unit from a cell centre)')
        in_some |= inside
    _expect(in_some.all() or not in_some.any(), where, f'block {name!r} sticks out of the target regions')

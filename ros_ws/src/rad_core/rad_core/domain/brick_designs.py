"""Brick designs as people have them: the text of text-to-brick generators, and LDraw models.

Why: people describe studded-brick builds (LEGO, Duplo) in two common forms, the one-brick-a-line
text that text-to-brick generators (LegoGPT / BrickGPT) write, and LDraw (.ldr, .mpd) files
that CAD tools write. rad must read both and keep the bricks as bricks: sizes in studs, places
on the stud lattice. This module reads them into one model, `BrickDesign`, and refuses what it
cannot hold faithfully (unknown parts, tilted or mirrored parts, places off the lattice,
bricks that overlap) with a message that names the file and line, rather than guess.

The design frame: x and y on the ground in studs, z up in plates, right-handed. A LEGO brick is
3 plates tall; a Duplo brick is also 3 "plates" of its own system, so heights are in thirds of
a brick for both. A brick's (x, y) is the stud of its corner with the smallest x and y.

The text format: one brick a line, `HxW (x,y,z)`: H studs along x, W along y, (x, y) the corner
stud, z the course (0 on the ground). Blank lines, `#` comments and spaces are allowed.

LDraw: 1 stud = 20 LDU (Duplo 40), a brick 24 LDU tall (Duplo 48), a plate 8; -y is up. Every
part in PARTS has its origin at the centre of its top face, its body below it (+y), its long
side along x: checked against the bounding boxes of the parts' geometry in the LDraw library
(2024-05 update). LDraw is y-down; the design frame is design (x, y, z) = LDraw (x, z, -y), a
quarter turn about x with no mirror, so a turn about LDraw's vertical axis is a turn about z.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from rad_core.domain.errors import SceneError

PLATES_PER_BRICK = 3
LATTICE_TOLERANCE = 0.05   # how far off the lattice a place may be, in studs or plates
TURN_TOLERANCE = 0.01      # how far off a quarter turn a rotation matrix may be, per entry

# LDU per stud, LDU per plate (a third of a brick), of each system.
LDRAW_UNITS = {'lego': (20.0, 8.0), 'duplo': (40.0, 16.0)}


@dataclass(frozen=True)
class PartShape:
    """A supported LDraw part: its studs along LDraw x and z unturned, its height in plates."""

    number: str
    kind: str           # 'brick' or 'plate'
    studs_x: int
    studs_z: int
    plates: int
    system: str         # 'lego' or 'duplo'


def _parts(system: str, kind: str, plates: int, table: str) -> dict[str, PartShape]:
    """'number:XxZ ...' as PartShapes."""
    out = {}
    for item in table.split():
        number, size = item.split(':')
        sx, sz = (int(v) for v in size.split('x'))
        out[number] = PartShape(number, kind, sx, sz, plates, system)
    return out


PARTS: dict[str, PartShape] = {
    **_parts('lego', 'brick', 3, '3005:1x1 3004:2x1 3622:3x1 3010:4x1 3009:6x1 3008:8x1 '
                                 '3003:2x2 3002:3x2 3001:4x2 2456:6x2 3007:8x2 3006:10x2'),
    **_parts('lego', 'plate', 1, '3024:1x1 3023:2x1 3023b:2x1 3623:3x1 3710:4x1 3666:6x1 3460:8x1 '
                                 '3022:2x2 3021:3x2 3020:4x2 3795:6x2 3034:8x2'),
    # 31459 and 31460 are the library's aliases of 3011 and 3437.
    **_parts('duplo', 'brick', 3, '3437:2x2 31460:2x2 87084:3x2 3011:4x2 31459:4x2 2300:6x2 '
                                  '4199:8x2 2291:10x2'),
    **_parts('duplo', 'brick', 6, '31110:2x2 31111:4x2'),     # two bricks tall
}


class BrickDesignError(SceneError):
    """A brick design file that cannot be read as bricks; str(error) names the file and line."""

    def __init__(self, where: str, problem: str, line: int | None = None):
        self.line = line
        super().__init__(where, problem)


def _at(source: str, line: int | None) -> str:
    return f'{source} line {line}' if line else source


@dataclass(frozen=True)
class Brick:
    """One brick or plate: `length` studs along x and `width` along y (after its turn), its
    corner stud (x, y), the height of its bottom `z` and its `height`, both in plates."""

    length: int
    width: int
    x: int
    y: int
    z: int
    height: int = PLATES_PER_BRICK
    part: str | None = None
    line: int = 0
    source: str = ''

    def __post_init__(self):
        if min(self.length, self.width, self.height) < 1:
            raise BrickDesignError(_at(self.source, self.line),
                                   f'a brick is at least 1x1 and 1 plate tall, not {self.size}')

    @property
    def size(self) -> str:
        return f'{self.length}x{self.width}'

    @property
    def box(self) -> tuple[int, int, int, int, int, int]:
        """(x, y, z, length, width, height): where it is and how big, without where it came from."""
        return self.x, self.y, self.z, self.length, self.width, self.height

    def describe(self) -> str:
        kind = {PLATES_PER_BRICK: 'brick', 1: 'plate'}.get(self.height, f'{self.height}-plate brick')
        part = f' {self.part}' if self.part else ''
        if self.z % PLATES_PER_BRICK == 0:
            up = f'on course {self.z // PLATES_PER_BRICK}'
        else:
            up = f'{self.z} plates up'
        return f'{self.size} {kind}{part} at ({self.x},{self.y}) {up}'

    def cells(self, course_plates: int) -> set[tuple[int, int, int]]:
        """The (i, j, k) cells it fills, k counting courses of course_plates plates."""
        if self.z % course_plates or self.height % course_plates:
            raise BrickDesignError(_at(self.source, self.line),
                                   f'{self.describe()} does not sit on courses of {course_plates} plates')
        k0 = self.z // course_plates
        return {(i, j, k)
                for i in range(self.x, self.x + self.length)
                for j in range(self.y, self.y + self.width)
                for k in range(k0, k0 + self.height // course_plates)}


@dataclass(frozen=True)
class BrickDesign:
    """The bricks of one design; `system` is 'lego', 'duplo', or None where the format cannot say."""

    bricks: tuple[Brick, ...]
    system: str | None = None
    name: str = ''

    def normalised(self) -> BrickDesign:
        """The same design shifted so the smallest x, y and z are 0."""
        if not self.bricks:
            return self
        dx, dy, dz = (min(getattr(b, a) for b in self.bricks) for a in 'xyz')
        moved = tuple(replace(b, x=b.x - dx, y=b.y - dy, z=b.z - dz) for b in self.bricks)
        return replace(self, bricks=moved)

    def course_plates(self) -> int:
        """The coarsest course, in plates, that every brick's z and height are multiples of:
        3 for bricks on brick courses, 1 where plates shift them."""
        values = [v for b in self.bricks for v in (b.z, b.height)]
        return math.gcd(*values) if values else PLATES_PER_BRICK

    def cells(self, course_plates: int | None = None) -> set[tuple[int, int, int]]:
        """Every cell some brick fills, with courses of course_plates (default course_plates())."""
        c = course_plates or self.course_plates()
        return set().union(*(b.cells(c) for b in self.bricks))

    def overlaps(self) -> list[tuple[Brick, Brick]]:
        """Pairs of bricks that share a cell, each pair once, earlier brick first."""
        c = self.course_plates()
        owner: dict[tuple[int, int, int], int] = {}
        pairs: set[tuple[int, int]] = set()
        for n, brick in enumerate(self.bricks):
            for cell in brick.cells(c):
                first = owner.setdefault(cell, n)
                if first != n:
                    pairs.add((first, n))
        return [(self.bricks[i], self.bricks[j]) for i, j in sorted(pairs)]

    def write_text(self) -> str:
        """The design in the text format, one `HxW (x,y,z)` line a brick, in order. Only whole
        bricks on brick courses fit that format; a plate, or a brick a plate off, is refused."""
        lines = []
        for b in self.bricks:
            if b.height != PLATES_PER_BRICK or b.z % PLATES_PER_BRICK:
                raise BrickDesignError(_at(b.source, b.line),
                                       f'the text format holds whole bricks on brick courses only, '
                                       f'not the {b.describe()}')
            lines.append(f'{b.size} ({b.x},{b.y},{b.z // PLATES_PER_BRICK})\n')
        return ''.join(lines)


def _checked(design: BrickDesign, source: str) -> BrickDesign:
    """The design, if it has bricks and none of them overlap."""
    if not design.bricks:
        raise BrickDesignError('', f'no bricks in {source}')
    pairs = design.overlaps()
    if pairs:
        a, b = pairs[0]
        raise BrickDesignError(_at(source, b.line),
                               f"the {b.describe()} overlaps line {a.line}'s {a.describe()}", b.line)
    return design


# ---- the text format ---------------------------------------------------------------------

_SIZE = r'\s*(\d+)\s*[xX×]\s*(\d+)\s*'
_TEXT_LINE = re.compile(_SIZE + r'\(\s*(-?\d+)\s*,\s*(-?\d+)\s*,\s*(-?\d+)\s*\)\s*')
_TEXT_FORM = "a line reads 'HxW (x,y,z)', such as '2x4 (3,7,0)'"


def _text_problem(body: str) -> str:
    """What is wrong with a line that is not `HxW (x,y,z)`."""
    size, paren, rest = body.partition('(')
    if not paren:
        return "no place '(x,y,z)'"
    if not re.fullmatch(_SIZE, size):
        return f'size {size.strip()!r} is not HxW'
    inside, close, after = rest.partition(')')
    if not close:
        return "the place has no closing ')'"
    if after.strip():
        return f'{after.strip()!r} after the place'
    numbers = [v.strip() for v in inside.split(',')]
    if len(numbers) != 3:
        return f'the place needs 3 numbers x,y,z, not {len(numbers)}'
    bad = next((v for v in numbers if not re.fullmatch(r'-?\d+', v)), inside)
    return f'{bad!r} in the place is not a whole number'


def _text_brick(body: str, number: int, source: str) -> Brick:
    m = _TEXT_LINE.fullmatch(body)
    if m is None:
        raise BrickDesignError(_at(source, number), f'{body.strip()!r}: {_text_problem(body)}; {_TEXT_FORM}',
                               number)
    length, width, x, y, course = (int(v) for v in m.groups())
    if length < 1 or width < 1:
        raise BrickDesignError(_at(source, number), f'size {length}x{width}: a brick is at least 1x1', number)
    return Brick(length, width, x, y, course * PLATES_PER_BRICK, PLATES_PER_BRICK, None, number, source)


def parse_text(text: str, source: str = '<text>', name: str | None = None) -> BrickDesign:
    """A design from the text format (one `HxW (x,y,z)` a line); system None, as it cannot say."""
    bricks = []
    for number, line in enumerate(text.removeprefix('\ufeff').splitlines(), 1):
        body = line.split('#', 1)[0]
        if body.strip():
            bricks.append(_text_brick(body, number, source))
    design = BrickDesign(tuple(bricks), None, Path(source).stem if name is None else name)
    return _checked(design, source)


# ---- LDraw ---------------------------------------------------------------------------------

def _model_key(name: str) -> str:
    """How LDraw names compare: any case, either slash."""
    return name.strip().replace('\\', '/').lower()


def _part_number(name: str) -> str:
    """'S\\3001.DAT', 'parts/3001.dat', '3001' -> '3001'."""
    key = _model_key(name).rsplit('/', 1)[-1]
    return key[:-4] if key.endswith('.dat') else key


def _supported() -> str:
    """The part table in words, as a hint in the message for an unknown part."""
    groups: dict[str, list[str]] = {}
    for p in PARTS.values():
        group = f'{"Duplo" if p.system == "duplo" else "LEGO"} {p.kind}s'
        tall = f'x{p.plates // PLATES_PER_BRICK}' if p.plates > PLATES_PER_BRICK else ''
        groups.setdefault(group, []).append(f'{p.number} ({p.studs_z}x{p.studs_x}{tall})')
    return '; '.join(f'{group}: {", ".join(parts)}' for group, parts in groups.items())


def _ldraw_sections(text: str, source: str) -> tuple[str, dict[str, list[tuple[int, str]]]]:
    """The main model's key and each model's non-comment lines (line number, text). A plain
    .ldr is one model keyed ''; in an .mpd the first `0 FILE` is the main model."""
    sections: dict[str, list[tuple[int, str]]] = {'': []}
    current: str | None = ''
    main = ''
    for number, line in enumerate(text.splitlines(), 1):
        tokens = line.split()
        if not tokens:
            continue
        if tokens[0] != '0':
            if current is not None:
                sections[current].append((number, line))
            continue
        meta = tokens[1].upper() if len(tokens) > 1 else ''
        if meta == 'FILE':
            current = _model_key(line.split(None, 2)[2] if len(tokens) > 2 else '')
            if current in sections:
                raise BrickDesignError(_at(source, number), f'a second model named {current!r}', number)
            sections[current] = []
            main = main or current
        elif meta in ('NOFILE', '!DATA'):
            current = None
    if main and sections['']:
        number = sections[''][0][0]
        raise BrickDesignError(_at(source, number), "a part before the first '0 FILE' line", number)
    return main, sections


def _quarter_turn(rot: np.ndarray) -> tuple[bool, str]:
    """(whether the footprint's x and z swap, '') for a turn about LDraw's vertical axis by a
    multiple of 90 degrees; (False, what is wrong) for anything else."""
    r = np.rint(rot)
    if np.abs(rot - r).max() > TURN_TOLERANCE or not np.array_equal(r @ r.T, np.eye(3)):
        return False, 'turned by other than a multiple of 90 degrees, or scaled'
    if round(np.linalg.det(r)) < 0:
        return False, 'mirrored'
    if r[1, 1] != 1:
        return False, 'tilted or upside down'
    return bool(r[0, 0] == 0), ''


def _on_lattice(value: float, what: str) -> int:
    n = round(value)
    if abs(value - n) > LATTICE_TOLERANCE:
        raise ValueError(f'{value:.3f} {what}, off the lattice')
    return int(n)


class _LDrawReader:
    """Walks the main model, composing the placements of submodels, and collects its bricks."""

    def __init__(self, text: str, source: str):
        self.source = source
        self.main, self.sections = _ldraw_sections(text, source)
        self.bricks: list[Brick] = []
        self.systems: dict[str, int] = {}     # system -> line of its first part

    def where(self, number: int, via: tuple[tuple[str, int], ...]) -> str:
        inside = ''.join(f' (in submodel {name!r} placed by line {line})' for name, line in reversed(via))
        return _at(self.source, number) + inside

    def walk(self, key: str, rot: np.ndarray, pos: np.ndarray, via: tuple[tuple[str, int], ...]) -> None:
        for number, line in self.sections[key]:
            kind = line.split(None, 1)[0]
            if kind in ('2', '3', '4', '5'):
                continue
            if kind != '1':
                raise BrickDesignError(self.where(number, via),
                                       f'line type {kind!r}: an LDraw line starts with 0 to 5', number)
            tokens = line.split(None, 14)
            try:
                values = [float(v) for v in tokens[2:14]]
            except ValueError:
                values = []
            if len(tokens) < 15 or len(values) != 12:
                raise BrickDesignError(self.where(number, via),
                                       'a part line reads 1 colour x y z a b c d e f g h i part', number)
            here_rot = rot @ np.array(values[3:]).reshape(3, 3)
            here_pos = rot @ np.array(values[:3]) + pos
            ref = _model_key(tokens[14])
            if ref in self.sections:
                if ref == self.main or any(ref == name for name, _ in via):
                    raise BrickDesignError(self.where(number, via), f'submodel {ref!r} contains itself', number)
                self.walk(ref, here_rot, here_pos, via + ((ref, number),))
            else:
                self.bricks.append(self.brick(tokens[14].strip(), here_rot, here_pos, number, via))

    def brick(self, ref: str, rot: np.ndarray, pos: np.ndarray, number: int, via) -> Brick:
        where = self.where(number, via)
        shape = PARTS.get(_part_number(ref))
        if shape is None:
            model = ' (a model not in this file)' if _model_key(ref).endswith(('.ldr', '.mpd')) else ''
            raise BrickDesignError(where, f'unknown part {ref!r}{model}; supported: {_supported()}', number)
        swapped, wrong = _quarter_turn(rot)
        if wrong:
            raise BrickDesignError(where, f'part {shape.number} is {wrong}; only turns about the vertical '
                                          'axis by multiples of 90 degrees are supported', number)
        self.systems.setdefault(shape.system, number)
        pitch, plate = LDRAW_UNITS[shape.system]
        length, width = (shape.studs_z, shape.studs_x) if swapped else (shape.studs_x, shape.studs_z)
        try:
            x = _on_lattice(pos[0] / pitch - length / 2, 'studs along x')
            y = _on_lattice(pos[2] / pitch - width / 2, 'studs along y')
            z = _on_lattice(-pos[1] / plate - shape.plates, 'plates up')
        except ValueError as e:
            raise BrickDesignError(where, f'part {shape.number}: its corner is at {e}', number) from None
        return Brick(length, width, x, y, z, shape.plates, shape.number, number, self.source)

    def design(self, name: str) -> BrickDesign:
        self.walk(self.main, np.eye(3), np.zeros(3), ())
        if len(self.systems) > 1:
            (first, at), (second, line) = sorted(self.systems.items(), key=lambda kv: kv[1])
            raise BrickDesignError(_at(self.source, line),
                                   f'a {second} part in a model whose first part (line {at}) is {first}; '
                                   'one model holds parts of one system', line)
        system = next(iter(self.systems), None)
        return _checked(BrickDesign(tuple(self.bricks), system, name), self.source)


def parse_ldraw(text: str, source: str = '<ldraw>', name: str | None = None) -> BrickDesign:
    """A design from an LDraw model (.ldr, or .mpd with submodels); the system comes from its parts."""
    return _LDrawReader(text, source).design(Path(source).stem if name is None else name)


READERS = {'.txt': parse_text, '.ldr': parse_ldraw, '.mpd': parse_ldraw, '.dat': parse_ldraw}


def read_design(path: str | Path) -> BrickDesign:
    """The design in a file, read by its suffix: .txt as text, .ldr, .mpd and .dat as LDraw."""
    p = Path(path)
    reader = READERS.get(p.suffix.lower())
    if reader is None:
        raise BrickDesignError(str(p), f'unknown suffix {p.suffix!r}; brick designs are {", ".join(READERS)}')
    try:
        text = p.read_text(encoding='utf-8-sig', errors='replace')
    except OSError as e:
        raise BrickDesignError(str(p), f'cannot be read: {e.strerror}') from None
    return reader(text, p.name, p.stem)

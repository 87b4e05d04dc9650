"""Polycube block types and their four yaw rotations about +z.

A block type is a list of integer unit offsets; the first unit is the anchor and
sits at offset (0, 0, 0). Yaw rotates the offsets about +z around the anchor, in
steps of 90 degrees, which keeps every unit on the integer lattice.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

YAWS = (0, 90, 180, 270)

# Rotation matrices about +z for yaw = 0, 90, 180, 270 degrees (exact integers).
_ROT_Z = {
    0: np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.int64),
    90: np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=np.int64),
    180: np.array([[-1, 0, 0], [0, -1, 0], [0, 0, 1]], dtype=np.int64),
    270: np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]], dtype=np.int64),
}


def rotation_z(yaw_deg: int) -> np.ndarray:
    """Integer 3x3 rotation about +z; yaw must be a multiple of 90 degrees."""
    return _ROT_Z[int(yaw_deg) % 360]


@dataclass(frozen=True)
class BlockType:
    """A polycube: unit offsets relative to the anchor (the first unit)."""

    name: str
    offsets: tuple[tuple[int, int, int], ...]

    @classmethod
    def from_cells(cls, name: str, cells: Iterable[Sequence[int]]) -> 'BlockType':
        """Build from cells in any frame; they are shifted so the first is (0, 0, 0)."""
        cells = [tuple(int(v) for v in c) for c in cells]
        ax, ay, az = cells[0]
        return cls(name, tuple((x - ax, y - ay, z - az) for x, y, z in cells))

    @property
    def size(self) -> int:
        return len(self.offsets)

    def rotated(self, yaw_deg: int) -> np.ndarray:
        """Offsets rotated by yaw about the anchor, shape (n, 3), int64."""
        return np.asarray(self.offsets, dtype=np.int64) @ rotation_z(yaw_deg).T

    def distinct_yaws(self) -> tuple[int, ...]:
        """Yaws that give pairwise different shapes (up to translation).

        A cube has one, a flat I2 bar two, an L3 four. The allocation only needs
        one representative per shape; the sequencing level still offers all four
        rotations of a block.
        """
        seen, out = set(), []
        for yaw in YAWS:
            key = canonical_shape(self.rotated(yaw))
            if key not in seen:
                seen.add(key)
                out.append(yaw)
        return tuple(out)

    def is_connected(self) -> bool:
        """True when the units form one face-connected polycube."""
        cells = set(self.offsets)
        stack, seen = [self.offsets[0]], {self.offsets[0]}
        while stack:
            x, y, z = stack.pop()
            for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
                n = (x + d[0], y + d[1], z + d[2])
                if n in cells and n not in seen:
                    seen.add(n)
                    stack.append(n)
        return len(seen) == len(cells)


def unit_boxes(offsets, half_side: float, half_height: float, recess: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One box per unit cube of a block, with the block's outer side faces set back.

    offsets: the block's integer unit offsets (n, 3) in the frame the boxes are wanted in
    (the type's, or turned by a yaw). Every side face (x, y) of a unit lies `half_side`
    from the unit's centre, and `recess` less where it is an outer face, i.e. no unit
    of the same block is behind it (a scene's clearance: ``recess = clearance * edge / 2``);
    top and bottom faces lie `half_height` from it. Returns (shift of each box's centre from
    its unit's centre (n, 3), half extents (n, 3)), in the units of the lengths given.
    With recess 0 every box is centred and exactly (half_side, half_side, half_height).
    """
    offsets = np.asarray(offsets, dtype=np.int64).reshape(-1, 3)
    cells = {tuple(o) for o in offsets.tolist()}
    shift = np.zeros((len(offsets), 3))
    half = np.empty((len(offsets), 3))
    half[:, 2] = half_height
    for i, o in enumerate(offsets.tolist()):
        for a in (0, 1):
            face = []
            for s in (1, -1):
                behind = list(o)
                behind[a] += s
                face.append(half_side if tuple(behind) in cells else half_side - recess)
            shift[i, a] = (face[0] - face[1]) / 2
            half[i, a] = (face[0] + face[1]) / 2
    return shift, half


def canonical_shape(cells: np.ndarray) -> tuple[tuple[int, int, int], ...]:
    """Translation-invariant key of a set of cells: sorted, shifted to min corner."""
    cells = np.asarray(cells, dtype=np.int64)
    shifted = cells - cells.min(axis=0)
    return tuple(sorted(tuple(int(v) for v in row) for row in shifted))


def _lib(**types: list[list[int]]) -> dict[str, BlockType]:
    return {name: BlockType.from_cells(name, cells) for name, cells in types.items()}


# The block set of the paper's predecessor (Learn2Assemble). "_up" types stand
# in the x-z plane; the others lie flat on the table.
DEFAULT_LIBRARY: dict[str, BlockType] = _lib(
    cube=[[0, 0, 0]],
    I2=[[0, 0, 0], [1, 0, 0]],
    I3=[[0, 0, 0], [1, 0, 0], [2, 0, 0]],
    I2_up=[[0, 0, 0], [0, 0, 1]],
    L3=[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
    L3_up=[[0, 0, 0], [1, 0, 0], [0, 0, 1]],
    T4=[[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0]],
    T4_up=[[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 1]],
    O4_up=[[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]],
    S4_up=[[0, 0, 0], [1, 0, 0], [1, 0, 1], [2, 0, 1]],
)


def _plate(name: str, width: int, length: int) -> BlockType:
    return BlockType.from_cells(name, [[i, j, 0] for j in range(width) for i in range(length)])


# Bricks one unit high (plates), width x length studs, lying flat with their length along x. A
# 1 x 2 plate is the I2 and a 1 x 4 the hand-made shapes' bar4 (`shapes.CUSTOM_TYPES`); these are the
# two-wide ones. No unit of a two-wide plate has both finger columns free, so only a wide grasp
# (`gamp.grasps.wide_grasps`) takes one: across its width of 2 units, where that fits the open hand
# (units up to 3.5 cm).
BRICK_TYPES: dict[str, BlockType] = {t.name: t for t in (_plate('B22', 2, 2), _plate('B23', 2, 3),
                                                         _plate('B24', 2, 4))}

"""The voxel grid: every cell of every target region under one global index.

Within a region, cell [i, j, k] has flat index i + j*nx + k*nx*ny (the paper's
flattening, Sec. IV-A); regions follow one another in scene order. Target cells
are the paper's T_F, all other cells T_E.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from rad_core.domain.scene import GRID_SNAP_TOL, Scene


class Grid:
    def __init__(self, scene: Scene):
        self.unit = scene.unit
        self.course = scene.course
        self.pitch = scene.pitch
        """The lattice's pitch along x, y, z (m): the unit, and along z the scene's course height."""
        self.clutch = None if scene.studs is None else scene.studs.clutch_in_weights
        """The pull a stud connection holds, in the weights of a cell (`domain.statics`); None: no studs."""
        self.table_clutch = scene.studs is not None and scene.studs.baseplate
        """Whether the table's studs hold the bricks on it too (a baseplate, ``studs.baseplate``)."""
        self.regions = scene.targets
        sizes = [t.num_cells for t in scene.targets]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.num_cells = int(self.offsets[-1])

        region_of, ijk, centres, target = [], [], [], []
        for r, t in enumerate(scene.targets):
            nx, ny, nz = t.size
            k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
            cells = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
            region_of.append(np.full(len(cells), r))
            ijk.append(cells)
            centres.append(np.asarray(t.origin) + self.pitch * cells)
            mask = np.zeros(len(cells), dtype=bool)
            for c in t.filled:
                mask[self._flat(t.size, c)] = True
            target.append(mask)
        self.region_of = np.concatenate(region_of)
        self.ijk = np.concatenate(ijk).astype(np.int64)
        self.centres = np.concatenate(centres)
        self.is_target = np.concatenate(target)
        # c of the paper's objective c^T g: +1 on target, -1 on non-target cells.
        self.weights = np.where(self.is_target, 1, -1).astype(np.int64)
        # Cells whose unit would rest on the table top (z = 0).
        self.on_table = np.abs(self.centres[:, 2] - self.course / 2) < GRID_SNAP_TOL * self.course
        # The grid cell directly under each cell, -1 where there is none.
        down = np.array([0.0, 0.0, self.course])
        self.below_idx = self.lookup(self.centres - down)
        # The grid cell directly over each cell, -1 where there is none.
        self.above_idx = self.lookup(self.centres + down)

    def columns_above(self, cell_ids) -> np.ndarray:
        """The cells over `cell_ids` in their columns, up to the grid's top, less `cell_ids` themselves
        (sorted): where a block placed from above on `cell_ids` passes on its way down."""
        own = np.asarray(cell_ids, dtype=np.int64)
        layers, up = [], self.above_idx[own]
        while (up >= 0).any():
            up = up[up >= 0]
            layers.append(up)
            up = self.above_idx[up]
        return np.setdiff1d(np.concatenate(layers), own) if layers else np.zeros(0, dtype=np.int64)

    @cached_property
    def face_neighbours(self) -> np.ndarray:
        """[num_cells, 6] face neighbours of every cell within its region (+-x, +-y, +-z), -1 where none."""
        out = np.full((self.num_cells, 6), -1, dtype=np.int64)
        steps = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
        for c in range(self.num_cells):
            r = int(self.region_of[c])
            for k, d in enumerate(steps):
                out[c, k] = self._or_minus_one(self.index(r, self.ijk[c] + d))
        return out

    @staticmethod
    def _or_minus_one(value):
        return -1 if value is None else value

    @staticmethod
    def _flat(size, ijk) -> int:
        return int(ijk[0] + ijk[1] * size[0] + ijk[2] * size[0] * size[1])

    def index(self, region: int, ijk) -> int | None:
        """Global index of region cell ijk, or None when it is outside the box."""
        t = self.regions[region]
        if not t.contains_index(ijk):
            return None
        return int(self.offsets[region]) + self._flat(t.size, ijk)

    def cell_at(self, point) -> int | None:
        """Global index of the cell whose centre is within tolerance of a world point."""
        found = self.cells_at(np.asarray(point, dtype=float).reshape(1, 3))
        return None if found is None else int(found[0])

    def cells_at(self, points: np.ndarray) -> np.ndarray | None:
        """Global indices for each point, or None if any point is off the grid."""
        out = self.lookup(points)
        return None if (out < 0).any() else out

    def lookup(self, points: np.ndarray) -> np.ndarray:
        """Global index of the cell at each point, -1 where it is off the grid."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        out = np.full(len(points), -1, dtype=np.int64)
        for r, t in enumerate(self.regions):
            idx = (points - np.asarray(t.origin)) / self.pitch
            rounded = np.round(idx)
            size = np.asarray(t.size)
            hit = (np.all(np.abs(idx - rounded) <= GRID_SNAP_TOL, axis=1)
                   & np.all((rounded >= 0) & (rounded < size), axis=1) & (out < 0))
            if hit.any():
                ijk = rounded[hit].astype(np.int64)
                out[hit] = self.offsets[r] + ijk[:, 0] + ijk[:, 1] * size[0] + ijk[:, 2] * size[0] * size[1]
        return out

    def region_cells(self, cell_ids) -> tuple[int, list[list[int]]]:
        """Region index and region-local [i, j, k] of cells that share one region."""
        cell_ids = list(cell_ids)
        r = int(self.region_of[cell_ids[0]])
        return r, [[int(v) for v in self.ijk[c]] for c in cell_ids]


def blocks_on_grid(scene: Scene, grid: Grid) -> dict[int, np.ndarray]:
    """Blocks that already sit on grid cells (placed earlier), by scene index.

    Scene validation guarantees a block is either fully on the grid or clear of it.
    """
    out = {}
    for b, block in enumerate(scene.blocks):
        cells = grid.cells_at(scene.unit_positions(block))
        if cells is not None:
            out[b] = cells
    return out

"""Candidate block poses in the target regions (the paper's p_{i,k} vectors)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rad_core.domain.blocks import BlockType
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Placement, Scene


@dataclass(frozen=True)
class Candidate:
    placement: Placement
    cell_ids: tuple[int, ...]   # global grid indices
    value: int                  # c^T p: +1 per target cell, -1 per non-target cell


def enumerate_candidates(scene: Scene, grid: Grid, positive_only: bool = True) -> list[Candidate]:
    """Every distinct pose of every block type that keeps all units in one region.

    Poses touching a cell that an already placed block occupies are left out.
    With positive_only, poses with c^T p <= 0 are dropped too: they can never
    raise the objective, so the optimum is unchanged and the model smaller.
    """
    occupied = np.zeros(grid.num_cells, dtype=bool)
    for cells in blocks_on_grid(scene, grid).values():
        occupied[cells] = True
    out = []
    for r, region in enumerate(scene.targets):
        size = np.asarray(region.size)
        for btype in scene.block_types.values():
            for yaw in btype.distinct_yaws():
                out.extend(_poses_in_region(btype, yaw, r, region.name, size, grid, occupied, positive_only))
    return out


def _poses_in_region(btype: BlockType, yaw: int, r: int, region_name: str, size: np.ndarray,
                     grid: Grid, occupied: np.ndarray, positive_only: bool):
    offs = btype.rotated(yaw)
    lo, hi = offs.min(axis=0), offs.max(axis=0)
    # Anchor positions that keep every unit inside [0, size).
    ranges = [range(-lo[a], size[a] - hi[a]) for a in range(3)]
    base = int(grid.offsets[r])
    strides = np.array([1, size[0], size[0] * size[1]])
    for ax in ranges[0]:
        for ay in ranges[1]:
            for az in ranges[2]:
                cells = offs + np.array([ax, ay, az])
                ids = base + cells @ strides
                if occupied[ids].any():
                    continue
                value = int(grid.weights[ids].sum())
                if positive_only and value <= 0:
                    continue
                placement = Placement(btype.name, region_name, yaw,
                                      tuple(tuple(int(v) for v in c) for c in cells))
                yield Candidate(placement, tuple(int(i) for i in ids), value)

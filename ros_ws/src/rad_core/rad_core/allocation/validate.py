"""A solver-independent check of an allocation, from the scene alone."""

from __future__ import annotations

from collections import Counter

import numpy as np

from rad_core.allocation.result import AllocationResult
from rad_core.domain.blocks import YAWS, canonical_shape
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Scene


def validate_allocation(scene: Scene, result: AllocationResult, tol: float = 1e-6) -> list[str]:
    """Every problem with the allocation, as messages; an empty list means valid.

    Checks: known types and regions, the cells are exactly the type's shape at the
    stated yaw, all in the region's box, no cell used twice (nor one a placed block
    holds), at most as many poses per type as blocks on the table, and that the
    objective c^T g recomputed from the cells matches the reported one.
    """
    problems = []
    grid = Grid(scene)
    used = np.zeros(grid.num_cells, dtype=bool)
    placed = blocks_on_grid(scene, grid)
    for cells in placed.values():
        used[cells] = True
    names = [t.name for t in scene.targets]
    objective = 0
    for n, p in enumerate(result.placements):
        tag = f'placement {n} ({p.type} in {p.target!r})'
        if p.type not in scene.block_types:
            problems.append(f'{tag}: unknown block type')
            continue
        if p.target not in names:
            problems.append(f'{tag}: unknown target region')
            continue
        if p.yaw not in YAWS:
            problems.append(f'{tag}: yaw {p.yaw} is not one of {YAWS}')
            continue
        cells = np.asarray(p.cells, dtype=np.int64).reshape(-1, 3)
        shape = scene.block_types[p.type].rotated(p.yaw)
        if len(cells) != len(shape) or canonical_shape(cells) != canonical_shape(shape):
            problems.append(f'{tag}: cells are not the block shape at yaw {p.yaw}')
            continue
        r = names.index(p.target)
        ids = [grid.index(r, c) for c in cells]
        if any(i is None for i in ids):
            problems.append(f'{tag}: a cell lies outside the region box')
            continue
        if used[ids].any():
            problems.append(f'{tag}: a cell is already occupied')
        used[ids] = True
        objective += int(grid.weights[ids].sum())
    on_table = Counter(b.type for i, b in enumerate(scene.blocks) if i not in placed)
    for name, count in Counter(p.type for p in result.placements).items():
        if count > on_table.get(name, 0):
            problems.append(f'type {name}: {count} poses but only {on_table.get(name, 0)} blocks available')
    if abs(objective - result.objective) > tol:
        problems.append(f'objective: reported {result.objective}, recomputed {objective}')
    if result.bound < result.objective - tol:
        problems.append(f'bound {result.bound} is below the objective {result.objective}')
    return problems

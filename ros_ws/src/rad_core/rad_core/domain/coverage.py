"""Target coverage, the paper's a-bar: the fraction of target cells filled. One place computes it,
whatever holds the filled cells (an MDP state, a registered scene, an allocation).

A target without cells counts as covered (1.0).
"""

from __future__ import annotations

import numpy as np

from rad_core.domain.grid import Grid, blocks_on_grid


def fraction_filled(filled: np.ndarray, is_target: np.ndarray) -> float:
    """Target cells that `filled` (a boolean per grid cell) covers, over all target cells."""
    total = int(np.count_nonzero(is_target))
    return float(np.count_nonzero(filled & is_target)) / total if total else 1.0


def state_coverage(env) -> float:
    """An MDP state's coverage (`mdp.AssemblyEnv`)."""
    return fraction_filled(env.state.occupancy >= 0, env.grid.is_target)


def measured_coverage(scene) -> float:
    """The coverage of a registered scene: target cells its blocks fill where they lie."""
    grid = Grid(scene)
    filled = np.zeros(grid.num_cells, dtype=bool)
    for cells in blocks_on_grid(scene, grid).values():
        filled[cells] = True
    return fraction_filled(filled, grid.is_target)


def optimum_coverage(env, guide) -> float:
    """The coverage the allocation's optimum reaches from the state: target cells already filled
    or covered by an allocated pose (`allocation.guide.AllocationGuide`)."""
    filled = env.state.occupancy >= 0
    for cells in guide.pose_cells:
        filled[cells] = True
    return fraction_filled(filled, env.grid.is_target)


def placements_coverage(scene, placements) -> float:
    """The coverage placements reach on an empty scene (the allocation's objective nets off
    non-target cells, so it can hide a target cell left empty behind one filled)."""
    targets = {(t.name, c) for t in scene.targets for c in t.filled}
    filled = {(p.target, tuple(c)) for p in placements for c in p.cells}
    return len(targets & filled) / len(targets) if targets else 1.0

"""The paper's allowed actions, inferred from an allocation (Sec. IV-B).

For every allocated pose and every unplaced block of its type, the actions
(block, unit, cell, rotation) that put the block exactly into that pose; all
units and all rotations that reproduce the pose (a symmetric block has several)
are offered. A pose whose cells are no longer all free (it was filled, or another
block took one of its cells) offers nothing: after a placement, the actions that
would fill the same pose are gone.

Blocks in a feeder (`rad_core.scene.Feeder`): a queue feeder offers only the blocks it
presents next; a request feeder presents every block of a type at the same pose, so
they are interchangeable and only the first of each type waiting is offered (the
others would repeat its actions; for 40 blocks in a feeder, ten times fewer).

The guide is built once per (scene, allocation) and is stateless: every query
takes the `AssemblyState` it is about, so one guide serves any number of env
clones, snapshots and search branches.
"""

from __future__ import annotations

import numpy as np

from rad_core.allocation.placements import Placement
from rad_core.blocks import canonical_shape
from rad_core.errors import RadError
from rad_core.grid import Grid
from rad_core.mdp import Action, AssemblyState, feeder_blocks
from rad_core.scene import Scene


class AllocationGuide:
    def __init__(self, scene: Scene, placements: tuple[Placement, ...] | list[Placement],
                 grid: Grid | None = None):
        self.scene = scene
        self.grid = grid if grid is not None else Grid(scene)
        self.placements = tuple(placements)
        names = [t.name for t in scene.targets]
        self.pose_cells: list[np.ndarray] = []
        # Per pose: list of (block index, [actions]).
        self._actions: list[list[tuple[int, list[Action]]]] = []
        for p in self.placements:
            if p.target not in names:
                raise RadError(f'allocation names unknown target region {p.target!r}')
            r = names.index(p.target)
            ids = [self.grid.index(r, c) for c in p.cells]
            if any(i is None for i in ids):
                raise RadError(f'allocated pose of {p.type} has a cell outside region {p.target!r}')
            self.pose_cells.append(np.asarray(ids, dtype=np.int64))
            per_block = []
            for b, block in enumerate(scene.blocks):
                if block.type == p.type:
                    per_block.append((b, self._actions_for(b, np.asarray(p.cells), r)))
            self._actions.append(per_block)

    def _actions_for(self, b: int, pose: np.ndarray, region: int) -> list[Action]:
        block = self.scene.blocks[b]
        btype, yaw0 = self.scene.block_types[block.type], block.yaw
        want = canonical_shape(pose)
        pose_sorted = sorted(map(tuple, pose))
        out = []
        for rot in range(4):
            offs = btype.rotated((yaw0 + 90 * rot) % 360)
            if canonical_shape(offs) != want:
                continue
            shift = np.asarray(pose_sorted[0]) - np.asarray(sorted(map(tuple, offs))[0])
            cells = offs + shift
            for u in range(btype.size):
                out.append(Action(b, u, self.grid.index(region, cells[u]), rot))
        return out

    def open_poses(self, state: AssemblyState) -> list[int]:
        """Indices of allocated poses whose cells are all still free in `state`."""
        occ = state.occupancy
        return [k for k, cells in enumerate(self.pose_cells) if np.all(occ[cells] < 0)]

    def _left_out(self, state: AssemblyState) -> set[int]:
        """Feeder blocks not offered in `state` (module docstring)."""
        if self.scene.feeder is None:
            return set()
        takeable, later = feeder_blocks(self.scene, state.placed)
        if self.scene.feeder.order == 'queue':
            return set(later)
        first = {}
        for b in takeable:
            first.setdefault(self.scene.blocks[b].type, b)
        return set(takeable) - set(first.values())

    def pose_actions(self, k: int, state: AssemblyState, left_out: set[int] | None = None) -> list[Action]:
        """The actions that fill pose k with a block still on the table (or offered by the feeder) in `state`."""
        skip = self._left_out(state) if left_out is None else left_out
        return [a for b, actions in self._actions[k] if b not in state.placed and b not in skip for a in actions]

    def allowed_actions(self, state: AssemblyState) -> list[Action]:
        """Allocation actions available in `state` (the termination action is not included).

        A block placed in an earlier step keeps its yaw; the actions are computed
        from the scene's initial yaws, so they are only offered for unplaced blocks.
        """
        skip = self._left_out(state)
        return [a for k in self.open_poses(state) for a in self.pose_actions(k, state, skip)]

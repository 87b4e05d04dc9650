"""The paper's allowed actions, inferred from an allocation (Sec. IV-B).

For every allocated pose and every unplaced block of its type, the actions
(block, unit, cell, rotation) that put the block exactly into that pose; all
units and all rotations that reproduce the pose (a symmetric block has several)
are offered. A pose whose cells are no longer all free (it was filled, or another
block took one of its cells) offers nothing: after a placement, the actions that
would fill the same pose are gone.

Blocks in a feeder (`rad_core.domain.scene.Feeder`): a queue feeder offers only the blocks it
presents next; a request feeder presents every block of a type at the same pose, so
they are interchangeable and only the first of each type waiting is offered (the
others would repeat its actions; for 40 blocks in a feeder, ten times fewer).

The guide is built once per (scene, allocation) and is stateless: every query
takes the `AssemblyState` it is about, so one guide serves any number of env
clones, snapshots and search branches.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from rad_core.allocation.placements import Placement
from rad_core.domain.blocks import BlockType, canonical_shape
from rad_core.domain.errors import RadError
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Scene
from rad_core.env.mdp import Action, AssemblyState, feeder_blocks


class AllocationGuide:
    def __init__(self, scene: Scene, placements: tuple[Placement, ...] | list[Placement],
                 grid: Grid | None = None):
        self.scene = scene
        self.grid = grid if grid is not None else Grid(scene)
        self.placements = tuple(placements)
        names = [t.name for t in scene.targets]
        self.pose_cells: list[np.ndarray] = []
        # Per pose: list of (block index, [(unit, cell, rotation)]); blocks of one type lying at
        # the same yaw share one list.
        self._fills: list[list[tuple[int, list[tuple[int, int, int]]]]] = []
        for p in self.placements:
            if p.target not in names:
                raise RadError(f'allocation names unknown target region {p.target!r}')
            r = names.index(p.target)
            ids = [self.grid.index(r, c) for c in p.cells]
            if any(i is None for i in ids):
                raise RadError(f'allocated pose of {p.type} has a cell outside region {p.target!r}')
            self.pose_cells.append(np.asarray(ids, dtype=np.int64))
            # Blocks of one type lying at the same yaw fill the pose with the same (unit, cell,
            # rotation) triples: worked out once per (type, yaw), in the blocks' order as before.
            pose = tuple(tuple(int(v) for v in c) for c in np.asarray(p.cells).tolist())
            same: dict[tuple[str, int], list[tuple[int, int, int]]] = {}
            per_block = []
            for b, block in enumerate(scene.blocks):
                if block.type == p.type:
                    key = (block.type, int(block.yaw) % 360)
                    if key not in same:
                        same[key] = [(u, self.grid.index(r, cell), rot) for rot, cells in _matching_rotations(
                            scene.block_types[block.type].offsets, key[1], pose) for u, cell in enumerate(cells)]
                    per_block.append((b, same[key]))
            self._fills.append(per_block)

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
        return [Action(b, u, cell, rot) for b, fills in self._fills[k] if b not in state.placed and b not in skip
                for u, cell, rot in fills]

    def allowed_actions(self, state: AssemblyState) -> list[Action]:
        """Allocation actions available in `state` (the termination action is not included).

        A block placed in an earlier step keeps its yaw; the actions are computed
        from the scene's initial yaws, so they are only offered for unplaced blocks.
        """
        skip = self._left_out(state)
        return [a for k in self.open_poses(state) for a in self.pose_actions(k, state, skip)]


@lru_cache(maxsize=65536)
def _matching_rotations(offsets: tuple, yaw0: int, pose: tuple) -> tuple:
    """The quarter turns (0..3, added to yaw0) that make a block with these unit offsets fill
    the pose's cells, each with the cell every unit lands on (in unit order). Pure geometry,
    asked again for every guide built on the same allocation, so it is remembered."""
    btype = BlockType('', offsets)
    want = canonical_shape(pose)
    first = np.asarray(min(pose))
    out = []
    for rot in range(4):
        offs = btype.rotated((yaw0 + 90 * rot) % 360)
        if canonical_shape(offs) != want:
            continue
        cells = offs + (first - np.asarray(min(map(tuple, offs.tolist()))))
        out.append((rot, tuple(tuple(int(v) for v in c) for c in cells.tolist())))
    return tuple(out)

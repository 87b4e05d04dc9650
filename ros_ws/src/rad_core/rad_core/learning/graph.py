"""A state as the paper's graph (Sec. IV-B, Fig. 3), and batches of them.

One node per primitive unit (unplaced: where it lies on the table; placed: the
cell it fills) and per grid cell still free (target or non-target). Node
features are the 3D position and the two type indices; edges (the attention
mask) connect every pair of nodes except unplaced units of different blocks, and
every node attends to itself. The candidate actions are (unit node, cell node,
rotation) triples: "move the block of this unit so the unit lands on this cell,
turned by rotation x 90 degrees"; the termination action is always a candidate
on top and is not listed.

Positions are in cube units, x and y relative to the centre of the grid cells,
z above the table top, then divided by `POSITION_SCALE`: nothing depends on the
cube size or where the structure stands, and a bigger problem only adds nodes.

Observations are numpy-only (the environment side never imports torch); the
network turns a list of them into padded tensors with `collate`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rad_core.env.mdp import Action, AssemblyEnv

UNPLACED, PLACED, TARGET, NON_TARGET = 0, 1, 2, 3
NODE_KINDS = ('unplaced unit', 'placed unit', 'target cell', 'non-target cell')
POSITION_SCALE = 10.0
FEATURES = 5


class GraphObs(NamedTuple):
    """One state. N nodes, A candidate actions (termination not included)."""

    pos: np.ndarray      # [N, 3] float32, scaled positions
    kind: np.ndarray     # [N] int8, UNPLACED / PLACED / TARGET / NON_TARGET
    group: np.ndarray    # [N] int32, scene block index for unit nodes, -1 for cells
    pairs: np.ndarray    # [A, 2] int32, (unit node, cell node) of each candidate action
    rot: np.ndarray      # [A] int8, rotation of each candidate action

    @property
    def num_nodes(self) -> int:
        return len(self.kind)

    @property
    def num_actions(self) -> int:
        return len(self.rot)

    def action_mask(self) -> np.ndarray:
        """The candidates as a validity mask over the paper's whole action space:
        [unplaced units, free cells, 4] bool (units and cells in node order); the
        termination action, always valid, is not in it. The network never needs
        this (it scores only the candidate pairs); it is for inspection and for
        code that wants the dense form."""
        units = np.flatnonzero(self.kind == UNPLACED)
        cells = np.flatnonzero(self.kind >= TARGET)
        mask = np.zeros((len(units), len(cells), 4), dtype=bool)
        mask[np.searchsorted(units, self.pairs[:, 0]), np.searchsorted(cells, self.pairs[:, 1]), self.rot] = True
        return mask


def node_features(pos: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """[N, 5]: position, then the two type indices: +1 for grid cells / -1 for units,
    +1 for target cells and placed units (what the structure should be / is) / -1 else."""
    is_cell = np.where(kind >= TARGET, 1.0, -1.0)
    filled = np.where((kind == TARGET) | (kind == PLACED), 1.0, -1.0)
    return np.concatenate([pos, is_cell[:, None], filled[:, None]], axis=1).astype(np.float32)


def attention_allowed(kind: np.ndarray, group: np.ndarray) -> np.ndarray:
    """[N, N] bool, True where node i may attend to node j."""
    unplaced = kind == UNPLACED
    other_block = group[:, None] != group[None, :]
    return ~(unplaced[:, None] & unplaced[None, :] & other_block)


class Observer:
    """Turns the states of one env (and its clones) into GraphObs.

    The static parts (unit positions on the table, cell centres, the scaling) are
    computed once per scene.
    """

    def __init__(self, env: AssemblyEnv):
        scene, grid = env.scene, env.grid
        self.grid = grid
        u = scene.unit
        ref = np.array([*grid.centres[:, :2].mean(axis=0), 0.0])
        self._scale = lambda p: ((np.asarray(p, dtype=float) - ref) / (u * POSITION_SCALE)).astype(np.float32)
        self.cell_pos = self._scale(grid.centres)
        self.table_pos = [self._scale(scene.unit_positions(b)) for b in scene.blocks]
        self.sizes = np.array([len(p) for p in self.table_pos])

    def __call__(self, env: AssemblyEnv, actions: list[Action]) -> GraphObs:
        state = env.state
        occ = state.occupancy
        unplaced = [b for b in range(len(self.sizes)) if b not in state.placed]
        placed = sorted(state.placed)
        free = np.flatnonzero(occ < 0)
        parts_pos, parts_kind, parts_group = [], [], []
        unit_node = {}
        n = 0
        for b in unplaced:
            parts_pos.append(self.table_pos[b])
            k = self.sizes[b]
            parts_kind.append(np.full(k, UNPLACED, np.int8))
            parts_group.append(np.full(k, b, np.int32))
            unit_node[b] = n
            n += k
        for b in placed:
            cells = state.placed[b][0]
            parts_pos.append(self.cell_pos[cells])
            parts_kind.append(np.full(len(cells), PLACED, np.int8))
            parts_group.append(np.full(len(cells), b, np.int32))
            n += len(cells)
        cell_node = np.full(self.grid.num_cells, -1, dtype=np.int64)
        cell_node[free] = n + np.arange(len(free))
        parts_pos.append(self.cell_pos[free])
        parts_kind.append(np.where(self.grid.is_target[free], TARGET, NON_TARGET).astype(np.int8))
        parts_group.append(np.full(len(free), -1, np.int32))
        pos = np.concatenate(parts_pos).astype(np.float32)
        kind = np.concatenate(parts_kind)
        group = np.concatenate(parts_group)
        pairs = np.empty((len(actions), 2), dtype=np.int32)
        rot = np.empty(len(actions), dtype=np.int8)
        for i, a in enumerate(actions):
            c = cell_node[a.cell]
            if a.block not in unit_node or c < 0:
                raise ValueError(f'action {a} is not a placement of an unplaced unit at a free cell')
            pairs[i] = (unit_node[a.block] + a.unit, c)
            rot[i] = a.rotation
        return GraphObs(pos, kind, group, pairs, rot)

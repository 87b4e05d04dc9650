"""Which actions a sequencer may choose among: the three action spaces of Table I.

- `AllocationActions` (MILP-DQN, HEUR): only actions that put a block exactly
  into a pose of the allocation (the paper's guided exploration).
- `all_actions` (the DQN baseline): any unplaced unit at any free cell with any
  of the four rotations, N_U x N_free x 4. Most of them put some other unit off
  the grid or into a placed block: such actions are invalid (-1), as in the paper.
- `relative_actions` (DQN-REL, the predecessor's action space): only free cells
  face-adjacent to a placed unit; while nothing is placed, any target cell.

Each is a function of the env's current state only (termination is always
allowed on top and is not listed), so the same object serves every env clone.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from rad_core.allocation.guide import AllocationGuide
from rad_core.allocation.placements import Placement
from rad_core.env.mdp import Action, AssemblyEnv
from rad_core.gamp.action import SceneAction

METHODS = ('milp', 'all', 'rel')


class ActionSpace(Protocol):
    def __call__(self, env: AssemblyEnv) -> list[Action]: ...


class AllocationActions:
    """The allocation's actions for the env's current state."""

    def __init__(self, env: AssemblyEnv, placements: tuple[Placement, ...] | list[Placement]):
        self.guide = AllocationGuide(env.scene, placements, env.grid)

    def __call__(self, env: AssemblyEnv) -> list[Action]:
        return self.guide.allowed_actions(env.state)


def _unit_actions(env: AssemblyEnv, cells: np.ndarray) -> list[Action]:
    return [Action(b, u, int(c), r) for b, u in env.unplaced_units() for c in cells for r in range(4)]


def all_actions(env: AssemblyEnv) -> list[Action]:
    return _unit_actions(env, env.free_cells())


def relative_actions(env: AssemblyEnv) -> list[Action]:
    occ = env.state.occupancy
    free = occ < 0
    if not (~free).any():
        cells = np.flatnonzero(free & env.grid.is_target)
    else:
        nb = env.grid.face_neighbours
        next_to_placed = ((nb >= 0) & ~free[np.maximum(nb, 0)]).any(axis=1)
        cells = np.flatnonzero(free & next_to_placed)
    return _unit_actions(env, cells)


def action_space(method: str, env: AssemblyEnv, placements=None) -> ActionSpace:
    """The action space of a method: 'milp' (needs the allocation's placements), 'all', 'rel'."""
    if method == 'milp':
        if placements is None:
            raise ValueError("the 'milp' action space needs the allocation's placements")
        return AllocationActions(env, placements)
    if method == 'all':
        return all_actions
    if method == 'rel':
        return relative_actions
    raise ValueError(f'unknown action space {method!r}; one of {", ".join(METHODS)}')


def scene_action(env: AssemblyEnv, action: Action) -> SceneAction:
    """An MDP action named the way messages name it (block id, target, region cell)."""
    region = int(env.grid.region_of[action.cell])
    cell = tuple(int(v) for v in env.grid.ijk[action.cell])
    return SceneAction(env.scene.blocks[action.block].id, int(action.unit), env.scene.targets[region].name, cell,
                       int(action.rotation))


def mdp_actions(env: AssemblyEnv, ranked: list[SceneAction], allowed=None) -> list:
    """The MDP actions of ranked scene actions, in order, keeping only those in `allowed` (None:
    every one that names a block, region and cell of the env)."""
    index = {b.id: n for n, b in enumerate(env.scene.blocks)}
    regions = {t.name: n for n, t in enumerate(env.scene.targets)}
    allowed, out = None if allowed is None else set(allowed), []
    for a in ranked:
        if a.block_id not in index or a.target not in regions:
            continue
        cell = env.grid.index(regions[a.target], a.cell)
        action = Action(index[a.block_id], int(a.unit), -1 if cell is None else cell, int(a.rotation))
        if (cell is not None) if allowed is None else (action in allowed):
            out.append(action)
    return out

"""GAMP for an MDP action given in scene terms, from a scene state.

The one place that turns (block id, unit, target region, cell, rotation, start
joints) into a motion plan: the gamp node serves it over ROS, and the in-process
assembly planner calls it directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rad_core.errors import RadError
from rad_core.gamp.planner import GampConfig, GampResult, placement_pose, plan_action
from rad_core.scene import Scene
from rad_core.sim import panda
from rad_core.sim.world import World


@dataclass(frozen=True)
class SceneAction:
    """An MDP action named the way messages name it."""

    block_id: str
    unit: int
    target: str
    cell: tuple[int, int, int]
    rotation: int


def start_joints(positions) -> np.ndarray | None:
    """Start positions as 9 joints (7 arm values get open fingers), None for home."""
    positions = [float(v) for v in positions]
    if not positions:
        return None
    if len(positions) == 7:
        positions += [panda.FINGER_OPEN, panda.FINGER_OPEN]
    if len(positions) != 9:
        raise RadError(f'start_positions needs 0, 7 or 9 joint values ({", ".join(panda.JOINT_NAMES)}), '
                       f'got {len(positions)}')
    if not all(math.isfinite(v) for v in positions):
        raise RadError('start_positions must be finite')
    if not panda.within_limits(positions, tol=1e-3):
        raise RadError('start_positions are outside the joint limits')
    return np.asarray(positions)


def target_pose(scene: Scene, action: SceneAction) -> tuple[np.ndarray, int]:
    """Anchor position and yaw the action puts the block at; RadError if malformed."""
    names = [t.name for t in scene.targets]
    if action.target not in names:
        raise RadError(f'unknown target region {action.target!r}')
    region = scene.target(action.target)
    if not region.contains_index(action.cell):
        raise RadError(f'cell {list(action.cell)} is outside target region {region.name!r} '
                       f'of size {list(region.size)}')
    if action.rotation not in (0, 1, 2, 3):
        raise RadError(f'rotation {action.rotation} is not one of 0, 1, 2, 3')
    scene.block(action.block_id)
    return placement_pose(scene, action.block_id, action.unit, region.cell_center(action.cell, scene.unit),
                          action.rotation)


class MotionPlanner:
    """GAMP over a planning world of its own; each call loads the given scene state."""

    def __init__(self, config: GampConfig = GampConfig()):
        self.config = config
        self.world = World()

    def close(self) -> None:
        self.world.close()

    def __call__(self, scene: Scene, action: SceneAction, start=None) -> tuple[GampResult, np.ndarray, int]:
        position, yaw = target_pose(scene, action)
        start = start_joints([] if start is None else start)
        self.world.load_scene(scene)
        return plan_action(self.world, action.block_id, position, yaw, start=start, config=self.config), position, yaw

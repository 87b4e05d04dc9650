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


def seat_shift(scene: Scene, block_id: str, position, yaw: int, limit: float = 0.25) -> np.ndarray:
    """How far (m, x/y) to move a block from its cell's pose so that it clears the neighbours motion
    capture saw off their cells (`Scene.measured_offsets`), as little as that takes.

    A real placement leaves a block a few millimetres off; snapped to its cell, it still counts as
    built, but a neighbour lowered flush beside it at the exact cell would land on its edge. Each side
    neighbour (same layer, one cell over in x or y) bounds the shift along that axis: no further
    towards it than its own offset. Within the bounds the smallest shift is taken (0 when nothing
    intrudes), so offsets do not pile up along a row; squeezed from both sides, the middle (the
    collision checks then say whether the play absorbs it). A corner neighbour that still overlaps is
    cleared along the axis that costs less. At most `limit` unit in each axis."""
    u = scene.unit
    block = scene.block(block_id)
    ours = np.asarray(position, dtype=float) + u * scene.block_types[block.type].rotated(yaw)
    lo, hi = np.full(2, -np.inf), np.full(2, np.inf)
    corners = []
    for other in scene.blocks:
        if other.id == block_id:
            continue
        theirs = scene.unit_positions(other)
        d = (theirs[None, :, :] - ours[:, None, :]) / u           # (our units, their units, 3)
        near = (np.abs(d[..., 2]) < 0.5) & (np.abs(d[..., :2]).max(axis=-1) < 1.25)
        if not near.any():
            continue
        o = scene.offset(other.id)[:2]
        for dx, dy in d[near][:, :2]:
            sx = int(round(dx))
            sy = int(round(dy))
            if sx and sy:
                corners.append((sx, sy, o))
            elif sx or sy:
                a, side = (0, sx) if sx else (1, sy)
                if side > 0:
                    hi[a] = min(hi[a], o[a])
                else:
                    lo[a] = max(lo[a], o[a])
    shift = np.array([min(max(0.0, lo[a]), hi[a]) if lo[a] <= hi[a] else (lo[a] + hi[a]) / 2 for a in range(2)])
    for sx, sy, o in corners:
        side = np.array([sx, sy])
        if np.all(side * (shift - o) > 1e-9):       # into their corner along both axes
            cost = np.abs(o - shift)
            for a in np.argsort(cost):
                if lo[a] <= o[a] <= hi[a]:
                    shift[a] = o[a]
                    break
    shift = np.clip(shift, -limit * u, limit * u)
    return np.array([round(float(shift[0]), 6), round(float(shift[1]), 6), 0.0])


def drop_obstacles_on_the_hand(world: World, q: np.ndarray) -> list[str]:
    """Remove from the planning world the obstacles (set-aside blocks) the robot touches at q: a block
    wedged on the fingers or leaning on the arm moves with them and falls when they move away, so
    it is no obstacle to leaving; the next registration shows where it went. Returns their ids."""
    p, cid = world.pybullet, world.client
    world.set_joint_positions(q)
    gone = [oid for oid, body in world.obstacles.items()
            if p.getClosestPoints(world.robot, body, 0.002, physicsClientId=cid)]
    for oid in gone:
        p.removeBody(world.obstacles.pop(oid), physicsClientId=cid)
    return gone


class MotionPlanner:
    """GAMP over a planning world of its own; each call loads the given scene state. A block goes to
    its cell's pose, moved by `seat_shift` clear of neighbours seen off their cells."""

    def __init__(self, config: GampConfig = GampConfig()):
        self.config = config
        self.world = World()

    def close(self) -> None:
        self.world.close()

    def load(self, scene: Scene, start=None) -> np.ndarray | None:
        """Load the scene state into the planning world for a motion from `start` (joint values, empty
        or None: home); returns the start as 9 joints (None: home). Obstacles the robot touches there
        are left out (`drop_obstacles_on_the_hand`)."""
        start = start_joints([] if start is None else start)
        self.world.load_scene(scene)
        if scene.obstacles:
            drop_obstacles_on_the_hand(self.world, panda.HOME if start is None else start)
        return start

    def __call__(self, scene: Scene, action: SceneAction, start=None) -> tuple[GampResult, np.ndarray, int]:
        position, yaw = target_pose(scene, action)
        start = self.load(scene, start)
        seat = position + seat_shift(scene, action.block_id, position, yaw) if scene.measured_offsets else position
        return plan_action(self.world, action.block_id, seat, yaw, start=start, config=self.config), position, yaw

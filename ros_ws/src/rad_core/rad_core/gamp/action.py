"""GAMP for an MDP action given in scene terms, from a scene state.

The one place that turns (block id, unit, target region, cell, rotation, start
joints) into a motion plan: the gamp node serves it over ROS, and the in-process
assembly planner calls it directly.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from rad_core.cell import panda
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.shapes import LayoutConfig, footprint, move_aside_spot
from rad_core.domain.transforms import yaw_quaternion
from rad_core.gamp.planner import GampConfig, GampResult, placement_pose, plan_action
from rad_core.sim.world import World, WorldConfig


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
    return placement_pose(scene, action.block_id, action.unit, region.cell_center(action.cell, scene.pitch),
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
    u = scene.pitch
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
    shift = np.clip(shift, -limit * scene.unit, limit * scene.unit)
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

    def __init__(self, config: GampConfig | None = None):
        config = GampConfig() if config is None else config
        config.validate()
        self.config = config
        self.world = World(config=WorldConfig(effector=config.effector))

    def close(self) -> None:
        self.world.close()

    def load(self, scene: Scene, start=None) -> np.ndarray | None:
        """Load the scene state into the planning world for a motion from `start` (joint values, empty
        or None: home); returns the start as 9 joints (None: home). Obstacles the robot touches there
        are left out (`drop_obstacles_on_the_hand`)."""
        start = start_joints([] if start is None else start)
        if not self.world.repose(scene):      # the next state of the scene loaded before: its bodies kept
            self.world.load_scene(scene)
        if scene.obstacles:
            drop_obstacles_on_the_hand(self.world, panda.HOME if start is None else start)
        return start

    def __call__(self, scene: Scene, action: SceneAction, start=None, move_aside: bool = False,
                 set_down: bool = False) -> tuple[GampResult, np.ndarray, int]:
        """GAMP's answer, the anchor position and yaw of the action. move_aside: when the block's
        grasps are blocked by neighbours on the table, move them aside first (`_move_aside_first`;
        at most `config.move_aside` of them); false: one pick and place. set_down: never a drop
        (`GampConfig.drop`), for a plan that takes none."""
        position, yaw = target_pose(scene, action)
        start = self.load(scene, start)
        seat = position + seat_shift(scene, action.block_id, position, yaw) if scene.measured_offsets else position
        config = replace(self.config, drop=False) if set_down and self.config.drop else self.config
        result = plan_action(self.world, action.block_id, seat, yaw, start=start, config=config)
        if move_aside and result.failure == 'grasp' and config.move_aside > 0:
            result = self._move_aside_first(scene, action.block_id, seat, yaw, start, result, config.move_aside, config)
        return result, position, yaw

    def _move_aside_first(self, scene: Scene, block_id: str, seat, yaw: int, start, blocked: GampResult,
                         moves: int, config: GampConfig) -> GampResult:
        """The block's pick is blocked: move a neighbour on the table that its grasps hit (as
        `blocked.reason` names them, nearest first, at most `MOVE_ASIDE_TRIES`) to a free place
        first, then plan the block's pick and place from there; where another neighbour still
        blocks it, move that one too (at most `moves` in all). `blocked`, its reason saying what
        was tried, when no way works."""
        tried = []
        named = blocks_named(blocked.reason)
        blockers = [b for b in table_neighbours(scene, block_id) if b in named]
        for other in blockers[:MOVE_ASIDE_TRIES]:
            spot = (move_aside_spot(scene, other, clear_of=[block_id])
                    or move_aside_spot(scene, other, MOVE_ASIDE_LAYOUT, clear_of=[block_id]))
            if spot is None:
                tried.append(f'{other}: no free place on the table')
                continue
            spot_position, spot_yaw = spot
            first = plan_action(self.world, other, spot_position, spot_yaw, start=start, config=config)
            if not first.success:
                tried.append(f'{other}: {first.reason}')
                continue
            pose = self.world.block_pose(other)
            self.world.set_block_pose(other, spot_position, yaw_quaternion(spot_yaw))
            try:
                then = plan_action(self.world, block_id, seat, yaw, start=first.motion.final_joints(),
                                   config=config)
                if then.failure == 'grasp' and moves > 1:
                    aside = replace(scene, blocks=tuple(
                        replace(b, position=tuple(spot_position), yaw=spot_yaw) if b.id == other else b
                        for b in scene.blocks))
                    then = self._move_aside_first(aside, block_id, seat, yaw, first.motion.final_joints(), then,
                                                 moves - 1, config)
            finally:
                self.world.set_block_pose(other, *pose)
            if not then.success:
                tried.append(f'{other} moved aside: {then.reason}')
                continue
            then.motion = first.motion.then(then.motion)
            then.moved_aside = [{'block': other, 'position': list(spot_position), 'yaw': spot_yaw}, *then.moved_aside]
            then.ik_calls += first.ik_calls + blocked.ik_calls
            then.timings = {k: then.timings[k] + first.timings[k] + blocked.timings[k] for k in then.timings}
            return then
        if tried:
            blocked.reason += '; moving a neighbour aside first: ' + '; '.join(tried)
        return blocked


_NAMED_BLOCK = re.compile(r'hits block (\S+?)(?=[;:,)]|\s|$)')


def blocks_named(reason: str) -> set[str]:
    """The ids of the blocks a GAMP reason says something hits ('hand hits block b4', 'carried block
    hits block b5; ...')."""
    return set(_NAMED_BLOCK.findall(reason or ''))


MOVE_ASIDE_TRIES = 3
"""Neighbours in a block's way that `MotionPlanner` tries to move aside, nearest first, at each move."""
MOVE_ASIDE_LAYOUT = LayoutConfig(reach=(0.3, 0.7), max_bearing_deg=100.0)
"""Where a block moved aside may go when the layout's own area (`shapes.LayoutConfig`) has no
free place: wider (a table the layout filled has room left beside the robot and farther out;
GAMP says whether the arm gets there)."""


def table_neighbours(scene: Scene, block_id: str, reach: float = 0.08) -> list[str]:
    """Blocks on the table (not in a target region) within `reach` (m, between unit faces) of the
    block, nearest first: the ones whose moving away could free its grasps."""
    unit, types = scene.unit, scene.block_types
    ours = footprint(scene.block(block_id), types, unit)
    boxes = [t.bounds(scene.pitch) for t in scene.targets]
    found = []
    for other in scene.blocks:
        if other.id == block_id or scene.in_feeder(other.id):
            continue
        if any(np.all((np.asarray(other.position) > lo) & (np.asarray(other.position) < hi)) for lo, hi in boxes):
            continue
        theirs = footprint(other, types, unit)
        gap = float(np.abs(ours[:, None, :] - theirs[None, :, :]).max(axis=-1).min()) - unit
        if gap < reach:
            found.append((gap, other.id))
    return [bid for _, bid in sorted(found)]

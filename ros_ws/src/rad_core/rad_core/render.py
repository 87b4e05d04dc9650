"""Snapshots of a scene with PyBullet's headless TinyRenderer: no display, no GPU.

What is drawn, in the scene's world frame (table top at z = 0):

- the table, a flat slab under everything;
- every block as unit cubes in its type's colour (`rad_core.colours`), at its scene
  pose, or at its grid cells when `occupancy` (an MDP state's per-cell block
  index, -1 for free) says it has been placed; with the scene's ``clearance``
  the block's outer side faces are set back by half of it (`rad_core.scene`);
- every target region cell: a small pink cube on target cells, a smaller green
  one on the region's other cells;
- optionally an allocation's placements as shrunk cubes in a paler shade of
  the type colour at their region cells, so a plan can be compared with the
  targets and with what is built.

Each call uses its own DIRECT client and disconnects it, so rendering never
touches a physics client. A 640x480 frame of a small scene takes about 50 ms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np

from rad_core.blocks import unit_boxes
from rad_core.colours import GREEN, PINK, TABLE, type_colour
from rad_core.errors import RadError
from rad_core.grid import Grid
from rad_core.png import write_png
from rad_core.scene import Scene

# Edge of each kind of cube, as a fraction of the unit. Placed blocks leave a hair
# of a gap so single cubes stay visible; the markers hide inside anything on them.
BLOCK_SIZE = 0.94
PLAN_SIZE = 0.75
TARGET_SIZE = 0.45
OTHER_CELL_SIZE = 0.2


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking at `target` from `distance` metres.

    azimuth_deg is the direction from the target to the eye, about +z from +x;
    elevation_deg how far above the table plane the eye is seen from the target.
    """

    target: tuple[float, float, float]
    distance: float
    azimuth_deg: float = 135.0
    elevation_deg: float = 40.0
    fov_deg: float = 40.0

    @property
    def eye(self) -> np.ndarray:
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        return np.asarray(self.target, dtype=float) + self.distance * direction


def fit_camera(lo, hi, aspect: float, azimuth_deg: float = 135.0, elevation_deg: float = 40.0,
               fov_deg: float = 40.0) -> Camera:
    """The closest camera, from the given direction, that sees all of the box [lo, hi].

    The default direction is front-left-above as the robot sees the table (it
    stands at the origin facing +x): diagonal, so rows of cubes along x or y
    do not hide one another, and high enough to see into target regions.
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    centre = (lo + hi) / 2
    back = Camera((0.0, 0.0, 0.0), 1.0, azimuth_deg, elevation_deg, fov_deg).eye   # unit vector to the eye
    right = np.cross([0.0, 0.0, 1.0], back)
    right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.array([0.0, 1.0, 0.0])
    up = np.cross(back, right)
    tan_v = math.tan(math.radians(fov_deg) / 2)
    tan_h = tan_v * aspect
    distance = 1e-3
    for corner in np.array(np.meshgrid(*zip(lo, hi))).reshape(3, -1).T - centre:
        toward = corner @ back        # how much nearer the eye this corner is than the centre
        distance = max(distance, toward + abs(corner @ right) / tan_h, toward + abs(corner @ up) / tan_v)
    return Camera(tuple(float(v) for v in centre), 1.08 * distance, azimuth_deg, elevation_deg, fov_deg)


def render_scene(scene: Scene, allocation=None, occupancy=None, width: int = 640, height: int = 480,
                 camera: Camera | None = None, robot=None) -> np.ndarray:
    """An (height, width, 3) uint8 picture of the scene; see the module docstring.

    allocation: an AllocationResult or an iterable of Placements (type, target,
    yaw, cells). occupancy: one entry per grid cell (`Grid` order), -1 for free,
    else the scene index of the block there. robot: the Panda's 9 joint positions
    (panda.JOINT_NAMES order) to draw it with its meshes at the origin, or None.
    """
    if not (isinstance(width, int) and isinstance(height, int) and 0 < width <= 4096 and 0 < height <= 4096):
        raise RadError(f'image size must be 1..4096 pixels a side, got {width!r} x {height!r}')
    boxes = _scene_boxes(scene, _placements(allocation), occupancy)
    corners = np.concatenate([[c - h, c + h] for c, h, _ in boxes])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    lo[2] = min(lo[2], 0.0)
    if robot is not None:
        # Roughly where the arm is: its base at the origin, up to shoulder height.
        lo, hi = np.minimum(lo, ROBOT_BOX[0]), np.maximum(hi, ROBOT_BOX[1])
    if camera is None:
        camera = fit_camera(lo, hi, width / height)
    return _draw(boxes, lo, hi, scene.unit, camera, width, height, robot)


def save_scene_png(scene: Scene, path: str | Path, **kw) -> Path:
    """Render the scene (keywords as for `render_scene`) and write it as a PNG."""
    return write_png(path, render_scene(scene, **kw))


# ---- what to draw -------------------------------------------------------

ROBOT_BOX = (np.array([-0.25, -0.25, 0.0]), np.array([0.45, 0.25, 0.9]))


def _add_robot(p, cid: int, joints) -> None:
    from rad_core.sim import panda
    joints = np.asarray(joints, dtype=float)
    if joints.shape != (len(panda.JOINT_NAMES),) or not np.all(np.isfinite(joints)):
        raise RadError(f'robot joints: expected {len(panda.JOINT_NAMES)} finite values')
    body = panda.load_panda(cid)
    index = {p.getJointInfo(body, j, physicsClientId=cid)[1].decode(): j
             for j in range(p.getNumJoints(body, physicsClientId=cid))}
    for name, value in zip(panda.JOINT_NAMES, joints):
        p.resetJointState(body, index[name], float(value), physicsClientId=cid)


def _placements(allocation) -> list:
    if allocation is None:
        return []
    placements = getattr(allocation, 'placements', allocation)
    if not isinstance(placements, Iterable):
        raise RadError('allocation must be an AllocationResult or a list of placements')
    return list(placements)


def block_cubes(centres: np.ndarray, unit: float, clearance: float) -> tuple[np.ndarray, np.ndarray]:
    """(box centres (n, 3), half extents (n, 3)) drawn for one block's unit cubes at these
    world centres: cubes of edge BLOCK_SIZE, their outer side faces set back by
    half the clearance (a fraction of the unit)."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    offsets = np.round((centres - centres[0]) / unit).astype(np.int64)
    half = unit * BLOCK_SIZE / 2
    shift, halves = unit_boxes(offsets, half, half, clearance * unit / 2)
    return centres + shift, halves


def _scene_boxes(scene: Scene, placements: list, occupancy) -> list[tuple[np.ndarray, float | tuple, tuple]]:
    """(centre, half edge or half extents (x, y, z), rgb) of every box to draw."""
    u = scene.unit
    boxes = []
    on_grid: dict[int, np.ndarray] = {}
    if occupancy is not None:
        grid = Grid(scene)
        occ = np.asarray(occupancy).reshape(-1)
        if len(occ) != grid.num_cells:
            raise RadError(f'occupancy has {len(occ)} entries, the scene has {grid.num_cells} grid cells')
        if occ.size and (occ.max() >= len(scene.blocks) or occ.min() < -1):
            raise RadError(f'occupancy names a block outside 0..{len(scene.blocks) - 1}')
        for b in np.unique(occ[occ >= 0]):
            on_grid[int(b)] = grid.centres[occ == b]
    for b, block in enumerate(scene.blocks):
        centres = on_grid.get(b)
        if centres is None:
            centres = scene.unit_positions(block)
        colour = type_colour(block.type)
        if scene.clearance:
            boxes.extend((c, tuple(h.tolist()), colour) for c, h in zip(*block_cubes(centres, u, scene.clearance)))
        else:
            boxes.extend((c, u * BLOCK_SIZE / 2, colour) for c in centres)
    for p in placements:
        region = scene.target(p.target)
        colour = tuple(0.65 * v + 0.35 for v in type_colour(p.type))   # paler: planned, not built
        boxes.extend((region.cell_center(c, u), u * PLAN_SIZE / 2, colour) for c in p.cells)
    for region in scene.targets:
        filled = set(region.filled)
        for ijk in np.ndindex(*region.size):
            size, colour = (TARGET_SIZE, PINK) if ijk in filled else (OTHER_CELL_SIZE, GREEN)
            boxes.append((region.cell_center(ijk, u), u * size / 2, colour))
    return boxes


def _draw(boxes, lo, hi, unit: float, camera: Camera, width: int, height: int, robot=None) -> np.ndarray:
    import pybullet as p      # here, not at the top: importing it prints a banner on stdout
    cid = p.connect(p.DIRECT)
    if cid < 0:
        raise RuntimeError('cannot start a PyBullet DIRECT client')
    try:
        if robot is not None:
            _add_robot(p, cid, robot)
        groups: dict[tuple, list] = {}
        for centre, half, colour in boxes:
            groups.setdefault((half, colour), []).append([float(v) for v in centre])
        for (half, colour), centres in groups.items():
            extents = list(half) if isinstance(half, tuple) else [half] * 3
            shape = p.createVisualShape(p.GEOM_BOX, halfExtents=extents, rgbaColor=[*colour, 1.0],
                                        physicsClientId=cid)
            p.createMultiBody(baseMass=0, baseVisualShapeIndex=shape, batchPositions=centres, physicsClientId=cid)
        # The table: a slab whose top is z = 0, a unit wider than everything on it.
        margin = 2 * unit
        half = [(hi[0] - lo[0]) / 2 + margin, (hi[1] - lo[1]) / 2 + margin, unit / 4]
        slab = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[*TABLE, 1.0], physicsClientId=cid)
        p.createMultiBody(baseMass=0, baseVisualShapeIndex=slab,
                          basePosition=[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, -unit / 4], physicsClientId=cid)

        eye = camera.eye
        view = p.computeViewMatrix(eye.tolist(), list(camera.target), [0, 0, 1], physicsClientId=cid)
        reach = float(np.linalg.norm(np.asarray(hi) - lo)) + margin
        near = max(1e-3, camera.distance - reach)
        proj = p.computeProjectionMatrixFOV(camera.fov_deg, width / height, near, camera.distance + reach,
                                            physicsClientId=cid)
        light = (eye - np.asarray(camera.target)) + np.array([0.0, 0.0, camera.distance])
        _, _, rgba, _, _ = p.getCameraImage(
            width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=1,
            lightDirection=light.tolist(), lightAmbientCoeff=0.6, lightDiffuseCoeff=0.4,
            lightSpecularCoeff=0.0, physicsClientId=cid)
    finally:
        p.disconnect(physicsClientId=cid)
    return np.ascontiguousarray(np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3])

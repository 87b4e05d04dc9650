"""Snapshots of a scene with PyBullet's headless TinyRenderer: no display, no GPU.

Two kinds of picture. `render_scene` shows the whole table (and, if asked, the robot);
`render_build` shows a structure close up from two sides against its target cells, and
`save_build_pictures` writes the before, after and step-by-step pictures of a build that
`rad demo` leaves (see their docstrings; the rest of this one is about `render_scene`).

What `render_scene` draws, in the scene's world frame (table top at z = 0):

- the table, a flat slab under everything;
- every block as unit cubes in its type's colour (`rad_core.domain.colours`), at its scene
  pose, or at its grid cells when `occupancy` (an MDP state's per-cell block
  index, -1 for free) says it has been placed; with the scene's ``clearance``
  the block's outer side faces are set back by half of it (`rad_core.domain.scene`);
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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable

import numpy as np

from rad_core.cell import panda
from rad_core.domain.blocks import unit_boxes
from rad_core.domain.colours import GREEN, PINK, TABLE, type_colour
from rad_core.domain.errors import RadError
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Block, Scene
from rad_core.view.png import write_apng, write_png

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
               fov_deg: float = 40.0, margin: float = 1.08) -> Camera:
    """The closest camera, from the given direction, that sees all of the box [lo, hi]
    (`frame_points` of its eight corners).

    The default direction is front-left-above as the robot sees the table (it
    stands at the origin facing +x): diagonal, so rows of cubes along x or y
    do not hide one another, and high enough to see into target regions.
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    corners = np.array(np.meshgrid(*zip(lo, hi))).reshape(3, -1).T
    return frame_points(corners, aspect, azimuth_deg, elevation_deg, fov_deg, margin)


def frame_points(points, aspect: float, azimuth_deg: float = 135.0, elevation_deg: float = 40.0,
                 fov_deg: float = 40.0, margin: float = 1.08) -> Camera:
    """The closest camera, from the given direction, that sees every point, their picture
    centred and spanning 1/margin of the frame on its tighter side.

    Exact, not iterated: with the orientation fixed, a point c is in view from the eye
    e when |(c - e).right| <= tan_h (c - e).forward (and likewise up), which is linear
    in e. For each screen axis, a pair of points (i, j) both fits only when
    e.forward <= (c_i + c_j).forward / 2 - (c_i - c_j).side / (2 tan); the eye goes as
    far forward as the tightest pair allows, and sideways to the middle of what is
    left, which centres the points.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(points) or not np.all(np.isfinite(points)):
        raise RadError('nothing to frame: expected finite points')
    if not margin >= 1.0:
        raise RadError(f'camera margin must be at least 1, got {margin!r}')
    back = Camera((0.0, 0.0, 0.0), 1.0, azimuth_deg, elevation_deg, fov_deg).eye   # unit vector to the eye
    right = np.cross([0.0, 0.0, 1.0], back)
    right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.array([0.0, 1.0, 0.0])
    up = np.cross(back, right)
    forward = -back
    tan_v = math.tan(math.radians(fov_deg) / 2) / margin
    depth = points @ forward
    extent = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    reach = float(depth.min()) - max(1e-3, 1e-3 * extent)    # never closer than the nearest point
    sides = []
    for axis, tan in ((right, tan_v * aspect), (up, tan_v)):
        side = points @ axis
        sides.append((side, tan))
        reach = min(reach, float((depth - side / tan).min() + (depth + side / tan).min()) / 2)
    eye = reach * forward
    for axis, (side, tan) in zip((right, up), sides):
        room = tan * (depth - reach)                          # how far sideways each point may be
        eye = eye + axis * (float((side - room).max()) + float((side + room).min())) / 2
    distance = float(points.mean(axis=0) @ forward - reach)
    target = eye + distance * forward
    return Camera(tuple(float(v) for v in target), distance, azimuth_deg, elevation_deg, fov_deg)


def render_scene(scene: Scene, allocation=None, occupancy=None, width: int = 640, height: int = 480,
                 camera: Camera | None = None, robot=None) -> np.ndarray:
    """An (height, width, 3) uint8 picture of the scene; see the module docstring.

    allocation: an AllocationResult or an iterable of Placements (type, target,
    yaw, cells). occupancy: one entry per grid cell (`Grid` order), -1 for free,
    else the scene index of the block there. robot: the Panda's 9 joint positions
    (panda.JOINT_NAMES order) to draw it with its meshes at the origin, or None.
    """
    _check_size(width, height)
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


def block_cubes(centres: np.ndarray, unit: float, clearance: float,
                course: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(box centres (n, 3), half extents (n, 3)) drawn for one block's unit cubes at these
    world centres: cubes of edge BLOCK_SIZE, their outer side faces set back by
    half the clearance (a fraction of the unit); `course` high where it is not the unit."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    course = unit if course is None else course
    offsets = np.round((centres - centres[0]) / np.array([unit, unit, course])).astype(np.int64)
    half = unit * BLOCK_SIZE / 2
    shift, halves = unit_boxes(offsets, half, course * BLOCK_SIZE / 2, clearance * unit / 2)
    return centres + shift, halves


def _scene_boxes(scene: Scene, placements: list, occupancy) -> list[tuple[np.ndarray, float | tuple, tuple]]:
    """(centre, half edge or half extents (x, y, z), rgb) of every box to draw."""
    u = scene.unit if scene.course == scene.unit else scene.pitch

    def half(size: float):
        return u * size / 2 if np.ndim(u) == 0 else tuple((u * size / 2).tolist())
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
            boxes.extend((c, tuple(h.tolist()), colour)
                         for c, h in zip(*block_cubes(centres, scene.unit, scene.clearance, scene.course)))
        else:
            boxes.extend((c, half(BLOCK_SIZE), colour) for c in centres)
    for p in placements:
        region = scene.target(p.target)
        colour = tuple(0.65 * v + 0.35 for v in type_colour(p.type))   # paler: planned, not built
        boxes.extend((region.cell_center(c, u), half(PLAN_SIZE), colour) for c in p.cells)
    for region in scene.targets:
        filled = set(region.filled)
        for ijk in np.ndindex(*region.size):
            size, colour = (TARGET_SIZE, PINK) if ijk in filled else (OTHER_CELL_SIZE, GREEN)
            boxes.append((region.cell_center(ijk, u), half(size), colour))
    return boxes


def _draw(boxes, lo, hi, unit: float, camera: Camera, width: int, height: int, robot=None,
          table_margin: float | None = None, shadow: bool = True) -> np.ndarray:
    """Draw boxes around [lo, hi] on a table reaching table_margin (default two units) beyond it."""
    import pybullet as p  # here, not at the top: importing it prints a banner on stdout
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
        table = margin if table_margin is None else table_margin
        half = [(hi[0] - lo[0]) / 2 + table, (hi[1] - lo[1]) / 2 + table, unit / 4]
        slab = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[*TABLE, 1.0], physicsClientId=cid)
        p.createMultiBody(baseMass=0, baseVisualShapeIndex=slab,
                          basePosition=[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, -unit / 4], physicsClientId=cid)

        eye = camera.eye
        view = p.computeViewMatrix(eye.tolist(), list(camera.target), [0, 0, 1], physicsClientId=cid)
        reach = float(np.linalg.norm(np.asarray(hi) - lo)) + margin
        near = max(1e-3, camera.distance - reach)
        proj = p.computeProjectionMatrixFOV(camera.fov_deg, width / height, near,
                                            camera.distance + reach + 2 * max(0.0, table - margin),
                                            physicsClientId=cid)
        light = (eye - np.asarray(camera.target)) + np.array([0.0, 0.0, camera.distance])
        _, _, rgba, _, _ = p.getCameraImage(
            width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=int(shadow),
            lightDirection=light.tolist(), lightAmbientCoeff=0.6, lightDiffuseCoeff=0.4,
            lightSpecularCoeff=0.0, physicsClientId=cid)
    finally:
        p.disconnect(physicsClientId=cid)
    return np.ascontiguousarray(np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3])


# ---- pictures of a build: what was built against the target cells ---------

VIEWS = ((135.0, 30.0), (-45.0, 30.0))
"""(azimuth, elevation) in degrees of the two sides a build is pictured from: front-left as the
robot sees the table, and back-right, so both faces of a two-sided target are seen."""
GHOST_ALPHA = 0.3
"""Opacity of a target cell no block fills: what is behind it shows through."""
GHOST_EDGE = tuple(0.75 * v for v in PINK)
"""The opaque edges of such a cell, so it reads as a cell even where little shows through."""
OFF_TARGET = (0.85, 0.05, 0.05)
"""The tint of a block's cube on a region cell that is not a target cell."""
OFF_TARGET_EDGE = (0.25, 0.0, 0.0)
"""The edges of such a cube, so it stands out from a block type that is red anyway."""
EDGE = 0.05
"""Thickness of outline bars, a fraction of the unit."""
FRAME_MARGIN = 1.05
"""The framed box spans 1/FRAME_MARGIN of the picture on its tighter side."""
TABLE_REACH = 1.5
"""How far (m) the table reaches beyond the framed box, so that it fills the background (drawn
without shadows: TinyRenderer's shadow map ends short of it and leaves a band of shade)."""
GUTTER = 6
"""White pixels between the two views."""


@dataclass(frozen=True)
class BuildLayers:
    """What a picture of a build draws of a scene (`build_layers`)."""

    solid: list
    """(centre, half edge or half extents, rgb) drawn opaque: blocks, outlines of unbuilt
    target cells and of block cubes outside the target."""
    ghosts: list
    """Target cells no block fills, drawn translucent over what is behind them."""
    frame: np.ndarray
    """(n, 3) points the cameras frame: the corners of the cells shown."""
    built: int
    """Target cells a block fills."""
    missing: int
    """Target cells no block fills."""
    off_target: int
    """Region cells outside the target that a block fills."""


def _outline(centre, half, colour, thickness: float) -> list:
    """The 12 edges of the box centre +- half as bars `thickness` thick."""
    centre, half = np.asarray(centre, dtype=float), np.broadcast_to(np.asarray(half, dtype=float), (3,))
    bars = []
    for a in range(3):
        b, c = (k for k in range(3) if k != a)
        extents = np.full(3, thickness / 2)
        extents[a] = half[a] + thickness / 2
        for sb in (-1, 1):
            for sc in (-1, 1):
                offset = np.zeros(3)
                offset[b], offset[c] = sb * half[b], sc * half[c]
                bars.append((centre + offset, tuple(extents.tolist()), colour))
    return bars


def build_layers(scene: Scene, heap: bool = False) -> BuildLayers:
    """The scene as a build picture shows it, framed on its structure.

    Blocks on grid cells are drawn in their type colours where the cell is a target
    cell, and tinted red and outlined where it is not; target cells no block fills are
    translucent pink cubes with pink edges. The frame is the target cells and every
    filled cell. Blocks off the grid (the heap) are left out unless `heap` is set,
    which also frames them, or they lie within a unit of the frame's box (a block that
    fell beside the structure is shown).
    """
    u = scene.unit
    grid = Grid(scene)
    on_grid = blocks_on_grid(scene, grid)
    filled = np.zeros(grid.num_cells, dtype=bool)
    for cells in on_grid.values():
        filled[cells] = True
    shown = grid.is_target | filled
    points = [grid.centres[shown]] if shown.any() else []
    if heap or not points:
        points += [scene.unit_positions(b) for b in scene.blocks]
    corners = np.array(np.meshgrid(*[[-u / 2, u / 2]] * 3)).reshape(3, -1).T
    points = (np.concatenate(points)[:, None, :] + corners[None]).reshape(-1, 3)
    lo, hi = points.min(axis=0), points.max(axis=0)
    solid, thickness = [], EDGE * u
    for b, block in enumerate(scene.blocks):
        centres, cells = scene.unit_positions(block), on_grid.get(b)
        if cells is None and not np.any(np.all((centres >= lo - u) & (centres <= hi + u), axis=1)):
            continue
        colour = type_colour(block.type)
        tint = tuple(0.35 * c + 0.65 * t for c, t in zip(colour, OFF_TARGET))
        for i, (centre, half) in enumerate(zip(*block_cubes(centres, u, scene.clearance, scene.course))):
            if cells is not None and not grid.is_target[cells[i]]:
                solid.append((centre, tuple(half.tolist()), tint))
                solid.extend(_outline(centre, half, OFF_TARGET_EDGE, thickness))
            else:
                solid.append((centre, tuple(half.tolist()), colour))
    ghosts, half = [], (u * BLOCK_SIZE / 2 if scene.course == u else tuple(scene.pitch * BLOCK_SIZE / 2))
    for centre in grid.centres[grid.is_target & ~filled]:
        ghosts.append((centre, half, PINK))
        solid.extend(_outline(centre, half, GHOST_EDGE, thickness))
    return BuildLayers(solid, ghosts, points, int((filled & grid.is_target).sum()),
                       int((grid.is_target & ~filled).sum()), int((filled & ~grid.is_target).sum()))


def _draw_layers(layers: BuildLayers, frame: np.ndarray, unit: float, camera: Camera, width: int,
                 height: int) -> np.ndarray:
    """The layers drawn twice, without and with the ghosts solid, and blended where the ghosts show:
    TinyRenderer draws no transparency of its own."""
    lo, hi = frame.min(axis=0), frame.max(axis=0)
    lo[2] = min(lo[2], 0.0)

    def draw(boxes):
        return _draw(boxes, lo, hi, unit, camera, width, height, table_margin=TABLE_REACH, shadow=False)

    base = draw(layers.solid)
    if not layers.ghosts:
        return base
    ghosted = draw(layers.solid + layers.ghosts)
    seen = np.any(base != ghosted, axis=2)
    out = base.copy()
    out[seen] = np.round(GHOST_ALPHA * ghosted[seen] + (1 - GHOST_ALPHA) * base[seen]).astype(np.uint8)
    return out


def render_build(scene: Scene, heap: bool = False, frame=None, width: int = 480, height: int = 400,
                 views=VIEWS) -> np.ndarray:
    """The structure in `scene` against its target cells (`build_layers`), seen from each of
    `views` ((azimuth, elevation) pairs) in a width x height picture framed close on the
    structure (or on `frame`, (n, 3) points), side by side with GUTTER white columns
    between them: an (height, n * width + (n - 1) * GUTTER, 3) uint8 array."""
    _check_size(width, height)
    layers = build_layers(scene, heap)
    frame = np.asarray(layers.frame if frame is None else frame, dtype=float).reshape(-1, 3)
    pictures = []
    for azimuth, elevation in views:
        camera = frame_points(frame, width / height, azimuth, elevation, margin=FRAME_MARGIN)
        if pictures:
            pictures.append(np.full((height, GUTTER, 3), 255, dtype=np.uint8))
        pictures.append(_draw_layers(layers, frame, scene.unit, camera, width, height))
    return np.concatenate(pictures, axis=1)


def scenes_after_steps(start: Scene, steps) -> list[Scene]:
    """The start scene, then the scene after each step of a rad-result/1 `steps` list.

    Each step's block is put at the pose the plan gave it (the step's `position` and
    `yaw`), not where motion capture saw it: no physics is run again, so a block that
    landed a few millimetres off is drawn on its cell. A step that failed (it has a
    `failure`) leaves the scene as it was: where its block went is not in the document.
    """
    blocks = {b.id: b for b in start.blocks}
    scenes = [start]
    for n, step in enumerate(steps):
        if not step.get('failure'):
            old = blocks.get(step.get('block'))
            position = step.get('position') or ()
            if old is None or len(position) != 3:
                raise RadError(f'steps[{n}]: expected a block of the scene and a position [x, y, z]')
            blocks[old.id] = Block(old.id, old.type, tuple(float(v) for v in position), int(step['yaw']) % 360)
        scenes.append(replace(start, blocks=tuple(blocks[b.id] for b in start.blocks), measured_offsets={}))
    return scenes


def save_build_pictures(start: Scene, final: Scene | None, steps, out: str | Path, width: int = 480,
                        height: int = 400, step_s: float = 0.8) -> dict[str, Path]:
    """Pictures of a build, two views side by side in each (`render_build`), written into `out`:

    - before.png: the target cells and the heap at the start (`start`);
    - after.png: what was built (`final`, the world as measured at the end) against the target;
    - build.png: an animated PNG, the start and then the structure after each step
      (`scenes_after_steps`: blocks at their planned poses), all framed alike, each shown
      step_s seconds and the last three times as long; viewers that play no APNG show the last.

    Returns the paths written by name ('before', 'after', 'build'); no after.png without a
    final scene, no build.png without steps.
    """
    out = Path(out)
    paths = {'before': write_png(out / 'before.png', render_build(start, heap=True, width=width, height=height))}
    if final is not None:
        paths['after'] = write_png(out / 'after.png', render_build(final, width=width, height=height))
    scenes = scenes_after_steps(start, steps)
    if len(scenes) > 1:
        frame = np.unique(np.concatenate([build_layers(s).frame for s in scenes]).round(9), axis=0)
        frames = [render_build(s, frame=frame, width=width, height=height) for s in scenes]
        delays = [step_s] * (len(frames) - 1) + [3 * step_s]
        paths['build'] = write_apng(out / 'build.png', frames, delays, still=frames[-1])
    return paths


def _check_size(width, height) -> None:
    if not (isinstance(width, int) and isinstance(height, int) and 0 < width <= 4096 and 0 < height <= 4096):
        raise RadError(f'image size must be 1..4096 pixels a side, got {width!r} x {height!r}')

"""Targets from files: surface meshes (STL, OBJ, PLY, OFF, GLB/GLTF) and voxel grids (.npy, binvox) as
target regions.

A user's own shape reaches rad as a file; this module turns it into the cells of a
`TargetRegion`, resting on the table in front of the robot, where the hand-made shapes
(`rad_core.domain.shapes`) and generated scenes put theirs. What blocks build it is
`rad_core.allocation.supply`'s business.

Cells: they are laid so that the model's bounding box is centred in theirs, so a box exactly N
cells long gives N cells, never N + 1. Which cells are solid depends on the mesh (`solid_cells`,
which says what it found and did in a `MeshReport`):
- one closed shell (every edge on two triangles, after merging repeated vertices): a cell is
  solid when its centre is inside (trimesh's ray-parity test), the rule the generator uses for
  its polygons ('contains');
- several closed shells: the same centre rule per shell, a cell solid when it is inside more
  shells that face outwards than shells that face inwards, so shells that touch or overlap are
  united, a shell inside another facing inwards is a cavity, and a shell with all its normals
  flipped still counts ('bodies');
- anything else (open edges, shells that share edges, triangles that cross): the holes left are
  capped with a fan of triangles, the surface is marked on a grid `sub` times finer than the cells
  (every sub-cell that a triangle touches), the outside is flood-filled from the grid's border, and
  a cell is solid when more than half of it is not outside, a sub-cell the surface touches
  counting half ('flood fill'). A gap narrower than a sub-cell closes by itself; the half rule
  keeps the solid from growing a cell layer fatter than the model, so a box exactly N cells long
  still gives N cells. Enclosed cavities are filled.
Where the flood fill finds nothing solid:
- a surface that encloses sub-cells but no cell, or that is closed (every edge on two triangles or
  more once its holes are capped, and every hole narrower than a sub-cell, a crack: closed shells, also
  ones that share edges or touch) is walls thinner than a cell (a tray, a frame of bars): the cells its
  surface passes through stand for them, one cell thick ('surface');
- anything else has gaps (cracks between parts, panels that do not meet, open edges that form no
  loop): they are closed on the flood fill's grid ('closed gaps'). The surface's sub-cells are
  thickened by r sub-cells along every axis, the outside of that is flood-filled and thickened back by
  r, so that the solid grows no fatter than the model, and a cell is solid by the flood fill's rule.
  r starts at the least value from 1 at which the thickened surface encloses something and a cell is
  solid, and grows while one more sub-cell adds cells (gaps of several widths), up to `sub`: gaps up
  to about two cells wide close. The report says how wide. A single sheet (a height field) thickened
  encloses nothing at any r: it is refused.
`hollow` keeps the solid's shell (cells with a face towards the outside); where nothing is
enclosed even with the gaps closed it takes the cells the surface passes through ('surface').

Scale: `size` N makes the longest side of all the models together N cells (several
models keep their proportions); `scale` S says how many metres one mesh unit is (1 for a
model in metres, 0.001 for one in millimetres). A voxel file has one cell per voxel.

Orientation: `up` names the model's axis that points up (`x`, `y` or `z`; many modellers
and OBJ files use `y`); it is turned onto +z by a rotation, never a mirror.

Fit (`fit_target`): a target must lie where the arm builds it. Its footprint stays within
`TargetLimits` (0.40 m along x, 0.30 m along y, in front of the robot), each region within
MAX_REGION_AXIS cells a side and all within MAX_GRID_CELLS; its top cells must be within the arm's
top-down reach (`reach_cells`): the hand comes down on every cell from `APPROACH` above its grasp
target, and the higher the structure the nearer the robot it must stand. The model may be turned
about z by quarter turns (the cells are a lattice aligned with the robot's base):
- yaw: the file's orientation (0) where it fits at x = STRUCTURE_X; else a quarter turn (90) where
  that fits there; else the file's orientation moved nearer the robot; else the turned one moved.
  A turn of 180 or 270 degrees is never needed for the fit (the limits are symmetric about
  y = 0), only given (`yaw`);
- place: centred on y = 0 and on x = STRUCTURE_X (0.5 m) where the reach allows its height there;
  else as near x = STRUCTURE_X as the reach allows, moved towards the robot (the reach over a
  height only grows nearer the robot, down to the footprint's near edge at 0.30 m).
A model that fits no yaw is refused naming the largest unit and the --size (and --scale) that fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from rad_core.domain.errors import RadError
from rad_core.domain.scene import MAX_GRID_CELLS, MAX_REGION_AXIS, TargetRegion
from rad_core.domain.shapes import STRUCTURE_X

# Widest cube the open hand takes (rad_core.gamp.grasps.MAX_GRASP_WIDTH: 0.08 m less 5 mm a side).
MAX_UNIT = 0.07

MESH_FORMATS = ('.stl', '.obj', '.ply', '.off', '.glb', '.gltf')
VOXEL_FORMATS = ('.npy', '.binvox')
UP_AXES = ('x', 'y', 'z')

# Rotations turning the named axis onto +z (proper rotations: a model is never mirrored).
_UP = {
    'z': np.eye(3),
    'y': np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),    # about x by +90: y -> z, z -> -y
    'x': np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]),    # about y by -90: x -> z, z -> -x
}


@dataclass(frozen=True)
class TargetLimits:
    """Where a target's footprint may lie, in metres, for the arm to build all of it.

    The footprint is centred on y = 0 and, by default, on x = STRUCTURE_X (0.5 m): a width (x) of
    0.40 m spans 0.30..0.70 m, the depth (y) straddles y = 0. A tall target may move nearer the
    robot, its near edge no nearer than STRUCTURE_X - max_width / 2. How high it may be follows
    the arm's reach at its place (`reach_cells`). The hand-made shapes stay within 0.30 x 0.20 m.
    """

    max_width: float = 0.40
    max_depth: float = 0.30

    @property
    def nearest_x(self) -> float:
        """The nearest to the robot a footprint's edge may be (m along x)."""
        return STRUCTURE_X - self.max_width / 2

    def cells(self, unit: float) -> np.ndarray:
        """Most cells along x, y, z at this unit: the footprint's, and the height a footprint that
        large allows at x = STRUCTURE_X (a narrower or nearer one allows more)."""
        w = min(int(math.floor(self.max_width / unit + 1e-9)), MAX_REGION_AXIS)
        d = int(math.floor(self.max_depth / unit + 1e-9))
        return np.array([w, d, reach_cells(w, d, unit, STRUCTURE_X)[0]])


# The arm's top-down reach, from the Panda's URDF (rad_core.cell.panda) and checked against the IK
# (`gamp.ik.solve_top_down`) in tests/core/test_voxels.py. With the hand pointing straight down, the
# wrist (joint 6) stands WRIST_ABOVE over the grasp target (flange 0.107 m + grasp target 0.105 m) and
# WRIST_BACK nearer the robot (joint 7's 0.088 m offset), and the wrist reaches ARM_REACH from the
# shoulder (joint 2, SHOULDER_Z over the base: `gamp.ik.SHOULDER`) with the elbow all but straight
# (links of 0.316 and 0.384 m with their 0.0825 m offsets: 0.719 m; the IK reaches 0.712..0.720 m
# between x = 0.25 and 0.75 m; ARM_REACH keeps 0.02 m of that in hand).
SHOULDER_Z = 0.333
WRIST_ABOVE = 0.212
WRIST_BACK = 0.088
ARM_REACH = 0.70
# The hand comes down on a placement, and leaves it, from this far over its grasp target
# (`gamp.planner.GampConfig.approach_height`).
APPROACH = 0.12
# A tight grasp's target stands this far under the unit's top (`gamp.grasps.GRASP_BELOW_TOP`).
GRASP_BELOW_TOP = 0.013
# The twin takes no cell centre higher than this (`sim.workspace.Workspace.upper[2]`, m).
WORKSPACE_TOP = 1.0


def top_down_reach(r: float) -> float:
    """The highest grasp target (m over the table) a top-down hand reaches at horizontal distance r (m)
    from the robot's base axis; -inf beyond the reach."""
    across = r - WRIST_BACK
    if abs(across) > ARM_REACH:
        return -math.inf
    return SHOULDER_Z - WRIST_ABOVE + math.sqrt(ARM_REACH ** 2 - across ** 2)


def reach_cells(width: int, depth: int, unit: float, x: float) -> tuple[int, str]:
    """How many cells high a footprint of width x depth cells centred on (x, 0) may be, and what
    caps it: the top-down reach over its farthest top cell (that cell's grasp target plus
    `APPROACH` within `top_down_reach`), a region's MAX_REGION_AXIS cells, the workspace's top."""
    far = math.hypot(x + unit * (width - 1) / 2, unit * (depth - 1) / 2)
    lift = max(0.0, unit / 2 - GRASP_BELOW_TOP)
    # Top cell k (from 1) has its centre at (k - 1/2) unit.
    reach = int(math.floor((top_down_reach(far) - APPROACH - lift) / unit + 0.5 + 1e-9)) \
        if math.isfinite(top_down_reach(far)) else 0
    space = int(math.floor(WORKSPACE_TOP / unit + 0.5 + 1e-9))
    caps = [(max(0, reach), f'the arm\'s top-down reach over its far corner {far:.2f} m out, '
                            f'{APPROACH:g} m approach included'),
            (MAX_REGION_AXIS, f'a region\'s {MAX_REGION_AXIS} cells a side'),
            (space, f'the workspace\'s top at {WORKSPACE_TOP:g} m')]
    return min(caps, key=lambda c: c[0])


@dataclass(frozen=True)
class MeshReport:
    """What making one mesh's cells found and did (`solid_cells`).

    bodies: connected pieces of surface; open_edges: edges with one triangle on them as read
    (vertices repeated along texture seams count); open_after: those left after the repairs and
    the caps; repairs: what was changed, in words; method: 'contains', 'bodies', 'flood fill', 'surface'
    or 'closed gaps' (the module docstring says which mesh gets which); cells: the filled cells.
    """

    bodies: int
    open_edges: int
    open_after: int
    repairs: tuple[str, ...]
    method: str
    cells: int

    def summary(self) -> str:
        """One line: the cells and how, the mesh as read, the repairs."""
        shells = f'{self.bodies} bod{"y" if self.bodies == 1 else "ies"}'
        if self.open_edges == 0 and self.open_after == 0:
            state = f'{shells}, no open edge'
        elif self.open_after == self.open_edges:
            state = f'{shells}, {self.open_edges} open edges'
        else:
            state = f'{shells}, {self.open_edges} open edges ({self.open_after} after repairs)'
        repaired = f'; {", ".join(self.repairs)}' if self.repairs else ''
        return f'{self.cells} cells by {self.method}: {state}{repaired}'


@dataclass(frozen=True)
class Model:
    """One file's cells: a boolean occupancy grid [i, j, k], k up, cropped to its filled cells, turned
    by `yaw`; for a mesh, the report of how they were made."""

    name: str
    path: str
    cells: np.ndarray
    report: MeshReport | None = None
    yaw: int = 0
    """Degrees the file's model was turned about z (`fit_target`), counter-clockwise seen from above."""


# ---- reading files ----------------------------------------------------------

def parse_region_arg(arg: str) -> tuple[str | None, str]:
    """'NAME=FILE' -> (NAME, FILE); a plain FILE -> (None, FILE). A FILE that exists as
    given is never split, so a path with '=' in it still reads."""
    name, sep, path = arg.partition('=')
    if sep and name and '/' not in name and not Path(arg).exists():
        return name, path
    return None, arg


def region_names(args: Sequence[str]) -> list[tuple[str, str]]:
    """(region name, file) per argument: the given name or the file's stem, unique."""
    out = []
    for arg in args:
        name, path = parse_region_arg(arg)
        out.append((name or Path(path).stem or 'target', path))
    names = [n for n, _ in out]
    for n in names:
        if names.count(n) > 1:
            raise RadError(f'two regions would be named {n!r}: name them, e.g. {n}_a=FILE {n}_b=FILE')
    return out


def _suffix(path: str, formats: Sequence[str], kind: str) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in formats:
        known = ', '.join(MESH_FORMATS + VOXEL_FORMATS)
        other = 'rad scene from-voxels' if suffix in VOXEL_FORMATS else 'rad scene from-mesh'
        hint = f' ({suffix} is read by {other})' if suffix in MESH_FORMATS + VOXEL_FORMATS else ''
        raise RadError(f'{path}: unknown {kind} format {suffix or "(no suffix)"!r}: expected '
                       f'{", ".join(formats)}{hint}; rad reads {known}')
    if not Path(path).is_file():
        raise RadError(f'{path}: no such file')
    return suffix


def load_mesh(path: str):
    """The file's triangles as one trimesh.Trimesh (a file of several parts, such as a GLB scene, gives
    them all, each where the file puts it); RadError naming the problem otherwise."""
    import trimesh  # trimesh: only a mesh import pays for its import
    suffix = _suffix(path, MESH_FORMATS, 'mesh')
    try:
        mesh = trimesh.load(path, file_type=suffix[1:], force='mesh', process=True)
    except Exception as e:   # noqa: BLE001 - trimesh raises anything on a broken file
        raise RadError(f'{path}: not a readable {suffix[1:].upper()} mesh ({type(e).__name__}: {e})') from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise RadError(f'{path}: the file holds no triangles: export the model\'s surface as a triangle mesh')
    if not np.all(np.isfinite(mesh.vertices)):
        raise RadError(f'{path}: the mesh has vertices that are not finite numbers: export it again')
    extent = mesh.extents
    if np.any(extent <= 1e-12 * max(1.0, float(extent.max()))):
        axis = 'xyz'[int(np.argmin(extent))]
        raise RadError(f'{path}: the mesh is flat (no extent along {axis}): it encloses no volume; give it a '
                       f'thickness in a modeller, or use a voxel file')
    if _flat(mesh.vertices[np.unique(mesh.faces)]):
        raise RadError(f'{path}: the mesh is flat (all its points lie in one plane): it encloses no volume; give '
                       f'it a thickness in a modeller, or use a voxel file')
    return mesh


def _flat(points: np.ndarray) -> bool:
    """Whether the points lie in one plane (their spread across it is a billionth of their largest)."""
    centred = points - points.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)
    return bool(spread[-1] <= 1e-9 * spread[0])


def open_edges(mesh) -> int:
    """Edges with one triangle on them (0 for a closed surface)."""
    from trimesh import grouping  # trimesh: only a mesh import pays for its import
    return len(grouping.group_rows(mesh.edges_sorted, require_count=1))


def load_voxel_grid(path: str) -> np.ndarray:
    """A .npy boolean (or integer, nonzero = filled) 3D array [x, y, z], or a binvox file's grid."""
    suffix = _suffix(path, VOXEL_FORMATS, 'voxel')
    if suffix == '.binvox':
        from trimesh.exchange.binvox import load_binvox  # trimesh: only a mesh import pays for its import
        try:
            with open(path, 'rb') as f:
                grid = np.asarray(load_binvox(f).matrix)
        except Exception as e:   # noqa: BLE001 - a corrupt file fails anywhere in the parser
            raise RadError(f'{path}: not a readable binvox file ({type(e).__name__}: {e})') from None
    else:
        try:
            grid = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:
            raise RadError(f'{path}: not a readable .npy array ({e})') from None
        if not isinstance(grid, np.ndarray):
            raise RadError(f'{path}: expected one array, got an archive of several')
    if grid.ndim != 3:
        raise RadError(f'{path}: expected a 3D array [x, y, z], got {grid.ndim} dimensions {list(grid.shape)}')
    if not (grid.dtype == bool or np.issubdtype(grid.dtype, np.integer)):
        raise RadError(f'{path}: expected a boolean array (or integers, nonzero = filled), got dtype {grid.dtype}')
    return grid != 0


# ---- cells --------------------------------------------------------------------

def orient_cells(grid: np.ndarray, up: str) -> np.ndarray:
    """The grid turned so that its axis `up` points along +z (as `_UP` turns points)."""
    _check_up(up)
    if up == 'y':   # (x, y, z) -> (x, -z, y)
        return np.flip(grid.transpose(0, 2, 1), axis=1)
    if up == 'x':   # (x, y, z) -> (-z, y, x)
        return np.flip(grid.transpose(2, 1, 0), axis=0)
    return grid


def _check_up(up: str) -> None:
    if up not in UP_AXES:
        raise RadError(f'up axis must be one of {", ".join(UP_AXES)}, got {up!r}')


def crop(grid: np.ndarray) -> np.ndarray:
    """The grid cut to the box of its filled cells: the lowest filled layer becomes k = 0
    (the model rests on the table) and no empty margin is left on any side."""
    if not grid.any():
        return grid[:0, :0, :0]
    idx = np.argwhere(grid)
    lo, hi = idx.min(axis=0), idx.max(axis=0) + 1
    return grid[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]


def shell(grid: np.ndarray) -> np.ndarray:
    """The filled cells with a face towards an empty cell or the outside (the hollow model)."""
    padded = np.pad(grid, 1)
    inner = padded[1:-1, 1:-1, 1:-1].copy()
    for axis in range(3):
        for step in (1, -1):
            inner &= np.roll(padded, step, axis=axis)[1:-1, 1:-1, 1:-1]
    return grid & ~inner


def cell_centres(lo: np.ndarray, counts: np.ndarray, pitch: float) -> np.ndarray:
    """Centres of counts[0] x counts[1] x counts[2] cells of edge `pitch` from corner lo, in [i, j, k] order."""
    axes = [lo[a] + pitch * (np.arange(counts[a]) + 0.5) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing='ij'), axis=-1).reshape(-1, 3)


def cell_counts(extents: np.ndarray, pitch: float) -> np.ndarray:
    """Cells per axis that cover the extents at this pitch (a side of exactly N pitches is N cells)."""
    return np.maximum(1, np.ceil(np.asarray(extents) / pitch - 1e-6)).astype(int)


def voxelize(mesh, pitch: float, hollow: bool = False, where: str = 'mesh') -> np.ndarray:
    """The mesh's cells of edge `pitch` (mesh units), the bounding box centred in theirs (`solid_cells`)."""
    return solid_cells(mesh, pitch, hollow, where)[0]


def solid_cells(mesh, pitch: float, hollow: bool = False, where: str = 'mesh') -> tuple[np.ndarray, MeshReport]:
    """The mesh's cells of edge `pitch` (mesh units), the bounding box centred in theirs, and the report.

    Solid by the mesh's kind (module docstring): 'contains' for one closed shell, 'bodies' for
    several, 'flood fill' for anything else; where that finds nothing solid, 'surface' for walls
    thinner than a cell, 'closed gaps' for a surface with gaps up to about two cells wide. Hollow: the
    solid's shell, or where the surface encloses nothing even with its gaps closed, the cells it passes
    through. RadError (naming `where`) when a solid is asked and the surface encloses nothing.
    """
    lo, hi = mesh.bounds
    counts = cell_counts(hi - lo, pitch)
    corner = (lo + hi) / 2 - pitch * counts / 2
    n_open = open_edges(mesh)
    mesh, repairs = _repaired(mesh)
    bodies = int(mesh.body_count)

    def done(grid, method, open_after):
        if hollow and method != 'surface':
            grid = shell(grid)
        return grid, MeshReport(bodies, n_open, open_after, tuple(repairs), method, int(grid.sum()))

    if mesh.is_watertight:
        shells = mesh.split(only_watertight=False) if bodies > 1 else [mesh]
        if len(shells) == 1:
            inside = _contains(mesh, cell_centres(corner, counts, pitch)).reshape(tuple(counts))
            if inside.any():
                return done(inside, 'contains', 0)
        elif all(s.is_watertight for s in shells):
            inside = _inside_shells(shells, corner, counts, pitch)
            if inside.any():
                return done(inside, 'bodies', 0)
    triangles = mesh.triangles
    caps, holes, open_after, widest = _hole_caps(mesh)
    sub = _sub_cells(counts)
    # Every edge on two triangles or more, once cracks narrower than a sub-cell are capped: closed shells, also
    # ones that share edges or touch. Closed shells thinner than a cell have no cell centre inside: their
    # surface's below.
    closed = not open_after and widest < pitch / sub
    if holes:
        repairs.append(f'capped {holes} hole{"s" if holes > 1 else ""}')
        triangles = np.concatenate([triangles, caps])
    solid, surface, enclosed, fine = _flood_fill(triangles, corner, counts, pitch, sub)
    if enclosed and solid.any():
        return done(solid, 'flood fill', open_after)
    if (enclosed or closed) and surface.any():
        if not hollow:
            # Walls thinner than a cell (a tray, a channel): no cell centre is inside them, so the cells
            # the surface passes through stand for them, one cell thick.
            repairs.append('thinner than a cell: the cells its surface passes through')
        return done(surface, 'surface', open_after)
    closed_solid, r = _close_gaps(fine, counts, sub)
    if closed_solid is not None:
        repairs.append(f'closed gaps up to about {_gap(r, pitch, sub):.3g} mesh units wide '
                       f'({_gap(r, pitch, sub) / pitch:.2g} cells)')
        return done(closed_solid, 'closed gaps', open_after)
    if hollow:
        return done(surface, 'surface', open_after)
    raise RadError(f'{where}: the surface encloses no volume at {pitch:.4g} mesh units per cell, even with its '
                   f'gaps up to about {_gap(sub, pitch, sub):.3g} units wide closed (a gap wider than that, or a '
                   f'single sheet): give --hollow to take its surface only, or close it in a mesh editor')


def _repaired(mesh):
    """A copy of the mesh's triangles with repeated vertices merged (a texture seam repeats them) and
    degenerate and repeated triangles dropped; and what was changed, in words.

    Holes are left to `_hole_caps` and the flood fill: trimesh.repair.fill_holes splits a hole of four
    edges along either diagonal, which for a rim that is not flat can put the patch across the solid."""
    import trimesh  # trimesh: only a mesh import pays for its import
    out = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)
    repairs = []
    used = len(np.unique(out.faces))
    out.merge_vertices(merge_tex=True, merge_norm=True)
    if len(np.unique(out.faces)) < used:
        repairs.append(f'merged {used - len(np.unique(out.faces))} repeated vertices')
    keep = out.nondegenerate_faces()
    unique = np.zeros(len(out.faces), dtype=bool)
    unique[out.unique_faces()] = True
    keep &= unique
    if not keep.all():
        repairs.append(f'dropped {int((~keep).sum())} degenerate or repeated triangles')
        out.update_faces(keep)
        out.remove_unreferenced_vertices()
    return out, repairs


# Triangles times points above which `_contains` casts its rays along z: trimesh's slanted rays meet
# a box of candidate triangles that grows with the mesh, and cost memory and time in proportion.
_SLANTED_RAYS_WORK = 2e7


def _contains(mesh, points: np.ndarray) -> np.ndarray:
    """Which points are inside the closed mesh, by trimesh's ray-parity test. Up to `_SLANTED_RAYS_WORK`
    its default slanted rays; beyond, rays along z, in chunks (a ray's candidates are then the
    triangles above and below the point): the answers differ only for a point on the surface."""
    if len(mesh.faces) * len(points) <= _SLANTED_RAYS_WORK:
        return mesh.contains(points)
    from trimesh.ray.ray_util import contains_points  # trimesh: only a mesh import pays for its import
    chunk = 20_000
    return np.concatenate([contains_points(mesh.ray, points[i:i + chunk], check_direction=(0.0, 0.0, 1.0))
                           for i in range(0, len(points), chunk)])


def _inside_shells(shells, corner: np.ndarray, counts: np.ndarray, pitch: float) -> np.ndarray:
    """Cells whose centre is inside more outward-facing closed shells than inward-facing ones, or inside
    only inward-facing ones (a shell with all its normals flipped). A shell whose triangles disagree
    on which side is out counts as outward-facing."""
    centres = cell_centres(corner, counts, pitch)
    outward = np.zeros(len(centres), dtype=int)
    inward = np.zeros(len(centres), dtype=int)
    for body in shells:
        lo, hi = body.bounds
        near = np.all((centres >= lo) & (centres <= hi), axis=1)
        if not near.any():
            continue
        inside = np.zeros(len(centres), dtype=bool)
        inside[near] = _contains(body, centres[near])
        if body.is_winding_consistent and body.volume < 0:
            inward += inside
        else:
            outward += inside
    solid = (outward > inward) | ((outward == 0) & (inward > 0))
    return solid.reshape(tuple(counts))


def _hole_caps(mesh) -> tuple[np.ndarray, int, int, float]:
    """Triangles that close the mesh's holes, a fan from the centroid of every loop of open edges;
    the number of loops; the open edges that no loop closes; and the widest hole's width (mesh units):
    four times its cap's area over its perimeter (a square's side, a circle's diameter, twice a slit's
    width)."""
    import networkx as nx  # trimesh's own dependency: only a mesh import pays for its import
    from trimesh import grouping  # trimesh: only a mesh import pays for its import
    boundary = mesh.edges_sorted[grouping.group_rows(mesh.edges_sorted, require_count=1)]
    if len(boundary) == 0:
        return np.zeros((0, 3, 3)), 0, 0, 0.0
    loops = nx.cycle_basis(nx.from_edgelist(boundary.tolist()))
    if not loops:
        return np.zeros((0, 3, 3)), 0, len(boundary), 0.0
    sizes = np.array([len(loop) for loop in loops])
    ring = np.concatenate([np.asarray(loop, dtype=np.int64) for loop in loops])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    following = np.arange(len(ring)) + 1
    following[starts + sizes - 1] = starts
    points = mesh.vertices[ring]
    centroids = np.add.reduceat(points, starts, axis=0) / sizes[:, None]
    caps = np.stack([np.repeat(centroids, sizes, axis=0), points, points[following]], axis=1)
    n = len(mesh.vertices)
    closed = np.sort(np.stack([ring, ring[following]], axis=1), axis=1)
    still_open = ~np.isin(boundary[:, 0] * n + boundary[:, 1], closed[:, 0] * n + closed[:, 1])
    area = np.add.reduceat(np.linalg.norm(np.cross(caps[:, 1] - caps[:, 0], caps[:, 2] - caps[:, 0]), axis=1) / 2,
                           starts)
    perimeter = np.add.reduceat(np.linalg.norm(points[following] - points, axis=1), starts)
    width = 4 * area / np.maximum(perimeter, 1e-300)
    return caps, len(loops), int(still_open.sum()), float(width.max())


def _sub_cells(counts: np.ndarray) -> int:
    """Sub-cells per cell edge of the flood fill's grid: 4, 6 or 8 (even, so that eight meet at a cell's
    centre), the most that keep the longest side within about 128."""
    return int(np.clip(128 // int(np.max(counts)), 4, 8)) // 2 * 2


def _flood_fill(triangles: np.ndarray, corner: np.ndarray, counts: np.ndarray, pitch: float,
                sub: int) -> tuple[np.ndarray, np.ndarray, bool, np.ndarray]:
    """The solid cells by a flood fill of the outside (module docstring), the cells the surface passes
    through, whether the surface encloses anything (a sub-cell neither outside nor on it), and the
    sub-cells the surface touches (the cells' sub-cells with two empty ones round them)."""
    from scipy import ndimage  # scipy: only a mesh import pays for its import
    step = pitch / sub
    shape = tuple(int(c) * sub + 4 for c in counts)          # two empty sub-cells round the cells
    surface = _rasterize((triangles - (corner - 2 * step)) / step, shape)
    labels, _ = ndimage.label(~surface)                      # faces shared: six neighbours
    outside = labels == labels[0, 0, 0]
    inner = (slice(2, -2),) * 3
    on = surface[inner]
    enclosed = ~outside[inner] & ~on
    return _cell_rule(enclosed, on, counts, sub), _blocks(on, counts, sub).any(axis=(1, 3, 5)), \
        bool(enclosed.any()), surface


def _blocks(fine: np.ndarray, counts: np.ndarray, sub: int) -> np.ndarray:
    """The cells' sub-cells [i, a, j, b, k, c]: sub-cell (a, b, c) of cell (i, j, k)."""
    return fine.reshape(tuple(v for c in counts for v in (int(c), sub)))


def _cell_rule(enclosed: np.ndarray, on: np.ndarray, counts: np.ndarray, sub: int) -> np.ndarray:
    """The solid cells: more than half of a cell not outside, a sub-cell the surface touches counting half
    (module docstring); at the cell's centre first, its 2 x 2 x 2 sub-cells, then all of it on a tie."""
    middle = slice(sub // 2 - 1, sub // 2 + 1)                # the 2 x 2 x 2 sub-cells round a cell's centre
    weight = _blocks(enclosed.astype(np.float32) + 0.5 * on, counts, sub)
    centre = weight[:, middle, :, middle, :, middle].sum(axis=(1, 3, 5))
    return (centre > 4) | ((centre == 4) & (weight.sum(axis=(1, 3, 5)) >= 0.5 * sub ** 3))


def _close_gaps(surface: np.ndarray, counts: np.ndarray, sub: int) -> tuple[np.ndarray | None, int]:
    """The solid cells of a surface that encloses nothing, its gaps closed (module docstring), and by how
    many sub-cells r it was thickened: for r = 1 .. sub, the surface (`_flood_fill`'s sub-cells) thickened
    by r sub-cells along every axis, the outside of that flood-filled from the border and thickened back by
    r, so that the solid is no fatter than the model; the solid by `_cell_rule`. From the least r at which
    the thickened surface encloses a sub-cell and a cell is solid, r grows while one more sub-cell adds
    cells (several gaps of different widths all closed, no wider one), up to r = sub. (None, 0) where no r
    encloses a solid cell: a single sheet thickened encloses nothing."""
    from scipy import ndimage  # scipy: only a mesh import pays for its import
    margin = sub + 1                                         # the thickest surface stays clear of the border
    grid = np.pad(surface, margin)
    inner = (slice(margin + 2, -margin - 2),) * 3            # the cells' sub-cells
    on = grid[inner]
    # Sub-cells from the surface, the most along any one axis: within r = within a cube of 2r + 1 round it.
    near = ndimage.distance_transform_cdt(~grid, metric='chessboard')
    found = None
    for r in range(1, sub + 1):
        labels, _ = ndimage.label(near > r)                  # faces shared: six neighbours
        outside = labels == labels[0, 0, 0]
        if found is None and not (near > r)[~outside].any():
            continue                                         # the thickened surface encloses nothing
        outside = ndimage.distance_transform_cdt(~outside, metric='chessboard') <= r
        solid = _cell_rule(~outside[inner] & ~on, on, counts, sub)
        if found is not None and np.array_equal(solid, found):
            return found, r - 1
        if solid.any():
            found = solid
    return found, sub if found is not None else 0


def _gap(r: int, pitch: float, sub: int) -> float:
    """About the widest gap (mesh units) that the surface's sub-cells close when thickened by r of pitch / sub:
    2r + 2 sub-cells. Each side's sub-cells cover that side and start at most half a sub-cell past it
    (`_rasterize`), so a gap g sub-cells wide leaves more than g - 3 and fewer than g sub-cells between them;
    thickened by r each side, every gap up to 2r + 1 sub-cells wide closes, none wider than 2r + 3."""
    return (2 * r + 2) * pitch / sub


def _rasterize(triangles: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The sub-cells (of edge 1, corner at the origin) that any of the triangles touches, and none
    farther than half a sub-cell from them: each triangle is cut into a grid of similar triangles
    with edges of at most half a sub-cell, and every sub-cell within half a sub-cell (along each
    axis) of a grid point is marked. Every point of a triangle lies within half a sub-cell of a grid
    point, so a sub-cell the surface crosses is never missed."""
    grid = np.zeros(shape, dtype=bool)
    edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max(axis=1)
    parts = np.maximum(1, np.ceil(edges / 0.5)).astype(int)
    top = np.array(shape) - 1
    for n in np.unique(parts):
        i, j = np.triu_indices(n + 1)
        weights = np.stack([(n - j) / n, (j - i) / n, i / n], axis=1)        # every (a, b, c) >= 0, sum 1
        group = triangles[parts == n]
        chunk = max(1, 1_000_000 // len(weights))
        for k in range(0, len(group), chunk):
            points = np.einsum('mv,tvd->tmd', weights, group[k:k + chunk]).reshape(-1, 3)
            low = np.clip(np.floor(points - 0.5).astype(np.intp), 0, top)
            high = np.clip(np.floor(points + 0.5).astype(np.intp), 0, top)
            for x in (low[:, 0], high[:, 0]):
                for y in (low[:, 1], high[:, 1]):
                    for z in (low[:, 2], high[:, 2]):
                        grid[x, y, z] = True
    return grid


def cells_to_mesh(grid: np.ndarray, pitch: float = 1.0):
    """The closed surface of a set of cells (cell [i, j, k] spans pitch * [i, i+1] x ...), as a
    trimesh.Trimesh: two triangles for every face between a filled and an empty cell.

    It is watertight where no two cells meet along an edge only. Tests and scripts/make_meshes.py
    use it to make meshes whose cells are known.
    """
    import trimesh  # trimesh: only a mesh import pays for its import
    padded = np.pad(np.asarray(grid, dtype=bool), 1)
    quads = []
    for axis in range(3):
        for step in (1, -1):
            neighbour = np.roll(padded, -step, axis=axis)
            faces = np.argwhere(padded & ~neighbour) - 1          # cells with an open face that way
            for cell in faces:
                quads.append(_face_quad(cell, axis, step))
    if not quads:
        raise RadError('no filled cells: there is no surface to make')
    corners = np.asarray(quads, dtype=float).reshape(-1, 3) * pitch
    n = len(quads)
    base = 4 * np.arange(n)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    mesh = trimesh.Trimesh(vertices=corners, faces=faces, process=True)
    mesh.fix_normals()
    return mesh


def _face_quad(cell, axis: int, step: int) -> list[list[int]]:
    """The four corners of the face of `cell` towards `step` along `axis`, counter-clockwise seen from outside."""
    u, v = [a for a in range(3) if a != axis]
    plane = cell[axis] + (1 if step > 0 else 0)
    corners = []
    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
        c = [0, 0, 0]
        c[axis], c[u], c[v] = plane, cell[u] + du, cell[v] + dv
        corners.append(c)
    # (u, v, axis) is right-handed for axis 0 and 2, left-handed for axis 1.
    if (step > 0) != (axis != 1):
        corners.reverse()
    return corners


# ---- models to regions ------------------------------------------------------

YAWS = (0, 90, 180, 270)

# Quarter turns about z, counter-clockwise seen from above: (x, y) -> (-y, x) per 90 degrees.
_YAW = {yaw: np.round(np.array([[math.cos(math.radians(yaw)), -math.sin(math.radians(yaw)), 0],
                                [math.sin(math.radians(yaw)), math.cos(math.radians(yaw)), 0],
                                [0, 0, 1]])) for yaw in YAWS}


def mesh_models(files: Sequence[tuple[str, str]], unit: float, size: int | None = None, scale: float | None = None,
                up: str = 'z', hollow: bool = False, limits: TargetLimits = TargetLimits(),
                yaw: int | None = None) -> list[Model]:
    """Each (region name, mesh file) as a Model at one common pitch (see the module docstring), all
    turned by one yaw: `yaw` (degrees, a multiple of 90) or, where None, the one `fit_target` chooses."""
    _check_up(up)
    _check_unit(unit)
    _check_yaw(yaw)
    if size is not None and scale is not None:
        raise RadError('give --size or --scale, not both')
    meshes = []
    for name, path in files:
        mesh = load_mesh(path)
        mesh.apply_transform(_homogeneous(_UP[up]))
        meshes.append((name, path, mesh))
    extents = np.array([m.extents for _, _, m in meshes])
    longest = float(extents.max())
    if size is not None:
        if not (isinstance(size, int) and size >= 1):
            raise RadError(f'--size must be a whole number of cells, at least 1, got {size!r}')
        pitch = longest / size
    else:
        scale = 1.0 if scale is None else scale
        if not (math.isfinite(scale) and scale > 0):
            raise RadError(f'--scale must be a positive number of metres per mesh unit, got {scale!r}')
        pitch = unit / scale
    fit = _check_fits(extents, pitch, unit, limits, [p for _, p, _ in meshes], size, scale, yaw)
    models = []
    for name, path, mesh in meshes:
        if fit.yaw:
            mesh.apply_transform(_homogeneous(_YAW[fit.yaw]))
        cells, report = solid_cells(mesh, pitch, hollow, where=path)
        cells = crop(cells)
        if not cells.any():
            raise RadError(f'{path}: no cell centre lies inside the model at {pitch:.4g} mesh units per cell '
                           f'(it is thinner than a cell): use a larger --size or --scale')
        models.append(Model(name, path, cells, report, fit.yaw))
    _check_total(models)
    return models


def voxel_models(files: Sequence[tuple[str, str]], unit: float, up: str = 'z', hollow: bool = False,
                 limits: TargetLimits = TargetLimits(), yaw: int | None = None) -> list[Model]:
    """Each (region name, voxel file) as a Model, one cell per voxel, all turned by one yaw: `yaw`
    (degrees, a multiple of 90) or, where None, the one `fit_target` chooses."""
    _check_up(up)
    _check_unit(unit)
    _check_yaw(yaw)
    grids = []
    for name, path in files:
        grid = orient_cells(load_voxel_grid(path), up)
        if hollow:
            grid = shell(grid)
        grid = crop(grid)
        if not grid.any():
            raise RadError(f'{path}: the voxel grid is empty (no filled voxel)')
        grids.append((name, path, grid))
    boxes = [tuple(int(v) for v in g.shape) for _, _, g in grids]
    fit = _fit_or_none(boxes, unit, limits, yaw)
    if not isinstance(fit, Fit):
        where, counts = _culprit(boxes, unit, limits, [p for _, p, _ in grids], yaw)
        best = largest_unit(boxes, unit, limits)
        fix = f'use --unit {best:.3f} or less' if best else 'no unit from 0.010 m fits: use a smaller model'
        raise _refusal(fit, where, f'its filled voxels span {_dims(counts)} cells', boxes, unit, limits, yaw, fix)
    return [Model(name, path, np.rot90(grid, fit.yaw // 90, axes=(0, 1)) if fit.yaw else grid, yaw=fit.yaw)
            for name, path, grid in grids]


@dataclass(frozen=True)
class Fit:
    """How a target stands (`fit_target`): its turn about z (degrees, counter-clockwise seen from above),
    the x of its centre (m; y is 0), its box turned (cells along x, y, z), the most cells high its place
    allows and what caps that; turned: why it was turned, in words ('' where it was not)."""

    yaw: int
    x: float
    box: tuple[int, int, int]
    most_high: int
    cap: str
    turned: str = ''

    @property
    def moved(self) -> bool:
        """Whether it stands nearer the robot than x = STRUCTURE_X."""
        return self.x < STRUCTURE_X - 1e-9


def fit_target(boxes: Sequence[tuple[int, int, int]], unit: float, limits: TargetLimits = TargetLimits(),
               yaw: int | None = None) -> Fit:
    """Where and how models of these boxes (cells along x, y, z, as the files have them; several: back to
    back along y, one yaw for all) stand, by the module docstring's rule; `yaw` fixes the turn.
    RadError naming what exceeds the limits otherwise."""
    _check_yaw(yaw)
    fit = _fit_or_none(boxes, unit, limits, yaw)
    if isinstance(fit, Fit):
        return fit
    best = largest_unit(boxes, unit, limits)
    fix = f'use --unit {best:.3f} or less' if best else 'no unit from 0.010 m fits: use smaller models'
    raise _refusal(fit, 'the target', f'its boxes span {_dims(_group(boxes, 0))} cells', boxes, unit, limits,
                   yaw, fix)


def largest_unit(boxes: Sequence[tuple[int, int, int]], unit: float, limits: TargetLimits = TargetLimits(),
                 yaw: int | None = None) -> float | None:
    """The largest cell edge, in whole mm up to `unit` and from 0.010 m, at which these boxes fit (in
    `yaw`, or in any yaw); None where none does."""
    for mm in range(int(math.floor(unit * 1000 + 1e-6)), 9, -1):
        if isinstance(_fit_or_none(boxes, mm / 1000, limits, yaw), Fit):
            return mm / 1000
    return None


def placement(models: Sequence[Model], unit: float, limits: TargetLimits = TargetLimits()) -> Fit:
    """Where the models stand as they are (turned already): back to back along y, centred on y = 0 and on
    x = STRUCTURE_X, or nearer the robot where only there the reach allows their height.
    RadError naming what exceeds the limits otherwise."""
    boxes = [tuple(int(v) for v in m.cells.shape) for m in models]
    fit = _try(boxes, unit, limits, 0)
    if isinstance(fit, Fit):
        return Fit(models[0].yaw if models else 0, fit.x, fit.box, fit.most_high, fit.cap)
    what = f'the {len(models)} regions together' if len(models) > 1 else f'the region {models[0].name!r}'
    raise RadError(f'{what}: {_dims(_group(boxes, 0))} cells of {unit:g} m exceed what the arm builds: '
                   f'{"; ".join(t for _, t in fit)}: use fewer, smaller or thinner models')


def place_regions(models: Sequence[Model], unit: float,
                  limits: TargetLimits = TargetLimits()) -> tuple[TargetRegion, ...]:
    """The models as regions back to back along y, the first at +y (the robot's left), the whole
    centred on (x, 0) where `placement` puts it (x = STRUCTURE_X unless the reach wants it nearer),
    each centred on that x and resting on the table.

    Two one-cell-deep faces named left and right so land where the generator puts its two sides.
    """
    x = placement(models, unit, limits).x
    depth = sum(m.cells.shape[1] for m in models)
    out, top = [], depth / 2
    for m in models:
        w, d, _ = m.cells.shape
        x0 = x - unit * (w - 1) / 2
        y0 = unit * (top - d + 0.5)
        top -= d
        origin = tuple(round(float(v), 6) for v in (x0, y0, unit / 2))
        filled = tuple(tuple(int(v) for v in c) for c in np.argwhere(m.cells))
        out.append(TargetRegion(m.name, origin, tuple(int(v) for v in m.cells.shape), filled))
    return tuple(out)


def fit_report(models: Sequence[Model], unit: float, limits: TargetLimits = TargetLimits(),
               given_yaw: bool = False) -> str:
    """One line: the target's cells, where it stands, how it is turned and why, how high it may be there."""
    fit = placement(models, unit, limits)
    w, d, h = fit.box
    line = f'target: {w} x {d} x {h} cells of {unit:g} m centred on x = {fit.x:g} m, y = 0'
    if not fit.yaw:
        line += ', as in the file'
    else:
        if given_yaw:
            line += f', turned {fit.yaw} degrees (--yaw)'
        else:
            back = [_turned(tuple(int(v) for v in m.cells.shape), -fit.yaw) for m in models]
            chosen = _fit_or_none(back, unit, limits, None)
            why = chosen.turned if isinstance(chosen, Fit) and chosen.yaw == fit.yaw else ''
            line += f', turned {fit.yaw} degrees' + (f' {why}' if why else '')
    if fit.moved:
        at_structure = reach_cells(w, d, unit, STRUCTURE_X)[0]
        line += (f', moved {STRUCTURE_X - fit.x:.3f} m nearer the robot (at x = {STRUCTURE_X:g} m the reach '
                 f'allows {at_structure} cells high)')
    return line + f'; up to {fit.most_high} cells high here ({fit.cap})'


def _check_yaw(yaw) -> None:
    if yaw is not None and yaw not in YAWS:
        raise RadError(f'--yaw must be one of {", ".join(str(y) for y in YAWS)} (degrees: the cells are a '
                       f'lattice aligned with the robot\'s base), got {yaw!r}')


def _turned(box: tuple[int, int, int], yaw: int) -> tuple[int, int, int]:
    """A box's cells along x, y, z after a turn of `yaw` degrees about z."""
    return (box[1], box[0], box[2]) if yaw % 180 else tuple(box)


def _group(boxes: Sequence[tuple[int, int, int]], yaw: int) -> tuple[int, int, int]:
    """The box of the models turned by `yaw` and laid back to back along y."""
    turned = [_turned(b, yaw) for b in boxes]
    return (max(b[0] for b in turned), sum(b[1] for b in turned), max(b[2] for b in turned))


def _try(boxes: Sequence[tuple[int, int, int]], unit: float, limits: TargetLimits,
         yaw: int) -> Fit | list[tuple[str, str]]:
    """The place of these boxes turned by `yaw`: x = STRUCTURE_X where it fits there, else the x nearest it
    (in whole mm, towards the robot) where it does; or what does not fit, as (axis, words) pairs."""
    w, d, h = _group(boxes, yaw)
    problems = []
    most_w = int(math.floor(limits.max_width / unit + 1e-9))
    most_d = int(math.floor(limits.max_depth / unit + 1e-9))
    if w > min(most_w, MAX_REGION_AXIS):
        cap = (f'{limits.max_width:g} m of reach along x' if most_w <= MAX_REGION_AXIS
               else f'a region\'s {MAX_REGION_AXIS} cells a side')
        problems.append(('x', f'{w} cells wide (x), {min(most_w, MAX_REGION_AXIS)} fit ({cap})'))
    if d > most_d:
        problems.append(('y', f'{d} cells deep (y), {most_d} fit ({limits.max_depth:g} m of reach across y = 0)'))
    thickest = max(_turned(b, yaw)[1] for b in boxes)
    if thickest > MAX_REGION_AXIS:
        problems.append(('y', f'{thickest} cells deep (y) in one region, {MAX_REGION_AXIS} fit (a region\'s '
                              f'{MAX_REGION_AXIS} cells a side)'))
    total = sum(int(np.prod(b)) for b in boxes)
    if total > MAX_GRID_CELLS:
        problems.append(('cells', f'{total} cells in the regions\' boxes, {MAX_GRID_CELLS} fit (a scene\'s grid)'))
    if problems:
        return problems
    most_h, cap = reach_cells(w, d, unit, STRUCTURE_X)
    if h <= most_h:
        return Fit(yaw, STRUCTURE_X, (w, d, h), most_h, cap)
    near = int(math.ceil((limits.nearest_x + unit * w / 2) * 1000 - 1e-6))
    if near >= round(STRUCTURE_X * 1000) or reach_cells(w, d, unit, near / 1000)[0] < h:
        most_near, cap_near = reach_cells(w, d, unit, min(near / 1000, STRUCTURE_X))
        return [('z', f'{h} cells high (z), {max(most_h, most_near)} fit ({cap_near}, with its near edge at '
                      f'{limits.nearest_x:g} m, as near the robot as a target stands)')]
    # The reach over a height only grows nearer the robot: the farthest x (in mm) that allows h.
    lo, hi = near, int(round(STRUCTURE_X * 1000))          # lo fits, hi does not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if reach_cells(w, d, unit, mid / 1000)[0] >= h:
            lo = mid
        else:
            hi = mid
    most_h, cap = reach_cells(w, d, unit, lo / 1000)
    return Fit(yaw, lo / 1000, (w, d, h), most_h, cap)


def _fit_or_none(boxes: Sequence[tuple[int, int, int]], unit: float, limits: TargetLimits,
                 yaw: int | None) -> Fit | dict[int, list[tuple[str, str]]]:
    """The fit in `yaw`, or where None by the rule (module docstring): the file's orientation at
    x = STRUCTURE_X, the quarter turn there, the file's orientation moved, the quarter turn moved. Else
    what does not fit per yaw tried."""
    if yaw is not None:
        fit = _try(boxes, unit, limits, yaw)
        return fit if isinstance(fit, Fit) else {yaw: fit}
    tries = {y: _try(boxes, unit, limits, y) for y in (0, 90)}
    fits = [f for f in tries.values() if isinstance(f, Fit)]
    if not fits:
        return tries
    best = next((f for f in fits if not f.moved), fits[0])
    if best.yaw:
        reason = _turn_reason(tries[0], boxes) if not isinstance(tries[0], Fit) else \
            f'to stand at x = {STRUCTURE_X:g} m (the file\'s orientation fits only nearer the robot)'
        best = Fit(best.yaw, best.x, best.box, best.most_high, best.cap, reason)
    return best


def _turn_reason(problems, boxes) -> str:
    """Why a quarter turn: what did not fit in the file's orientation, and what it becomes."""
    w, d, h = _group(boxes, 0)
    w90, d90, _ = _group(boxes, 90)
    axes = {axis for axis, _ in problems} if isinstance(problems, list) else set()
    if 'y' in axes:
        return f'to fit the reach: {d} cells deep becomes {w90} wide'
    if 'x' in axes:
        return f'to fit the reach: {w} cells wide becomes {d90} deep'
    return 'to fit the reach'


def _culprit(boxes, unit: float, limits: TargetLimits, paths, yaw: int | None = None) -> tuple[str, tuple]:
    """Which to name in a refusal: the one file, or the first that does not fit alone, else all together."""
    if len(paths) == 1:
        return paths[0], boxes[0]
    for box, path in zip(boxes, paths):
        if not isinstance(_fit_or_none([box], unit, limits, yaw), Fit):
            return path, box
    return f'the {len(paths)} models together', _group(boxes, 0)


def _refusal(tried, where: str, what: str, boxes, unit: float, limits: TargetLimits, yaw: int | None,
             fix: str) -> RadError:
    """One line: what exceeds which limit in each yaw tried, what a target may span, and `fix`; for a
    given yaw where another fits, that yaw."""
    if yaw is not None:
        other = _fit_or_none(boxes, unit, limits, None)
        if isinstance(other, Fit):
            return RadError(f'{where}: {what}; at --yaw {yaw}: {"; ".join(t for _, t in tried[yaw])}: '
                            f'--yaw {other.yaw} fits, or leave --yaw out')
        tried = other
    texts = {y: ', '.join(t for _, t in p) for y, p in tried.items()}
    if len(set(texts.values())) == 1:
        why = next(iter(texts.values()))
    else:
        why = '; '.join(f'{"as in the file" if y == 0 else f"turned {y}"}: {t}' for y, t in texts.items())
    return RadError(f'{where}: {what} of {unit:g} m, too large for the arm in any yaw ({why}); a target may '
                    f'span {_dims(limits.cells(unit))} cells at x = {STRUCTURE_X:g} m ({_limits_text(limits)}): '
                    f'{fix}')


def _check_unit(unit: float) -> None:
    if not (isinstance(unit, (int, float)) and math.isfinite(unit) and 0.01 <= unit <= MAX_UNIT):
        raise RadError(f'--unit must be a cell edge in 0.01..{MAX_UNIT} m (the blocks\' cube edge, e.g. 0.05; '
                       f'the open hand takes cubes up to {MAX_UNIT} m), got {unit!r}')


def _check_fits(extents: np.ndarray, pitch: float, unit: float, limits: TargetLimits, paths, size, scale,
                yaw: int | None) -> Fit:
    """The fit of the models' boxes at this pitch (`fit_target`); refuse models that fit in no yaw
    naming the largest unit, a --size and a --scale that fit."""
    boxes = [tuple(int(v) for v in cell_counts(ext, pitch)) for ext in extents]
    fit = _fit_or_none(boxes, unit, limits, yaw)
    if isinstance(fit, Fit):
        return fit
    longest = float(extents.max())
    n_now = max(max(b) for b in boxes)
    n_fit = next((n for n in range(n_now, 0, -1)
                  if isinstance(_fit_or_none([tuple(int(v) for v in cell_counts(ext, longest / n))
                                              for ext in extents], unit, limits, yaw), Fit)), 1)
    best = largest_unit(boxes, unit, limits, yaw)
    given = f'--size {size}' if size is not None else f'--scale {scale:g}'
    fixes = [f'--size {n_fit} or less']
    if size is None:
        # --scale S gives the cells of --size n where S = unit * n / longest (mesh units).
        fixes.append(f'--scale {_round_down(unit * n_fit / max(longest, 1e-12))} or less')
    if best:
        fixes.append(f'--unit {best:.3f} or less' + (f' with --size {n_now}' if size is None else ' at this size'))
    where, counts = _culprit(boxes, unit, limits, paths, yaw)
    raise _refusal(fit, where, f'at {given} the model is {_dims(counts)} cells', boxes, unit, limits, yaw,
                   'use ' + ', or '.join(fixes))


def _check_total(models: Sequence[Model]) -> None:
    total = sum(int(np.prod(m.cells.shape)) for m in models)
    if total > MAX_GRID_CELLS:
        raise RadError(f'the regions\' boxes hold {total} cells, over the limit of {MAX_GRID_CELLS}: '
                       f'use smaller models')


def _round_down(x: float) -> str:
    """x rounded down to two significant figures, so the suggested scale really fits."""
    if x <= 0:
        return '0'
    digits = 1 - int(math.floor(math.log10(x)))
    return f'{math.floor(x * 10 ** digits) / 10 ** digits:.{max(digits, 0)}f}'


def _dims(shape) -> str:
    return ' x '.join(str(int(v)) for v in shape)


def _limits_text(limits: TargetLimits) -> str:
    return (f'{limits.max_width:g} x {limits.max_depth:g} m wide and deep within the arm\'s reach, as high as '
            f'its reach allows a footprint that large')


def _homogeneous(rotation: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rotation
    return out

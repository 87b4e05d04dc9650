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
`hollow` keeps the solid's shell (cells with a face towards the outside); where nothing is
enclosed it takes the cells the surface passes through ('surface').

Scale: `size` N makes the longest side of all the models together N cells (several
models keep their proportions); `scale` S says how many metres one mesh unit is (1 for a
model in metres, 0.001 for one in millimetres). A voxel file has one cell per voxel.

Orientation: `up` names the model's axis that points up (`x`, `y` or `z`; many modellers
and OBJ files use `y`); it is turned onto +z by a rotation, never a mirror.

Limits: a target must lie where the arm builds (`TargetLimits`); a model larger than that
is refused with the scale or size that would fit.
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
    """How large a target may be, in metres, for the arm to build all of it.

    The structure is centred on x = STRUCTURE_X (0.5 m) in front of the robot, so a width of
    0.40 m spans 0.30..0.70 m, the depth straddles y = 0; tops above max_height are out of a
    top-down placement's reach. The hand-made shapes stay within 0.30 x 0.20 x 0.30 m.
    """

    max_width: float = 0.40
    max_depth: float = 0.30
    max_height: float = 0.35

    def cells(self, unit: float) -> np.ndarray:
        """Most cells along x, y, z at this unit (also within a region's limit)."""
        m = np.floor(np.array([self.max_width, self.max_depth, self.max_height]) / unit + 1e-9)
        return np.minimum(m, MAX_REGION_AXIS).astype(int)


@dataclass(frozen=True)
class MeshReport:
    """What making one mesh's cells found and did (`solid_cells`).

    bodies: connected pieces of surface; open_edges: edges with one triangle on them as read
    (vertices repeated along texture seams count); open_after: those left after the repairs and
    the caps; repairs: what was changed, in words; method: 'contains', 'bodies', 'flood fill' or
    'surface' (the module docstring says which mesh gets which); cells: the filled cells.
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
        if self.open_edges == 0:
            state = f'{shells}, no open edge'
        elif self.open_after == self.open_edges:
            state = f'{shells}, {self.open_edges} open edges'
        else:
            state = f'{shells}, {self.open_edges} open edges ({self.open_after} after repairs)'
        repaired = f'; {", ".join(self.repairs)}' if self.repairs else ''
        return f'{self.cells} cells by {self.method}: {state}{repaired}'


@dataclass(frozen=True)
class Model:
    """One file's cells: a boolean occupancy grid [i, j, k], k up, cropped to its filled cells;
    for a mesh, the report of how they were made."""

    name: str
    path: str
    cells: np.ndarray
    report: MeshReport | None = None


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
    several, 'flood fill' for anything else. Hollow: the solid's shell, or where the surface
    encloses nothing, the cells it passes through. RadError (naming `where`) when a solid is asked
    and the surface encloses nothing.
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

    closed = False              # closed shells thinner than a cell have no cell centre inside: their surface's below
    if mesh.is_watertight:
        shells = mesh.split(only_watertight=False) if bodies > 1 else [mesh]
        closed = len(shells) == 1 or all(s.is_watertight for s in shells)
        if len(shells) == 1:
            inside = _contains(mesh, cell_centres(corner, counts, pitch)).reshape(tuple(counts))
            if inside.any():
                return done(inside, 'contains', 0)
        elif all(s.is_watertight for s in shells):
            inside = _inside_shells(shells, corner, counts, pitch)
            if inside.any():
                return done(inside, 'bodies', 0)
    triangles = mesh.triangles
    caps, holes, open_after = _hole_caps(mesh)
    if holes:
        repairs.append(f'capped {holes} hole{"s" if holes > 1 else ""}')
        triangles = np.concatenate([triangles, caps])
    sub = _sub_cells(counts)
    solid, surface, enclosed = _flood_fill(triangles, corner, counts, pitch, sub)
    if enclosed and solid.any():
        return done(solid, 'flood fill', open_after)
    thin = (enclosed or closed) and surface.any()
    if thin and not hollow:
        # Walls thinner than a cell (a tray, a channel): no cell centre is inside them, so the cells
        # the surface passes through stand for them, one cell thick.
        repairs.append('thinner than a cell: the cells its surface passes through')
    if thin or hollow:
        return done(surface, 'surface', open_after)
    raise RadError(f'{where}: the surface encloses no volume at {pitch:.4g} mesh units per cell (a gap wider than '
                   f'{pitch / sub:.3g} units, or a single sheet): give --hollow to take its surface only, or '
                   f'close it in a mesh editor')


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


def _hole_caps(mesh) -> tuple[np.ndarray, int, int]:
    """Triangles that close the mesh's holes, a fan from the centroid of every loop of open edges;
    the number of loops; and the open edges that no loop closes."""
    import networkx as nx  # trimesh's own dependency: only a mesh import pays for its import
    from trimesh import grouping  # trimesh: only a mesh import pays for its import
    boundary = mesh.edges_sorted[grouping.group_rows(mesh.edges_sorted, require_count=1)]
    if len(boundary) == 0:
        return np.zeros((0, 3, 3)), 0, 0
    loops = nx.cycle_basis(nx.from_edgelist(boundary.tolist()))
    if not loops:
        return np.zeros((0, 3, 3)), 0, len(boundary)
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
    return caps, len(loops), int(still_open.sum())


def _sub_cells(counts: np.ndarray) -> int:
    """Sub-cells per cell edge of the flood fill's grid: 4, 6 or 8 (even, so that eight meet at a cell's
    centre), the most that keep the longest side within about 128."""
    return int(np.clip(128 // int(np.max(counts)), 4, 8)) // 2 * 2


def _flood_fill(triangles: np.ndarray, corner: np.ndarray, counts: np.ndarray, pitch: float,
                sub: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """The solid cells by a flood fill of the outside (module docstring), the cells the surface passes
    through, and whether the surface encloses anything (a sub-cell neither outside nor on it)."""
    from scipy import ndimage  # scipy: only a mesh import pays for its import
    step = pitch / sub
    shape = tuple(int(c) * sub + 4 for c in counts)          # two empty sub-cells round the cells
    surface = _rasterize((triangles - (corner - 2 * step)) / step, shape)
    labels, _ = ndimage.label(~surface)                      # faces shared: six neighbours
    outside = labels == labels[0, 0, 0]
    inner = (slice(2, -2),) * 3
    on = surface[inner]
    enclosed = ~outside[inner] & ~on
    blocks = tuple(v for c in counts for v in (int(c), sub))
    middle = slice(sub // 2 - 1, sub // 2 + 1)                # the 2 x 2 x 2 sub-cells round a cell's centre
    weight = (enclosed.astype(np.float32) + 0.5 * on).reshape(blocks)
    centre = weight[:, middle, :, middle, :, middle].sum(axis=(1, 3, 5))
    solid = (centre > 4) | ((centre == 4) & (weight.sum(axis=(1, 3, 5)) >= 0.5 * sub ** 3))
    return solid, on.reshape(blocks).any(axis=(1, 3, 5)), bool(enclosed.any())


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

def mesh_models(files: Sequence[tuple[str, str]], unit: float, size: int | None = None, scale: float | None = None,
                up: str = 'z', hollow: bool = False, limits: TargetLimits = TargetLimits()) -> list[Model]:
    """Each (region name, mesh file) as a Model at one common pitch (see the module docstring)."""
    _check_up(up)
    _check_unit(unit)
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
    _check_fits(extents, pitch, unit, limits, [p for _, p, _ in meshes], size, scale)
    models = []
    for name, path, mesh in meshes:
        cells, report = solid_cells(mesh, pitch, hollow, where=path)
        cells = crop(cells)
        if not cells.any():
            raise RadError(f'{path}: no cell centre lies inside the model at {pitch:.4g} mesh units per cell '
                           f'(it is thinner than a cell): use a larger --size or --scale')
        models.append(Model(name, path, cells, report))
    _check_total(models)
    return models


def voxel_models(files: Sequence[tuple[str, str]], unit: float, up: str = 'z', hollow: bool = False,
                 limits: TargetLimits = TargetLimits()) -> list[Model]:
    """Each (region name, voxel file) as a Model, one cell per voxel."""
    _check_up(up)
    _check_unit(unit)
    models = []
    for name, path in files:
        grid = orient_cells(load_voxel_grid(path), up)
        if hollow:
            grid = shell(grid)
        grid = crop(grid)
        if not grid.any():
            raise RadError(f'{path}: the voxel grid is empty (no filled voxel)')
        most = limits.cells(unit)
        if np.any(np.array(grid.shape) > most):
            raise RadError(f'{path}: its filled voxels span {_dims(grid.shape)} cells; at unit {unit} m a target '
                           f'may span {_dims(most)} ({_limits_text(limits)}): use a smaller model or a smaller '
                           f'--unit')
        models.append(Model(name, path, grid))
    _check_total(models)
    return models


def place_regions(models: Sequence[Model], unit: float,
                  limits: TargetLimits = TargetLimits()) -> tuple[TargetRegion, ...]:
    """The models as regions back to back along y, the first at +y (the robot's left), the whole
    centred on (STRUCTURE_X, 0), each centred on x = STRUCTURE_X and resting on the table.

    Two one-cell-deep faces named left and right so land where the generator puts its two sides.
    """
    depth = sum(m.cells.shape[1] for m in models)
    most = limits.cells(unit)
    if depth > most[1]:
        raise RadError(f'the {len(models)} regions together are {depth} cells deep (y); at unit {unit} m a target '
                       f'may be {most[1]} ({_limits_text(limits)}): use fewer or thinner models')
    out, top = [], depth / 2
    for m in models:
        w, d, _ = m.cells.shape
        x0 = STRUCTURE_X - unit * (w - 1) / 2
        y0 = unit * (top - d + 0.5)
        top -= d
        origin = tuple(round(float(v), 6) for v in (x0, y0, unit / 2))
        filled = tuple(tuple(int(v) for v in c) for c in np.argwhere(m.cells))
        out.append(TargetRegion(m.name, origin, tuple(int(v) for v in m.cells.shape), filled))
    return tuple(out)


def _check_unit(unit: float) -> None:
    if not (isinstance(unit, (int, float)) and math.isfinite(unit) and 0.01 <= unit <= MAX_UNIT):
        raise RadError(f'--unit must be a cell edge in 0.01..{MAX_UNIT} m (the blocks\' cube edge, e.g. 0.05; '
                       f'the open hand takes cubes up to {MAX_UNIT} m), got {unit!r}')


def _check_fits(extents: np.ndarray, pitch: float, unit: float, limits: TargetLimits, paths, size, scale) -> None:
    """Refuse models beyond the limits, naming a --size and a --scale that fit."""
    most = limits.cells(unit)
    for ext, path in zip(extents, paths):
        counts = cell_counts(ext, pitch)
        if np.all(counts <= most):
            continue
        # Cells along axis a at scale S: ceil(ext_a * S / unit) <= most_a  <=>  S <= most_a * unit / ext_a.
        s_fit = float(np.min(most * unit / np.maximum(extents.max(axis=0), 1e-12)))
        longest = float(extents.max())
        n_fit = int(np.min(np.floor(most * longest / np.maximum(extents.max(axis=0), 1e-12) + 1e-9)))
        given = f'--size {size}' if size is not None else f'--scale {scale:g}'
        raise RadError(f'{path}: at {given} the model is {_dims(counts)} cells of {unit} m; a target may span '
                       f'{_dims(most)} ({_limits_text(limits)}): use --size {max(1, n_fit)} or less, '
                       f'or --scale {_round_down(s_fit)} or less')


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
    return (f'{limits.max_width:g} x {limits.max_depth:g} x {limits.max_height:g} m wide, deep and high '
            f'within the arm\'s reach')


def _homogeneous(rotation: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rotation
    return out

"""Targets from files (rad_core.domain.voxels): meshes and voxel grids give the cells they should,
placed where the arm builds, and bad files are errors that name the problem and the fix."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from rad_core.domain import voxels
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.shapes import STRUCTURE_X
from trimesh.exchange import binvox

UNIT = 0.05
MESHES = Path(__file__).resolve().parents[2] / 'data' / 'meshes'


def cells_of(grid) -> set:
    return {tuple(int(v) for v in c) for c in np.argwhere(grid)}


def save(mesh, path) -> str:
    mesh.export(path)
    return str(path)


def one(path, **kw) -> np.ndarray:
    return voxels.mesh_models([('m', str(path))], UNIT, **kw)[0].cells


# ---- voxelization ---------------------------------------------------------------

def test_a_cube_n_cells_long_gives_n_cubed_cells_not_n_plus_one(tmp_path):
    # Its faces lie on cell borders: a surface sampler would mark the cells on both sides.
    path = save(trimesh.creation.box(extents=(0.15, 0.15, 0.15)), tmp_path / 'cube.stl')
    grid = one(path, scale=1.0)
    assert grid.shape == (3, 3, 3) and grid.all()
    assert one(path, size=4).shape == (4, 4, 4) and one(path, size=4).all()
    hollow = one(path, scale=1.0, hollow=True)
    assert hollow.sum() == 26 and not hollow[1, 1, 1]


def test_an_l_gives_its_cells_at_any_mesh_scale(tmp_path):
    l_cells = np.zeros((3, 2, 3), dtype=bool)
    l_cells[:, :, 0] = True
    l_cells[0, :, :] = True
    for pitch, fmt in ((1.0, 'obj'), (25.0, 'ply'), (0.05, 'stl')):     # mesh units, mm, m
        path = save(voxels.cells_to_mesh(l_cells, pitch), tmp_path / f'l.{fmt}')
        got = one(path, size=3)
        assert got.shape == l_cells.shape and cells_of(got) == cells_of(l_cells), fmt
    # The same in metres at --scale 1: 0.05 m per cell is one cell each.
    assert cells_of(one(tmp_path / 'l.stl', scale=1.0)) == cells_of(l_cells)


def test_a_torus_like_ring_has_its_hole(tmp_path):
    ring = trimesh.creation.annulus(r_min=1.2, r_max=2.5, height=1.0, sections=64)
    grid = one(save(ring, tmp_path / 'ring.ply'), size=5)
    assert grid.shape == (5, 5, 1)
    # Cell centres at -2..2 around the axis: inside when 1.2 < distance < 2.5.
    expected = {(i, j, 0) for i in range(5) for j in range(5) if 1.2 < math.hypot(i - 2, j - 2) < 2.5}
    assert cells_of(grid) == expected
    assert not grid[2, 2, 0] and len(expected) == 16


def test_up_axis_turns_without_mirroring(tmp_path):
    # A chiral corner: x, y and z arms of different lengths.
    grid = np.zeros((3, 2, 4), dtype=bool)
    grid[:, 0, 0] = True
    grid[0, :, 0] = True
    grid[0, 0, :] = True
    z_up = voxels.cells_to_mesh(grid)
    for up in ('y', 'x'):
        turn = np.eye(4)
        turn[:3, :3] = voxels._UP[up].T            # as a modeller with that axis up would save it
        mesh = z_up.copy()
        mesh.apply_transform(turn)
        got = one(save(mesh, tmp_path / f'corner_{up}.stl'), size=4, up=up)
        assert cells_of(got) == cells_of(grid), up
        # A voxel grid saved that way reads back the same with the same --up.
        np.save(tmp_path / f'corner_{up}.npy', voxels.crop(_turn_cells(grid, voxels._UP[up].T)))
        back = voxels.voxel_models([('v', str(tmp_path / f'corner_{up}.npy'))], UNIT, up=up)[0].cells
        assert cells_of(back) == cells_of(grid), up


def _turn_cells(grid, rotation):
    idx = np.argwhere(grid) @ np.asarray(rotation).T.round().astype(int)
    idx -= idx.min(axis=0)
    out = np.zeros(idx.max(axis=0) + 1, dtype=bool)
    out[tuple(idx.T)] = True
    return out


def test_several_models_keep_their_proportions_with_size(tmp_path):
    big = save(trimesh.creation.box(extents=(4, 1, 2)), tmp_path / 'big.stl')
    small = save(trimesh.creation.box(extents=(2, 1, 1)), tmp_path / 'small.stl')
    models = voxels.mesh_models([('a', big), ('b', small)], UNIT, size=4)
    assert [m.cells.shape for m in models] == [(4, 1, 2), (2, 1, 1)]


# ---- voxel files --------------------------------------------------------------------

def test_npy_and_binvox_give_their_voxels_cropped_onto_the_table(tmp_path):
    grid = np.zeros((4, 4, 4), dtype=bool)
    grid[1, 1, 1:4] = True
    grid[2, 1, 1] = True
    expected = {(0, 0, 0), (0, 0, 1), (0, 0, 2), (1, 0, 0)}    # the empty layer under it is gone
    np.save(tmp_path / 'g.npy', grid)
    np.save(tmp_path / 'g_int.npy', grid.astype(np.uint8) * 7)
    (tmp_path / 'g.binvox').write_bytes(binvox.export_binvox(trimesh.voxel.VoxelGrid(grid)))
    for name in ('g.npy', 'g_int.npy', 'g.binvox'):
        cells = voxels.voxel_models([('v', str(tmp_path / name))], UNIT)[0].cells
        assert cells_of(cells) == expected, name


@pytest.mark.parametrize('array, problem', [
    (np.zeros((3, 3), dtype=bool), '3D array'),
    (np.zeros((2, 2, 2), dtype=float), 'dtype float64'),
    (np.zeros((2, 2, 2), dtype=bool), 'empty'),
])
def test_bad_voxel_arrays_are_refused_with_the_reason(tmp_path, array, problem):
    np.save(tmp_path / 'bad.npy', array)
    with pytest.raises(RadError, match=problem):
        voxels.voxel_models([('v', str(tmp_path / 'bad.npy'))], UNIT)


def test_an_object_array_is_not_unpickled(tmp_path):
    np.save(tmp_path / 'obj.npy', np.array([{'a': 1}], dtype=object), allow_pickle=True)
    with pytest.raises(RadError, match='not a readable .npy'):
        voxels.load_voxel_grid(str(tmp_path / 'obj.npy'))


def test_a_voxel_grid_too_large_names_the_limit(tmp_path):
    np.save(tmp_path / 'wide.npy', np.ones((12, 1, 1), dtype=bool))
    with pytest.raises(RadError, match=r'12 x 1 x 1 cells.*8 x 6 x 7'):
        voxels.voxel_models([('v', str(tmp_path / 'wide.npy'))], UNIT)
    # The same voxels fit at a smaller unit.
    assert voxels.voxel_models([('v', str(tmp_path / 'wide.npy'))], 0.03)[0].cells.shape == (12, 1, 1)


# ---- bad meshes -------------------------------------------------------------------

def test_an_open_mesh_is_closed_and_filled(tmp_path):
    box = trimesh.creation.box(extents=(0.15, 0.1, 0.1))
    box.update_faces(box.face_normals[:, 0] > -0.5)     # the side towards -x missing
    path = save(box, tmp_path / 'open.stl')
    model = voxels.mesh_models([('m', path)], UNIT, scale=1.0)[0]
    assert model.cells.shape == (3, 2, 2) and model.cells.all()
    assert model.report.method == 'flood fill' and model.report.repairs == ('capped 1 hole',)
    assert model.report.open_edges == 4 and model.report.open_after == 0
    surface = one(path, scale=1.0, hollow=True)
    assert surface.shape == (3, 2, 2) and surface.all()      # every cell has a face outside


@pytest.mark.parametrize('name, content, problem', [
    ('model.fbx', b'x', "unknown mesh format '.fbx'"),
    ('model.npy', b'x', r"\.npy is read by rad scene from-voxels"),
    ('model.stl', b'', 'no triangles|not a readable'),
    ('model.obj', b'this is not a mesh\n', 'no triangles|not a readable'),
    ('model.ply', b'ply\nformat nonsense\n', 'not a readable|no triangles'),
])
def test_unreadable_files_name_the_file_and_the_problem(tmp_path, name, content, problem):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(RadError, match=problem) as e:
        one(path)
    assert str(path) in str(e.value)


def test_a_missing_file_and_a_flat_mesh(tmp_path):
    with pytest.raises(RadError, match='no such file'):
        one(tmp_path / 'nothing.stl')
    flat = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    with pytest.raises(RadError, match='flat'):
        one(save(flat, tmp_path / 'flat.stl'))


def test_walls_thinner_than_a_cell_become_the_cells_their_surface_passes_through(tmp_path):
    """A thin ring (a tube's wall, 0.1 of 5 units thick): no cell centre lies inside it, so the cells
    its surface passes through stand for it, said in the report; the hole in the middle stays empty."""
    thin = trimesh.creation.annulus(r_min=2.4, r_max=2.5, height=1.0, sections=64)
    [model] = voxels.mesh_models([('m', save(thin, tmp_path / 'thin.stl'))], UNIT, size=5)
    assert model.report.method == 'surface' and 'thinner than a cell' in model.report.summary()
    ring = model.cells.any(axis=2)
    assert ring.shape == (5, 5) and ring[0, 2] and ring[4, 2] and ring[2, 0] and ring[2, 4]
    assert not ring[2, 2]                   # the middle of the ring is not part of it


def test_too_large_names_a_size_and_a_scale_that_fit(tmp_path):
    path = save(trimesh.creation.box(extents=(1.0, 0.2, 0.3)), tmp_path / 'wall.stl')     # 20 x 4 x 6 cells
    with pytest.raises(RadError) as e:
        one(path, scale=1.0)
    message = str(e.value)
    assert '20 x 4 x 6 cells' in message
    size = int(re.search(r'--size (\d+) or less', message).group(1))
    scale = float(re.search(r'--scale ([0-9.]+) or less', message).group(1))
    assert one(path, size=size).shape[0] == size          # what it suggests does fit
    assert one(path, scale=scale).shape[0] <= 8
    with pytest.raises(RadError, match='too large|cells of'):
        one(path, size=size + 1)


def test_bad_flags(tmp_path):
    path = save(trimesh.creation.box(extents=(0.1, 0.1, 0.1)), tmp_path / 'c.stl')
    for kw, problem in (({'size': 2, 'scale': 1.0}, 'not both'), ({'size': 0}, '--size'),
                        ({'scale': -1.0}, '--scale'), ({'up': 'w'}, 'up axis')):
        with pytest.raises(RadError, match=problem):
            one(path, **kw)
    with pytest.raises(RadError, match='--unit'):
        voxels.mesh_models([('m', path)], 0.5)


# ---- regions ---------------------------------------------------------------------------

def test_two_faces_land_where_the_generator_puts_its_two_sides():
    face = np.ones((4, 1, 3), dtype=bool)
    regions = voxels.place_regions([voxels.Model('left', '', face), voxels.Model('right', '', face)], UNIT)
    left, right = regions
    assert left.origin == pytest.approx((STRUCTURE_X - 1.5 * UNIT, UNIT / 2, UNIT / 2))
    assert right.origin == pytest.approx((STRUCTURE_X - 1.5 * UNIT, -UNIT / 2, UNIT / 2))
    # A valid scene: regions back to back, not overlapping, resting on the table.
    scene = Scene.from_dict({'format': 'rad-scene/1', 'unit': UNIT, 'block_types': {'cube': [[0, 0, 0]]},
                             'blocks': [], 'targets': [t.to_dict() for t in regions]})
    assert scene.num_target_cells == 24


def test_region_names_from_files_or_given_and_never_twice():
    assert voxels.region_names(['a/arch.stl', 'deck=b/arch.stl']) == [('arch', 'a/arch.stl'), ('deck', 'b/arch.stl')]
    with pytest.raises(RadError, match="named 'arch'"):
        voxels.region_names(['a/arch.stl', 'b/arch.stl'])


def test_cells_to_mesh_is_closed_and_encloses_its_cells():
    grid = np.zeros((3, 3, 2), dtype=bool)
    grid[:, :, 0] = True
    grid[1, 1, 1] = True
    mesh = voxels.cells_to_mesh(grid, 0.5)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(grid.sum() * 0.125)


# ---- imperfect meshes -------------------------------------------------------------

def boxes(*corners, unit=UNIT) -> trimesh.Trimesh:
    """Closed boxes from (lo, hi) cell corners, one mesh of several bodies."""
    return trimesh.util.concatenate([trimesh.creation.box(bounds=np.array(c, dtype=float) * unit) for c in corners])


def model(path, **kw):
    return voxels.mesh_models([('m', str(path))], UNIT, **kw)[0]


ARCH = {(0, 0, 0), (0, 0, 1), (0, 0, 2), (1, 0, 2), (2, 0, 0), (2, 0, 1), (2, 0, 2)}


def test_a_closed_shell_keeps_the_centre_rule(tmp_path):
    # Sides of 3.4, 2.6 and 1.5 cells: the cells whose centres are inside, 3 x 3 x 1 or 2 by rounding.
    got = model(save(trimesh.creation.box(extents=(0.17, 0.13, 0.075)), tmp_path / 'box.stl'), scale=1.0)
    assert got.report.method == 'contains' and got.report.repairs == ()
    lo = -np.array([4, 3, 2]) * UNIT / 2
    centres = voxels.cell_centres(lo, np.array([4, 3, 2]), UNIT)
    inside = np.all(np.abs(centres) < np.array([0.17, 0.13, 0.075]) / 2, axis=1).reshape(4, 3, 2)
    assert cells_of(got.cells) == cells_of(voxels.crop(inside))


def test_three_closed_boxes_that_touch_give_the_arch(tmp_path):
    # Two posts and a lintel as separate bodies, as CAD exports them: edges on four triangles.
    arch = boxes([(0, 0, 0), (1, 1, 2)], [(2, 0, 0), (3, 1, 2)], [(0, 0, 2), (3, 1, 3)])
    for name in ('arch.stl', 'arch.obj', 'arch.ply'):
        got = model(save(arch, tmp_path / name), scale=1.0)
        assert cells_of(got.cells) == ARCH, name
        assert got.report.method == 'flood fill' and got.report.open_edges == 0


def test_a_glb_scene_of_several_parts_is_one_model(tmp_path):
    parts = [trimesh.creation.box(bounds=np.array(c, dtype=float) * UNIT)
             for c in ([(0, 0, 0), (1, 1, 2)], [(2, 0, 0), (3, 1, 2)], [(0, 0, 2), (3, 1, 3)])]
    path = tmp_path / 'arch.glb'
    trimesh.Scene(parts).export(path)
    assert cells_of(model(path, scale=1.0).cells) == ARCH
    save(trimesh.creation.box(extents=(0.15, 0.1, 0.1)), tmp_path / 'box.off')
    assert model(tmp_path / 'box.off', scale=1.0).cells.shape == (3, 2, 2)


def test_flipped_normals_give_the_same_cells(tmp_path):
    l_cells = np.zeros((3, 2, 3), dtype=bool)
    l_cells[:, :, 0] = True
    l_cells[0, :, :] = True
    mesh = voxels.cells_to_mesh(l_cells, UNIT)
    inverted = mesh.copy()
    inverted.invert()
    mixed = trimesh.Trimesh(mesh.vertices, np.where(np.arange(len(mesh.faces))[:, None] % 3 == 0,
                                                    mesh.faces[:, ::-1], mesh.faces), process=False)
    for name, m in (('inverted', inverted), ('mixed', mixed)):
        got = model(save(m, tmp_path / f'{name}.stl'), scale=1.0)
        assert cells_of(got.cells) == cells_of(l_cells), name
    # Several shells, one of them inside out, still all count.
    two = boxes([(0, 0, 0), (1, 1, 1)], [(2, 0, 0), (3, 1, 1)])
    faces = two.faces.copy()
    faces[:12] = faces[:12, ::-1]
    got = model(save(trimesh.Trimesh(two.vertices, faces, process=False), tmp_path / 'two.ply'), scale=1.0)
    assert cells_of(got.cells) == {(0, 0, 0), (2, 0, 0)} and got.report.method == 'bodies'


def test_overlapping_shells_give_their_union_and_an_inner_shell_facing_in_a_cavity(tmp_path):
    # Two closed bars crossing: the ray-parity rule alone would leave their overlap empty.
    cross = boxes([(0, 1, 0), (3, 2, 1)], [(1, 0, 0), (2, 3, 1)])
    got = model(save(cross, tmp_path / 'cross.stl'), scale=1.0)
    assert got.report.method == 'bodies' and got.report.bodies == 2
    assert cells_of(got.cells) == {(1, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0), (1, 2, 0)}
    hollow_cube = boxes([(0, 0, 0), (3, 3, 3)])
    inner = boxes([(1, 1, 1), (2, 2, 2)])
    inner.invert()
    got = model(save(trimesh.util.concatenate([hollow_cube, inner]), tmp_path / 'cavity.ply'), scale=1.0)
    assert got.cells.sum() == 26 and not got.cells[1, 1, 1]


def test_a_sheet_and_a_tilted_plane_are_refused_with_the_reason(tmp_path):
    tilted = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 1], [1, 1, 1], [0, 1, 0]], faces=[[0, 1, 2], [0, 2, 3]])
    with pytest.raises(RadError, match='flat.*one plane.*thickness'):
        one(save(tilted, tmp_path / 'tilted.obj'), size=4)
    # A gently waved sheet: open along its whole rim, it encloses nothing a cell could see.
    x, y = np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 1, 9), indexing='ij')
    points = np.stack([x.ravel(), y.ravel(), 0.01 * np.sin(6 * x.ravel())], axis=1)
    idx = np.arange(81).reshape(9, 9)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    sheet = trimesh.Trimesh(points, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
    path = save(sheet, tmp_path / 'sheet.ply')
    with pytest.raises(RadError, match=r'encloses no volume.*--hollow') as e:
        one(path, size=4)
    assert '\n' not in str(e.value)
    surface = model(path, size=4, hollow=True)
    assert surface.report.method == 'surface' and surface.cells.shape == (4, 4, 1) and surface.cells.all()


def panel_box(n: int, gap: float) -> trimesh.Trimesh:
    """The six faces of a box n cells a side (UNIT) as separate sheets, each pushed out by `gap` cells: a CAD
    export whose panels do not meet. Every panel's rim is a loop (capped onto the panel itself), so only
    the gaps at the box's edges let the outside in."""
    box = voxels.cells_to_mesh(np.ones((n, n, n), dtype=bool))
    panels = []
    for axis in range(3):
        for side in (0, n):
            panel = box.triangles[np.all(np.isclose(box.triangles[:, :, axis], side), axis=1)].copy()
            panel[:, :, axis] += gap if side else -gap
            panels.append(panel)
    corners = np.concatenate(panels).reshape(-1, 3) * UNIT
    return trimesh.Trimesh(corners, np.arange(len(corners)).reshape(-1, 3))


def test_a_box_of_panels_that_do_not_meet_has_its_gaps_closed(tmp_path):
    # Gaps of 0.6 cells (3.7 sub-cells at size 4) at every edge: the flood fill's outside leaks in.
    path = save(panel_box(4, 0.6), tmp_path / 'panels.stl')
    got = model(path, size=4)
    assert got.report.method == 'closed gaps' and got.cells.shape == (4, 4, 4) and got.cells.all()
    closed = [r for r in got.report.repairs if r.startswith('closed gaps up to about ')]
    width, cells = re.match(r'closed gaps up to about ([0-9.]+) mesh units wide \(([0-9.]+) cells\)',
                            closed[0]).groups()
    pitch = 5.2 * UNIT / 4                                                  # the panels span 5.2 cells
    assert 0.6 * UNIT < float(width) <= pitch and float(cells) == pytest.approx(float(width) / pitch, abs=0.01)
    assert 'closed gaps' in got.report.summary()
    hollow = model(path, size=4, hollow=True)
    assert hollow.report.method == 'closed gaps' and hollow.cells.sum() == 56 and not hollow.cells[1:3, 1:3, 1:3].any()
    # Gaps of 2.4 cells at size 8: wider than the closing's two cells, the panels are left apart.
    with pytest.raises(RadError, match=r'encloses no volume .* even with its gaps up to about [0-9.]+ units wide'):
        voxels.mesh_models([('m', save(panel_box(4, 3.0), tmp_path / 'apart.stl'))], 0.03, size=8)


def test_an_open_sheet_is_refused_even_with_its_gaps_closed(tmp_path):
    # A gently waved sheet, as it is and tilted (its sub-cells a staircase whose corners a closing fills): thickened
    # and thinned again it is still a sheet, at any size.
    x, y = np.meshgrid(np.linspace(0, 1, 33), np.linspace(0, 1, 33), indexing='ij')
    idx = np.arange(33 * 33).reshape(33, 33)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    points = np.stack([x.ravel(), y.ravel(), 0.01 * np.sin(2 * np.pi * x.ravel())], axis=1)
    for about_y, about_x in ((0, 0), (30, 15)):
        sheet = trimesh.Trimesh(points, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
        sheet.apply_transform(trimesh.transformations.rotation_matrix(math.radians(about_y), [0, 1, 0]))
        sheet.apply_transform(trimesh.transformations.rotation_matrix(math.radians(about_x), [1, 0, 0]))
        path = save(sheet, tmp_path / f'sheet_{about_y}.ply')
        for size in (4, 6, 8):
            with pytest.raises(RadError, match=r'encloses no volume .* even with its gaps up to about .* closed '
                                               r'\(a gap wider than that, or a single sheet\): give --hollow'):
                voxels.mesh_models([('m', path)], 0.03, size=size)
            [surface] = voxels.mesh_models([('m', path)], 0.03, size=size, hollow=True)
            assert surface.report.method == 'surface' and surface.cells.any()


def test_thin_parts_that_share_edges_or_have_hairline_cracks_give_their_surface(tmp_path):
    # An L bracket of two plates 0.3 cells thick that share an edge (on four triangles, so not watertight):
    # no cell centre is inside either, and the flood fill finds nothing between their walls.
    bracket = boxes([(0, 0, 0), (4, 1, 0.3)], [(0, 0, 0.3), (0.3, 1, 3)])
    got = model(save(bracket, tmp_path / 'bracket.ply'), scale=1.0)
    assert got.report.method == 'surface' and got.report.open_edges == 0
    assert cells_of(got.cells) == {(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 0, 1), (0, 0, 2)}
    # A thin ring (as in the test above) with a T-junction: an edge split on one side only, a crack of no width.
    ring = trimesh.creation.annulus(r_min=2.4, r_max=2.5, height=1.0, sections=64)
    a, b, c = ring.faces[0]
    vertices = np.vstack([ring.vertices, (ring.vertices[a] + ring.vertices[b]) / 2])
    m = len(ring.vertices)
    cracked = trimesh.Trimesh(vertices, np.vstack([[[a, m, c], [m, b, c]], ring.faces[1:]]), process=False)
    got = model(save(cracked, tmp_path / 'cracked.ply'), size=5)
    assert got.report.method == 'surface' and got.report.open_after == 0 and 'capped 1 hole' in got.report.repairs
    ring_cells = got.cells.any(axis=2)
    assert ring_cells[0, 2] and ring_cells[4, 2] and not ring_cells[2, 2]


def test_the_report_says_what_was_done_in_one_line(tmp_path):
    box = trimesh.creation.box(extents=(0.15, 0.1, 0.1))
    box.update_faces(box.face_normals[:, 2] < 0.5)      # no top
    line = model(save(box, tmp_path / 'open.stl'), scale=1.0).report.summary()
    assert line.startswith('12 cells by ') and '4 open edges (0 after repairs)' in line and '\n' not in line


def _pybullet(name):
    pybullet_data = pytest.importorskip('pybullet_data')
    from pathlib import Path
    return Path(pybullet_data.getDataPath()) / name


def test_pybullet_duck_gives_a_solid(tmp_path):
    # 332 open edges as read: a texture seam repeats its vertices; merged, the shell is closed.
    got = model(_pybullet('duck.obj'), size=6, up='y')
    assert got.report.open_edges == 332 and got.report.open_after == 0
    assert got.cells.sum() > 0.3 * got.cells.size                 # a solid, not a shell


def test_pybullet_lego_brick_gives_its_walls(tmp_path):
    # A brick like the real one: hollow underneath, sixteen bodies, 2 open edges. At 24 cells its walls
    # are a cell thick; at 6 only its corners are left.
    mesh = voxels.load_mesh(str(_pybullet('lego/lego.obj')))
    mesh.apply_transform(voxels._homogeneous(voxels._UP['y']))
    grid, report = voxels.solid_cells(mesh, float(mesh.extents.max()) / 24)
    assert report.method == 'flood fill' and report.open_edges == 2 and 'capped 2 holes' in report.repairs
    layers = grid.sum(axis=(0, 1))
    assert layers.max() == 24 * 24 and layers[:10].max() < 0.25 * 24 * 24   # a closed top on walls and a tube
    assert not grid[6, 6, 3]                                                # inside the hollow
    assert model(_pybullet('lego/lego.obj'), size=6, up='y').cells.any()


def test_pybullet_meshes_of_thin_parts_and_gaps_give_targets(tmp_path):
    # A rail frame of bars thinner than a cell, closed shells that touch: the cells its surface passes through.
    def at_size_8(name):
        return voxels.mesh_models([('m', str(_pybullet(name)))], 0.03, size=8)[0]

    rail = at_size_8('husky/meshes/user_rail.stl')
    assert rail.report.method == 'surface' and rail.cells.shape == (8, 7, 1)
    assert not rail.cells[2:6, 2:5].any()                              # a frame, not a plate
    # A shelf pod whose fabric bins have cracks that no loop of open edges bounds: closed, the bins are solid.
    pod = at_size_8('kiva_shelf/meshes/pod_lowres.stl')
    assert pod.report.method == 'closed gaps' and pod.report.open_after > 0
    assert pod.cells.sum() >= 0.9 * pod.cells.size and pod.cells.shape[1] >= 5
    # A height field is a single sheet: still refused.
    with pytest.raises(RadError, match='encloses no volume .* closed'):
        at_size_8('terrain.obj')


# ---- fit: yaw, place, height, refusal -------------------------------------------------

def box_npy(tmp_path, shape, name='box') -> str:
    path = tmp_path / f'{name}.npy'
    np.save(path, np.ones(shape, dtype=bool))
    return str(path)


def test_a_4_by_17_box_is_turned_a_quarter_to_fit_and_the_report_says_so(tmp_path):
    # 17 cells deep exceed the 15 the reach allows across y = 0 at 2 cm; 17 wide fit (20).
    path = save(trimesh.creation.box(extents=(0.08, 0.34, 0.06)), tmp_path / 'slab.stl')
    [model] = voxels.mesh_models([('m', path)], 0.02, scale=1.0)
    assert model.yaw == 90 and model.cells.shape == (17, 4, 3) and model.cells.all()
    line = voxels.fit_report([model], 0.02)
    assert 'turned 90 degrees to fit the reach: 17 cells deep becomes 17 wide' in line
    assert 'x = 0.5 m' in line
    [region] = voxels.place_regions([model], 0.02)
    assert region.size == (17, 4, 3) and region.origin[0] == pytest.approx(STRUCTURE_X - 0.02 * 8)
    # A voxel grid is turned the same way, by a rotation (counter-clockwise seen from above).
    grid = np.zeros((4, 17, 3), dtype=bool)
    grid[:, :, 0] = True
    grid[0, 0, :] = True                    # a post on the floor's corner (0, 0)
    np.save(tmp_path / 'slab.npy', grid)
    [turned] = voxels.voxel_models([('v', str(tmp_path / 'slab.npy'))], 0.02)
    assert turned.yaw == 90 and np.array_equal(turned.cells, np.rot90(grid, 1, axes=(0, 1)))
    assert turned.cells[16, 0, 2] and not turned.cells[0, 0, 2]       # (i, j) -> (16 - j, i)


def test_a_fixed_yaw_that_does_not_fit_is_refused_naming_the_one_that_does(tmp_path):
    path = save(trimesh.creation.box(extents=(0.08, 0.34, 0.06)), tmp_path / 'slab.stl')
    with pytest.raises(RadError, match=r'at --yaw 0: 17 cells deep \(y\), 15 fit.*--yaw 90 fits') as e:
        voxels.mesh_models([('m', path)], 0.02, scale=1.0, yaw=0)
    assert '\n' not in str(e.value)
    assert voxels.mesh_models([('m', path)], 0.02, scale=1.0, yaw=270)[0].cells.shape == (17, 4, 3)
    with pytest.raises(RadError, match='--yaw must be one of 0, 90, 180, 270'):
        voxels.mesh_models([('m', path)], 0.02, scale=1.0, yaw=45)


def test_a_yaw_of_180_turns_without_mirroring(tmp_path):
    grid = np.zeros((3, 2, 1), dtype=bool)
    grid[0, 0, 0] = grid[1, 0, 0] = grid[2, 0, 0] = grid[0, 1, 0] = True      # an L
    np.save(tmp_path / 'l.npy', grid)
    [model] = voxels.voxel_models([('v', str(tmp_path / 'l.npy'))], UNIT, yaw=180)
    assert model.yaw == 180 and cells_of(model.cells) == {(0, 1, 0), (1, 1, 0), (2, 1, 0), (2, 0, 0)}
    assert 'turned 180 degrees (--yaw)' in voxels.fit_report([model], UNIT, given_yaw=True)


def test_a_target_that_fits_no_yaw_names_the_largest_unit_that_fits(tmp_path):
    # 22 x 17 cells: 22 wide exceed 20 and 17 deep exceed 15 at 2 cm; turned, 22 deep exceed 15.
    path = box_npy(tmp_path, (22, 17, 3))
    with pytest.raises(RadError) as e:
        voxels.voxel_models([('v', path)], 0.02)
    message = str(e.value)
    assert '\n' not in message and 'in any yaw' in message and '22 cells wide (x), 20 fit' in message
    unit = float(re.search(r'--unit ([0-9.]+) or less', message).group(1))
    assert unit == 0.017
    assert voxels.voxel_models([('v', path)], unit)[0].cells.shape == (22, 17, 3)   # it does fit there
    with pytest.raises(RadError, match='in any yaw'):
        voxels.voxel_models([('v', path)], unit + 0.001)
    # A mesh at --size: the largest unit at that size and the --size that fits at the unit given.
    mesh = save(trimesh.creation.box(extents=(0.44, 0.34, 0.06)), tmp_path / 'slab.stl')
    with pytest.raises(RadError) as e:
        voxels.mesh_models([('m', mesh)], 0.02, size=22)
    message = str(e.value)
    unit = float(re.search(r'--unit ([0-9.]+) or less at this size', message).group(1))
    size = int(re.search(r'--size (\d+) or less', message).group(1))
    assert voxels.mesh_models([('m', mesh)], unit, size=22)[0].cells.shape == (22, 17, 3)
    assert voxels.mesh_models([('m', mesh)], 0.02, size=size)[0].cells.shape[0] == size
    with pytest.raises(RadError, match='in any yaw'):
        voxels.mesh_models([('m', mesh)], 0.02, size=size + 1)


def test_more_cells_a_side_than_a_region_holds_fit_no_unit(tmp_path):
    with pytest.raises(RadError, match=r"25 cells wide \(x\), 24 fit \(a region's 24 cells a side\).*no unit"):
        voxels.voxel_models([('v', box_npy(tmp_path, (25, 1, 1)))], 0.01)


def test_the_gallery_meshes_keep_the_file_orientation_and_x_05(tmp_path):
    # As before the fit existed: yaw 0, the region centred on x = STRUCTURE_X (scenes byte for byte the same).
    gallery = json.loads(MESHES.joinpath('meshes.json').read_text())
    for name, entry in gallery.items():
        models = voxels.mesh_models([(name, str(MESHES / entry['file']))], UNIT, size=entry['size'], up=entry['up'])
        [region] = voxels.place_regions(models, UNIT)
        w, d, _ = models[0].cells.shape
        assert models[0].yaw == 0, name
        assert region.origin == pytest.approx((STRUCTURE_X - UNIT * (w - 1) / 2, -UNIT * (d - 1) / 2, UNIT / 2)), name
        assert 'x = 0.5 m, y = 0, as in the file' in voxels.fit_report(models, UNIT), name


def test_a_tall_thin_tower_is_as_high_as_the_reach_allows(tmp_path):
    # At 2 cm: 22 cells (0.44 m) stand at x = 0.5 m; the old fixed limit was 17.
    [tower] = voxels.voxel_models([('t', box_npy(tmp_path, (2, 2, 22)))], 0.02)
    assert tower.yaw == 0 and voxels.placement([tower], 0.02).x == STRUCTURE_X
    # 24 cells is a region's limit, whatever the reach: it says so.
    with pytest.raises(RadError, match=r"25 cells high \(z\), 24 fit \(a region's 24 cells a side"):
        voxels.voxel_models([('t', box_npy(tmp_path, (2, 2, 25)))], 0.02)
    # At 5 cm: 12 cells stand only nearer the robot; it moves there and says so.
    [tall] = voxels.voxel_models([('t', box_npy(tmp_path, (2, 2, 12)))], UNIT)
    fit = voxels.placement([tall], UNIT)
    assert fit.moved and voxels.TargetLimits().nearest_x + UNIT <= fit.x < STRUCTURE_X
    assert voxels.reach_cells(2, 2, UNIT, fit.x)[0] >= 12 > voxels.reach_cells(2, 2, UNIT, fit.x + 0.001)[0]
    [region] = voxels.place_regions([tall], UNIT)
    assert region.origin[0] == pytest.approx(fit.x - UNIT / 2)
    assert 'nearer the robot' in voxels.fit_report([tall], UNIT)
    # 14 cells fit nowhere in the area: the reach is named, and the unit that fits.
    with pytest.raises(RadError, match=r"14 cells high \(z\), 13 fit \(the arm's top-down reach.*--unit 0.04"):
        voxels.voxel_models([('t', box_npy(tmp_path, (2, 2, 14)))], UNIT)


def test_whatever_fitted_the_fixed_limits_still_fits_at_x_05():
    # The limits before the reach: 0.40 x 0.30 x 0.35 m, and at most 24 cells a side.
    limits = voxels.TargetLimits()
    for mm in range(10, 71):
        unit = mm / 1000
        old = [min(int(math.floor(m / unit + 1e-9)), 24) for m in (0.40, 0.30, 0.35)]
        if old[0] * old[1] * old[2] > 4096:
            old[2] = 4096 // (old[0] * old[1])
        fit = voxels.fit_target([tuple(old)], unit, limits)
        assert fit.yaw == 0 and fit.x == STRUCTURE_X, unit


def test_the_reach_numbers_are_the_arm_s():
    from rad_core.gamp.grasps import GRASP_BELOW_TOP
    from rad_core.gamp.ik import SHOULDER
    from rad_core.gamp.planner import GampConfig
    from rad_core.sim.workspace import Workspace
    assert voxels.SHOULDER_Z == SHOULDER[2] and voxels.APPROACH == GampConfig().approach_height
    assert voxels.GRASP_BELOW_TOP == GRASP_BELOW_TOP and voxels.WORKSPACE_TOP == Workspace().upper[2]


def test_the_top_down_reach_is_within_what_the_ik_solves():
    # What `top_down_reach` promises the IK reaches, hand pointing down, across the area targets
    # stand in; and 5 cm higher it no longer does (the model is not far inside the real reach).
    from rad_core.gamp.ik import IkConfig, solve_top_down
    from rad_core.sim.world import World
    world, config = World(), IkConfig(random_seeds=8)

    def reaches(x, y, z):
        return any(solve_top_down(world, (x, y, z), yaw, config=config).ok for yaw in (0.0, math.pi / 2))

    for x, y in ((0.3, 0.0), (0.5, 0.0), (0.7, 0.0), (0.3, 0.15), (0.5, 0.15), (0.7, 0.15)):
        z = voxels.top_down_reach(math.hypot(x, y))
        assert reaches(x, y, z), (x, y, z)
        assert not reaches(x, y, z + 0.05), (x, y, z)

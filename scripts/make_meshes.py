"""Make the gallery's meshes: self-made shapes in data/meshes/ (STL, OBJ and PLY mixed).

    python scripts/make_meshes.py [--out data/meshes]

Each shape is drawn here, without booleans: an outline in the x-z plane extruded along y
(the arch with its round opening, the house's gable, letters, stairs, a bridge), a set of
cells' closed surface (`rad_core.domain.voxels.cells_to_mesh`: the chair, the step pyramid), or
a trimesh primitive (the ring, the column, the spire). Files are written in the units a user's
would be in (millimetres for some, so --scale 0.001 reads them in metres) and some with y up,
as OBJ files often are. meshes.json beside them lists each file with the `rad scene from-mesh`
flags the gallery uses (benchmarks/bench_gallery.py reads it) and what the shape tests.
The output is deterministic: running the script again rewrites the same files.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import trimesh
from rad_core.domain.voxels import _UP, cells_to_mesh


def triangulate(outline: np.ndarray) -> np.ndarray:
    """Triangles (indices) of a simple polygon given counter-clockwise, by ear clipping."""
    pts = np.asarray(outline, dtype=float)
    left = list(range(len(pts)))
    out = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    while len(left) > 3:
        for n in range(len(left)):
            i, j, k = left[n - 1], left[n], left[(n + 1) % len(left)]
            a, b, c = pts[i], pts[j], pts[k]
            if cross(a, b, c) <= 1e-12:
                continue                       # a reflex (or straight) corner is no ear
            others = [pts[m] for m in left if m not in (i, j, k)]
            if any(cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0 for p in others):
                continue                       # another corner lies in the triangle
            out.append((i, j, k))
            left.pop(n)
            break
        else:
            raise ValueError('the outline is not a simple counter-clockwise polygon')
    out.append(tuple(left))
    return np.asarray(out)


def extruded(outline, depth: float) -> trimesh.Trimesh:
    """The outline (x, z points, counter-clockwise) extruded `depth` along y, from y = 0 to -depth."""
    outline = np.asarray(outline, dtype=float)
    about_x = np.eye(4)
    about_x[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]     # (u, v, w) -> (u, -w, v): v up, w into -y
    mesh = trimesh.creation.extrude_triangulation(outline, triangulate(outline), depth, transform=about_x)
    mesh.merge_vertices()
    return mesh


def arc(centre, radius: float, start_deg: float, stop_deg: float, n: int) -> list:
    return [(centre[0] + radius * np.cos(np.radians(a)), centre[1] + radius * np.sin(np.radians(a)))
            for a in np.linspace(start_deg, stop_deg, n)]


def letter(rows: list[str]) -> np.ndarray:
    """Cells [x, 0, z] of a letter drawn as text, top row first."""
    h, w = len(rows), max(len(r) for r in rows)
    grid = np.zeros((w, 1, h), dtype=bool)
    for r, row in enumerate(rows):
        for i, ch in enumerate(row):
            grid[i, 0, h - 1 - r] = ch == '#'
    return grid


def chair() -> np.ndarray:
    """Four legs two cells high, a 3 x 3 seat, a back two cells high along its +y edge."""
    g = np.zeros((3, 3, 5), dtype=bool)
    for x in (0, 2):
        for y in (0, 2):
            g[x, y, 0:2] = True
    g[:, :, 2] = True
    g[:, 2, 3:5] = True
    return g


def step_pyramid() -> np.ndarray:
    g = np.zeros((5, 5, 3), dtype=bool)
    g[:, :, 0] = True
    g[1:4, 1:4, 1] = True
    g[2, 2, 2] = True
    return g


def shapes() -> dict[str, tuple[trimesh.Trimesh, dict]]:
    """name -> (mesh with z up, in its file's units; how the gallery reads it and why it is there)."""
    mm = 50.0                                     # one 5 cm cell in millimetres
    arch_outline = [(0, 0), (1, 0), (1, 1.5)] + arc((2.5, 1.5), 1.5, 180, 0, 17)[1:-1] + \
        [(4, 1.5), (4, 0), (5, 0), (5, 4), (0, 4)]
    house = [(0, 0), (4, 0), (4, 2), (2, 3.6), (0, 2)]
    bridge = [(0, 2), (1, 2), (1, 0), (2, 0), (2, 2), (4, 2), (4, 0), (5, 0), (5, 2), (6, 2), (6, 3), (0, 3)]
    stairs = [(0, 0), (4, 0), (4, 4), (3, 4), (3, 3), (2, 3), (2, 2), (1, 2), (1, 1), (0, 1)]
    out = {
        'arch': (extruded(np.array(arch_outline) * mm, 2 * mm),
                 {'size': 5, 'why': 'a round opening three cells wide under a deck: spans need scaffolds'}),
        'bridge': (extruded(bridge, 2), {'size': 6, 'up': 'y', 'why': 'a deck on two piers, cantilevered at both '
                                                                       'ends; drawn y up'}),
        'house': (extruded(np.array(house) * mm, 2 * mm),
                  {'size': 4, 'why': 'a gable roof: slanted faces, cells by their centres'}),
        'letter_H': (cells_to_mesh(letter(['#.#', '###', '#.#'])), {'size': 3, 'why': 'a bar between two posts'}),
        'letter_L': (cells_to_mesh(letter(['#.', '#.', '#.', '##'])), {'size': 4, 'why': 'a post and a foot'}),
        'letter_T': (cells_to_mesh(letter(['###', '.#.', '.#.'])), {'size': 3, 'why': 'a bar balanced on a stem'}),
        'letter_U': (cells_to_mesh(letter(['#.#', '#.#', '###'])), {'size': 3, 'why': 'two posts on a base'}),
        'chair': (cells_to_mesh(chair()), {'size': 5, 'up': 'y', 'why': 'a seat on four legs, a back: 3D, '
                                                                         'spans both ways; drawn y up'}),
        'step_pyramid': (cells_to_mesh(step_pyramid(), mm), {'size': 5, 'why': 'a solid three steps high'}),
        'stairs': (extruded(stairs, 2), {'size': 4, 'why': 'four steps, two cells deep'}),
        'ring': (trimesh.creation.annulus(r_min=1.2, r_max=2.5, height=1.0, sections=48),
                 {'size': 5, 'why': 'a torus-like ring lying flat: a closed loop of cells'}),
        'column': (trimesh.creation.cylinder(radius=1.3, height=3.0, sections=48),
                   {'size': 3, 'why': 'a round column: its cross-section a plus of five cells'}),
        'spire': (trimesh.creation.cone(radius=2.0, height=4.0, sections=48),
                  {'size': 4, 'why': 'a cone: layers shrinking to a point'}),
    }
    return out


FORMATS = {'arch': 'stl', 'bridge': 'obj', 'house': 'ply', 'letter_H': 'obj', 'letter_L': 'ply', 'letter_T': 'stl',
           'letter_U': 'stl', 'chair': 'obj', 'step_pyramid': 'stl', 'stairs': 'obj', 'ring': 'ply', 'column': 'stl',
           'spire': 'ply'}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--out', type=Path, default=Path('data/meshes'))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    manifest = {}
    for name, (mesh, info) in shapes().items():
        assert mesh.is_watertight, name
        up = info.get('up', 'z')
        if up != 'z':
            turn = np.eye(4)
            turn[:3, :3] = _UP[up].T           # z-up drawing -> the file's own up axis
            mesh.apply_transform(turn)
        mesh.apply_translation(-mesh.bounds[0])  # the model's corner at the origin, as editors save them
        path = args.out / f'{name}.{FORMATS[name]}'
        if path.suffix == '.obj':
            path.write_text(trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False,
                                                            digits=6, header=None))
        else:
            mesh.export(path)
        manifest[name] = {'file': path.name, 'size': info['size'], 'up': up, 'why': info['why']}
        print(f'{path}: {len(mesh.faces)} triangles, {path.stat().st_size} bytes')
    (args.out / 'meshes.json').write_text(json.dumps(manifest, indent=1) + '\n')
    print(f'wrote {args.out / "meshes.json"}')


if __name__ == '__main__':
    main()

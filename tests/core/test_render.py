"""Scene snapshots (TinyRenderer) and the PNG writer, checked by decoding the files."""

import struct
import zlib

import numpy as np
import pytest

from rad_core.allocation import solve
from rad_core.colours import PINK, type_colour
from rad_core.errors import RadError
from rad_core.mdp import Action, AssemblyEnv, EnvConfig
from rad_core.png import SIGNATURE, encode_png, write_png
from rad_core.render import fit_camera, render_scene, save_scene_png

from scenes import scene

W, H = 320, 240


def read_png(data: bytes) -> np.ndarray:
    """Decode the PNGs write_png makes (8-bit, filter 0), checking every CRC."""
    assert data[:8] == SIGNATURE
    pos, chunks = 8, []
    while pos < len(data):
        (length,) = struct.unpack('>I', data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack('>I', data[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(kind + body) & 0xFFFFFFFF, kind
        chunks.append((kind, body))
        pos += 12 + length
    assert [k for k, _ in chunks] == [b'IHDR', b'IDAT', b'IEND']
    width, height, depth, colour, _, _, _ = struct.unpack('>IIBBBBB', chunks[0][1])
    channels = {0: 1, 2: 3, 6: 4}[colour]
    assert depth == 8
    rows = np.frombuffer(zlib.decompress(chunks[1][1]), dtype=np.uint8).reshape(height, 1 + width * channels)
    assert (rows[:, 0] == 0).all()
    return rows[:, 1:].reshape(height, width, channels)


def pinkish(img: np.ndarray) -> np.ndarray:
    """Pixels whose colour is the target pink under any of the renderer's shading."""
    rgb = img.astype(float)
    target = np.asarray(PINK) / np.linalg.norm(PINK)
    norm = np.linalg.norm(rgb, axis=2)
    return (norm > 80) & ((rgb @ target) / np.maximum(norm, 1) > 0.995)


@pytest.fixture(scope='module')
def picture():
    return render_scene(scene(), width=W, height=H)


def test_saved_png_has_the_signature_the_size_and_the_rendered_pixels(tmp_path, picture):
    path = save_scene_png(scene(), tmp_path / 'scene.png', width=W, height=H)
    data = path.read_bytes()
    assert data.startswith(b'\x89PNG\r\n\x1a\n')
    width, height = struct.unpack('>II', data[16:24])
    assert (width, height) == (W, H)
    assert np.array_equal(read_png(data), picture)


def test_picture_shows_the_targets_in_pink_and_is_not_uniform(picture):
    assert picture.shape == (H, W, 3) and picture.dtype == np.uint8
    colours, counts = np.unique(picture.reshape(-1, 3), axis=0, return_counts=True)
    assert len(colours) >= 6 and counts.max() < 0.8 * W * H      # faces are flat-shaded
    assert pinkish(picture).sum() > 50
    # Blocks in their type colours: the scene has red-ish cubes (type 'cube').
    cube = np.asarray(type_colour('cube')) / np.linalg.norm(type_colour('cube'))
    rgb = picture.astype(float)
    assert ((rgb @ cube) / np.maximum(np.linalg.norm(rgb, axis=2), 1) > 0.995).sum() > 50


def test_rendering_is_repeatable(picture):
    assert np.array_equal(render_scene(scene(), width=W, height=H), picture)


def test_allocation_and_placed_blocks_cover_the_targets(picture):
    s = scene()
    plan = render_scene(s, allocation=solve(s), width=W, height=H)
    assert pinkish(plan).sum() < pinkish(picture).sum() / 4
    # Build the whole target with the MDP: placed blocks hide the pink markers too.
    env = AssemblyEnv(s, EnvConfig(stability='none'))
    for a in (Action(2, 1, env.grid.index(0, (2, 0, 0)), 3), Action(0, 0, env.grid.index(0, (0, 0, 0)), 0),
              Action(1, 0, env.grid.index(0, (0, 0, 1)), 0)):
        env.step(a)
    built = render_scene(s, occupancy=env.state.occupancy, width=W, height=H)
    assert pinkish(built).sum() < pinkish(picture).sum() / 4
    assert not np.array_equal(built, plan)


def test_type_colours_are_fixed_and_distinct():
    from rad_core.blocks import DEFAULT_LIBRARY
    colours = [type_colour(n) for n in DEFAULT_LIBRARY]
    assert len(set(colours)) == len(colours)
    assert type_colour('my_own_type') == type_colour('my_own_type')
    assert PINK not in colours


def test_default_camera_sees_every_corner():
    lo, hi = np.array([0.3, -0.3, 0.0]), np.array([0.7, 0.4, 0.2])
    cam = fit_camera(lo, hi, W / H)
    eye, target = cam.eye, np.asarray(cam.target)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0, 0, 1])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_v = np.tan(np.radians(cam.fov_deg) / 2)
    for corner in np.array(np.meshgrid(*zip(lo, hi))).reshape(3, -1).T:
        d = corner - eye
        depth = d @ forward
        assert depth > 0
        assert abs(d @ up) / depth <= tan_v and abs(d @ right) / depth <= tan_v * W / H
    assert eye[0] < target[0] and eye[1] > target[1] and eye[2] > target[2]    # front-left-above


def test_bad_render_inputs_raise():
    with pytest.raises(RadError, match='occupancy'):
        render_scene(scene(), occupancy=[-1, -1], width=W, height=H)
    with pytest.raises(RadError, match='image size'):
        render_scene(scene(), width=0, height=H)


@pytest.mark.parametrize('shape', [(5, 7), (5, 7, 3), (5, 7, 4)])
def test_png_round_trip(tmp_path, shape):
    img = np.random.default_rng(0).integers(0, 256, size=shape, dtype=np.uint8)
    path = write_png(tmp_path / 'x.png', img)
    decoded = read_png(path.read_bytes())
    assert np.array_equal(decoded.reshape(shape), img)


@pytest.mark.parametrize('bad', [np.zeros((4, 4, 3), dtype=np.float32), np.zeros((4, 4, 2), dtype=np.uint8),
                                 np.zeros((0, 4, 3), dtype=np.uint8), np.zeros(5, dtype=np.uint8)])
def test_png_rejects_what_it_cannot_write(bad):
    with pytest.raises(ValueError):
        encode_png(bad)


def test_robot_is_drawn_at_the_given_joints():
    from rad_core.render import ROBOT_BOX
    from rad_core.sim.panda import HOME
    s = scene()
    camera = fit_camera(ROBOT_BOX[0], ROBOT_BOX[1] + [0.6, 0, 0], 4 / 3)
    bare = render_scene(s, width=160, height=120, camera=camera)
    with_robot = render_scene(s, width=160, height=120, camera=camera, robot=HOME)
    changed = np.any(bare != with_robot, axis=2).mean()
    assert changed > 0.03, changed
    bent = np.array(HOME)
    bent[0] += 1.2
    assert np.any(render_scene(s, width=160, height=120, camera=camera, robot=bent) != with_robot)
    with pytest.raises(RadError, match='robot joints'):
        render_scene(s, robot=[0.0] * 3)

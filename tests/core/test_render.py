"""Scene snapshots (TinyRenderer) and the PNG writer, checked by decoding the files."""

import struct
import zlib

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.domain.colours import PINK, type_colour
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.env.mdp import Action, AssemblyEnv, EnvConfig
from rad_core.view.png import SIGNATURE, encode_apng, encode_png, write_png
from rad_core.view.render import (
    GHOST_EDGE,
    GUTTER,
    OFF_TARGET,
    build_layers,
    fit_camera,
    frame_points,
    render_build,
    render_scene,
    save_build_pictures,
    save_scene_png,
    scenes_after_steps,
)

from scenes import U, scene

W, H = 320, 240


def png_chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """(kind, body) of every chunk, checking the signature and every CRC."""
    assert data[:8] == SIGNATURE
    pos, chunks = 8, []
    while pos < len(data):
        (length,) = struct.unpack('>I', data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack('>I', data[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(kind + body) & 0xFFFFFFFF, kind
        chunks.append((kind, body))
        pos += 12 + length
    return chunks


def unpack_rows(compressed: bytes, width: int, height: int, channels: int) -> np.ndarray:
    rows = np.frombuffer(zlib.decompress(compressed), dtype=np.uint8).reshape(height, 1 + width * channels)
    assert (rows[:, 0] == 0).all()
    return rows[:, 1:].reshape(height, width, channels)


def header(chunks) -> tuple[int, int, int]:
    assert chunks[0][0] == b'IHDR'
    width, height, depth, colour, _, _, _ = struct.unpack('>IIBBBBB', chunks[0][1])
    assert depth == 8
    return width, height, {0: 1, 2: 3, 6: 4}[colour]


def read_png(data: bytes) -> np.ndarray:
    """Decode the PNGs write_png makes (8-bit, filter 0), checking every CRC."""
    chunks = png_chunks(data)
    assert [k for k, _ in chunks] == [b'IHDR', b'IDAT', b'IEND']
    return unpack_rows(chunks[1][1], *header(chunks))


def read_apng(data: bytes) -> tuple[np.ndarray, list[np.ndarray], list[float]]:
    """(the still a plain PNG reader shows, every frame as displayed, each frame's delay in s) of an
    animated PNG as encode_apng writes it: frame k > 0 replaces the rectangle its fcTL names."""
    chunks = png_chunks(data)
    width, height, channels = header(chunks)
    assert chunks[1][0] == b'acTL' and chunks[-1][0] == b'IEND'
    num_frames, _ = struct.unpack('>II', chunks[1][1])
    still, frames, delays, sequence, region = None, [], [], 0, None
    for kind, body in chunks[2:-1]:
        if kind == b'fcTL':
            seq, w, h, x, y, num, den, dispose, blend = struct.unpack('>IIIIIHHBB', body)
            assert seq == sequence and (dispose, blend) == (0, 0) and x + w <= width and y + h <= height
            sequence += 1
            region = (w, h, x, y)
            delays.append(num / den)
        elif kind in (b'IDAT', b'fdAT'):
            if kind == b'fdAT':
                assert struct.unpack('>I', body[:4])[0] == sequence
                sequence += 1
                body = body[4:]
            if region is None:
                still = unpack_rows(body, width, height, channels)
                continue
            w, h, x, y = region
            canvas = frames[-1].copy() if frames else np.zeros((height, width, channels), dtype=np.uint8)
            canvas[y:y + h, x:x + w] = unpack_rows(body, w, h, channels)
            frames.append(canvas)
            region = None
    assert len(frames) == num_frames
    return (frames[0] if still is None else still), frames, delays


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
    from rad_core.domain.blocks import DEFAULT_LIBRARY
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
    from rad_core.cell.panda import HOME
    from rad_core.view.render import ROBOT_BOX
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


# ---- pictures of a build -------------------------------------------------

VW, VH = 160, 120       # one view of a build picture


def moved(**poses) -> Scene:
    """The test scene with blocks (by id) at new positions, yaw 0."""
    blocks = [{'id': b.id, 'type': b.type, 'position': list(poses.get(b.id, b.position)),
               'yaw': 0 if b.id in poses else b.yaw} for b in scene().blocks]
    return scene(blocks=blocks)


# The target 'front' (origin 0.45, 0.1; 3 x 1 x 2) wants cells (0..2, 0, 0) and (0, 0, 1).
BUILT = {'c0': (0.45, 0.1, U / 2), 'i0': (0.5, 0.1, U / 2), 'c1': (0.45, 0.1, 1.5 * U)}
OFF = {'c0': (0.45, 0.1, U / 2), 'i0': (0.5, 0.1, U / 2), 'c1': (0.5, 0.1, 1.5 * U)}    # c1 on (1, 0, 1)


def split(picture) -> list[np.ndarray]:
    assert picture.shape == (VH, 2 * VW + GUTTER, 3)
    assert (picture[:, VW:VW + GUTTER] == 255).all()
    return [picture[:, :VW], picture[:, VW + GUTTER:]]


def not_table(view: np.ndarray) -> np.ndarray:
    """Pixels that are not the table top (the most common colour: drawn flat, without shadows)."""
    colours, counts = np.unique(view.reshape(-1, 3), axis=0, return_counts=True)
    return np.any(view != colours[np.argmax(counts)], axis=2)


def tinted_red(img: np.ndarray) -> np.ndarray:
    """Pixels of the OFF_TARGET tint: red with little green or blue (the 'cube' type's red has more)."""
    rgb = img.astype(float)
    return (rgb[:, :, 0] > 100) & (rgb[:, :, 1] < 0.25 * rgb[:, :, 0]) & (rgb[:, :, 2] < 0.2 * rgb[:, :, 0])


def project(camera, points, aspect):
    """Each point's place in the picture, -1..1 across and up, and its depth."""
    eye = camera.eye
    forward = (np.asarray(camera.target) - eye) / np.linalg.norm(np.asarray(camera.target) - eye)
    right = np.cross(forward, [0, 0, 1])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_v = np.tan(np.radians(camera.fov_deg) / 2)
    rel = np.asarray(points) - eye
    depth = rel @ forward
    return (rel @ right) / depth / (tan_v * aspect), (rel @ up) / depth / tan_v, depth


@pytest.mark.parametrize('azimuth, elevation, aspect', [(135, 30, 4 / 3), (-45, 30, 4 / 3), (60, 50, 0.7),
                                                         (0, 20, 2.0)])
def test_frame_points_fills_the_tighter_side_and_keeps_every_point_in_view(azimuth, elevation, aspect):
    points = np.random.default_rng(azimuth % 360).uniform([0.3, -0.2, 0.0], [0.6, 0.1, 0.25], size=(40, 3))
    cam = frame_points(points, aspect, azimuth, elevation, margin=1.05)
    x, y, depth = project(cam, points, aspect)
    assert (depth > 0).all()
    assert np.abs(x).max() <= 1 / 1.05 + 1e-9 and np.abs(y).max() <= 1 / 1.05 + 1e-9
    # One screen axis binds: the points touch both of its sides, so they are centred and as large as allowed.
    assert any(np.isclose(a.min(), -1 / 1.05) and np.isclose(a.max(), 1 / 1.05) for a in (x, y))
    with pytest.raises(RadError, match='margin'):
        frame_points(points, aspect, margin=0.9)


def test_build_picture_frames_the_target_closely_from_two_sides():
    picture = render_build(scene(), width=VW, height=VH)
    left, right = split(picture)
    assert not np.array_equal(left, right)
    for view in (left, right):
        rows, cols = np.nonzero(not_table(view))
        spans = (cols.max() - cols.min() + 1) / VW, (rows.max() - rows.min() + 1) / VH
        assert max(spans) > 0.85 and min(spans) > 0.4, spans
        assert not_table(view).mean() > 0.2
    # The whole-table snapshot of the same scene leaves the target a small part of its picture.
    old = render_scene(scene(), width=VW, height=VH)
    rows, cols = np.nonzero(pinkish(old))
    assert (cols.max() - cols.min() + 1) / VW < 0.5


def test_unbuilt_target_cells_are_drawn_until_blocks_fill_them():
    empty, full = build_layers(scene()), build_layers(moved(**BUILT))
    assert (empty.built, empty.missing, empty.off_target) == (0, 4, 0)
    assert (full.built, full.missing, full.off_target) == (4, 0, 0)
    assert len(empty.ghosts) == 4 and not full.ghosts
    assert np.asarray(GHOST_EDGE) @ PINK / np.linalg.norm(GHOST_EDGE) / np.linalg.norm(PINK) > 0.999
    for view in split(render_build(scene(), width=VW, height=VH)):
        assert pinkish(view).mean() > 0.03             # the ghosts' edges
    for view in split(render_build(moved(**BUILT), width=VW, height=VH)):
        assert pinkish(view).sum() == 0 and tinted_red(view).sum() == 0


def test_blocks_on_cells_outside_the_target_are_tinted_red():
    layers = build_layers(moved(**OFF))
    assert (layers.built, layers.missing, layers.off_target) == (3, 1, 1)
    assert OFF_TARGET[0] > 4 * max(OFF_TARGET[1:])
    for view in split(render_build(moved(**OFF), width=VW, height=VH)):
        assert tinted_red(view).sum() > 30


def test_the_heap_is_left_out_after_and_framed_before():
    after, before = build_layers(scene()), build_layers(scene(), heap=True)
    heap_cubes = 4                                     # c0, c1 and the two units of i0
    assert len(before.solid) == len(after.solid) + heap_cubes
    assert before.frame[:, 1].min() < -0.2 < after.frame[:, 1].min()


STEPS = [{'block': 'i0', 'position': list(BUILT['i0']), 'yaw': 0},
         {'block': 'c0', 'position': list(BUILT['c0']), 'yaw': 0, 'failure': 'grasp'},
         {'block': 'c0', 'position': list(BUILT['c0']), 'yaw': 0},
         {'block': 'c1', 'position': list(BUILT['c1']), 'yaw': 0}]


def test_scenes_after_steps_put_each_steps_block_at_its_planned_pose():
    scenes = scenes_after_steps(scene(), STEPS)
    assert len(scenes) == len(STEPS) + 1 and scenes[0] == scene()
    assert scenes[1].block('i0').position == BUILT['i0'] and scenes[1].block('i0').yaw == 0
    assert scenes[2] == scenes[1]                      # the failed step moved nothing anyone knows of
    assert scenes[3].block('c0').position == BUILT['c0'] and scenes[1].block('c0') == scene().block('c0')
    assert scenes[-1].blocks == moved(**BUILT).blocks
    with pytest.raises(RadError, match=r'steps\[0\]'):
        scenes_after_steps(scene(), [{'block': 'nope', 'position': [0, 0, 0], 'yaw': 0}])
    with pytest.raises(RadError, match=r'steps\[1\]'):
        scenes_after_steps(scene(), [STEPS[0], {'block': 'c0', 'yaw': 0}])


def test_build_pictures_before_after_and_one_frame_per_step(tmp_path):
    paths = save_build_pictures(scene(), moved(**BUILT), STEPS, tmp_path, width=VW, height=VH, step_s=0.5)
    assert sorted(paths) == ['after', 'before', 'build']
    before = read_png(paths['before'].read_bytes())
    assert np.array_equal(before, render_build(scene(), heap=True, width=VW, height=VH))
    assert np.array_equal(read_png(paths['after'].read_bytes()), render_build(moved(**BUILT), width=VW, height=VH))
    still, frames, delays = read_apng(paths['build'].read_bytes())
    assert len(frames) == len(STEPS) + 1 and delays == [0.5] * len(STEPS) + [1.5]
    assert np.array_equal(still, frames[-1])
    assert np.array_equal(frames[2], frames[1]) and not np.array_equal(frames[1], frames[0])
    assert pinkish(frames[0]).sum() > pinkish(frames[3]).sum() > pinkish(frames[4]).sum() == 0
    # Every frame is framed alike: the start's picture, framed on the same cells, is the first frame.
    assert np.array_equal(frames[0], render_build(scene(), frame=build_layers(scene()).frame, width=VW, height=VH))
    # Without steps nothing is animated; without a final scene there is no after.png.
    (tmp_path / 'bare').mkdir()
    assert sorted(save_build_pictures(scene(), None, [], tmp_path / 'bare', width=VW, height=VH)) == ['before']
    assert [p.name for p in (tmp_path / 'bare').iterdir()] == ['before.png']


def test_apng_round_trip_with_and_without_a_still():
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 256, size=(6, 9, 3), dtype=np.uint8)]
    for change in ((slice(1, 3), slice(2, 5)), None, (slice(0, 6), slice(8, 9))):
        frames.append(frames[-1].copy())
        if change is not None:
            frames[-1][change] = rng.integers(0, 256, size=frames[-1][change].shape, dtype=np.uint8)
    still, decoded, delays = read_apng(encode_apng(frames, 0.25))
    assert np.array_equal(still, frames[0]) and delays == [0.25] * 4
    assert all(np.array_equal(a, b) for a, b in zip(decoded, frames))
    other = np.zeros_like(frames[0])
    still, decoded, delays = read_apng(encode_apng(frames, [0.1, 0.2, 0.3, 4.0], still=other))
    assert np.array_equal(still, other) and delays == [0.1, 0.2, 0.3, 4.0]
    assert all(np.array_equal(a, b) for a, b in zip(decoded, frames))
    # Unchanged frames store one pixel, changed ones the rectangle that changed.
    assert len(encode_apng([frames[0]] * 4, 0.1)) < len(encode_apng(frames, 0.1))


@pytest.mark.parametrize('frames, delays, still', [
    ([], 0.1, None),
    ([np.zeros((4, 4, 3), np.uint8), np.zeros((4, 5, 3), np.uint8)], 0.1, None),
    ([np.zeros((4, 4, 3), np.uint8)] * 2, [0.1], None),
    ([np.zeros((4, 4, 3), np.uint8)], 70.0, None),
    ([np.zeros((4, 4, 3), np.uint8)], 0.1, np.zeros((4, 4, 4), np.uint8)),
    ([np.zeros((4, 4, 3), np.float32)], 0.1, None)])
def test_apng_rejects_what_it_cannot_write(frames, delays, still):
    with pytest.raises(ValueError):
        encode_apng(frames, delays, still)

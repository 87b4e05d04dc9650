"""Motion-capture registration: round trips, noise, and every way a pose can be wrong."""

import math
from dataclasses import replace

import numpy as np
import pytest
from rad_core.cell.mocap import (
    RegistrationConfig,
    RigidBodyPose,
    body_map_for,
    register_scene,
    register_world,
    scene_to_bodies,
    yaw_quaternion,
)
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Block, Scene

from scenes import U, scene


def with_placed(s: Scene, n: int = 3) -> Scene:
    """The scene with its first n blocks moved onto the target grid (as if placed).

    Each block goes to the first target cells where all its units fit at yaw 0 or
    180, on the table or on cells filled already, without overlapping.
    """
    grid = Grid(s)
    taken: set[int] = set()
    blocks = list(s.blocks)
    placed = 0
    for i, b in enumerate(blocks):
        if placed == n:
            break
        offs = s.block_types[b.type]
        for yaw in (0, 180):
            done = False
            for c in np.flatnonzero(grid.is_target):
                pts = grid.centres[c] + s.unit * offs.rotated(yaw)
                cells = grid.cells_at(pts)
                if cells is None or taken & set(cells.tolist()) or not grid.is_target[cells].all():
                    continue
                blocks[i] = Block(b.id, b.type, tuple(float(v) for v in grid.centres[c]), yaw)
                taken |= set(cells.tolist())
                placed += 1
                done = True
                break
            if done:
                break
    doc = s.to_dict()
    doc['blocks'] = [b.to_dict() for b in blocks]
    return Scene.from_dict(doc)


def assert_same_scene(got: Scene, want: Scene, atol=1e-9):
    assert [(b.id, b.type, b.yaw) for b in got.blocks] == [(b.id, b.type, b.yaw) for b in want.blocks]
    assert got.targets == want.targets and got.unit == want.unit
    np.testing.assert_allclose([b.position for b in got.blocks], [b.position for b in want.blocks], atol=atol)


def noisy(bodies, rng, pos_sigma=0.003, ang_sigma_deg=2.0):
    out = []
    for b in bodies:
        roll, pitch, dyaw = np.radians(rng.normal(0, ang_sigma_deg, 3))
        yaw = 2 * math.atan2(b.quaternion[2], b.quaternion[3]) + dyaw
        q = _rpy_quat(roll, pitch, yaw)
        out.append(RigidBodyPose(b.name, tuple(np.asarray(b.position) + rng.normal(0, pos_sigma, 3)), q))
    return out


def _rpy_quat(r, p, y):
    cr, sr, cp, sp, cy, sy = (math.cos(r / 2), math.sin(r / 2), math.cos(p / 2), math.sin(p / 2),
                              math.cos(y / 2), math.sin(y / 2))
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def config_for(s, **kw):
    return RegistrationConfig(body_map=body_map_for(s), **kw)


@pytest.mark.parametrize('seed', range(25))
def test_round_trip_of_generated_scenes_is_exact(seed):
    s = generate_scene(GeneratorConfig(grid=3 + seed % 3), seed)
    assert_same_scene(register_scene(scene_to_bodies(s), s, config_for(s)), s)


@pytest.mark.parametrize('seed', range(10))
def test_round_trip_with_placed_blocks_keeps_them_on_the_grid(seed):
    s = with_placed(generate_scene(GeneratorConfig(grid=4), seed))
    placed = blocks_on_grid(s, Grid(s))
    assert len(placed) >= 1
    got = register_scene(scene_to_bodies(s), s, config_for(s))
    assert_same_scene(got, s)
    assert {k: v.tolist() for k, v in blocks_on_grid(got, Grid(got)).items()} == \
        {k: v.tolist() for k, v in placed.items()}


@pytest.mark.parametrize('seed', range(10))
def test_noise_of_3mm_and_2deg_registers_the_same_scene(seed):
    rng = np.random.default_rng(seed)
    s = with_placed(generate_scene(GeneratorConfig(grid=4), seed))
    got = register_scene(noisy(scene_to_bodies(s), rng), s, config_for(s))
    # Yaws, heights and grid positions snap back exactly; table blocks keep their noisy x/y.
    assert [(b.id, b.type, b.yaw) for b in got.blocks] == [(b.id, b.type, b.yaw) for b in s.blocks]
    grid = Grid(s)
    on_grid = blocks_on_grid(s, grid)
    for i, (g, w) in enumerate(zip(got.blocks, s.blocks)):
        assert g.position[2] == pytest.approx(w.position[2], abs=1e-9)
        tol = 1e-9 if i in on_grid else 0.015
        np.testing.assert_allclose(g.position[:2], w.position[:2], atol=tol)
    assert blocks_on_grid(got, Grid(got)).keys() == on_grid.keys()


def test_body_names_map_to_block_ids_and_template_blocks_are_ignored():
    s = scene()
    names = {b.id: f'rb_{b.id}' for b in s.blocks}
    bodies = scene_to_bodies(s, names)
    assert [b.name for b in bodies] == ['rb_c0', 'rb_c1', 'rb_i0']
    got = register_scene(bodies[:2], s, RegistrationConfig(body_map=body_map_for(s, names)))
    assert [b.id for b in got.blocks] == ['c0', 'c1']


def test_table_height_offset_is_removed():
    s = scene()
    cfg = config_for(s, table_z=0.74)
    assert_same_scene(register_scene(scene_to_bodies(s, table_z=0.74), s, cfg), s)


def test_measured_positions_are_rounded_to_the_resolution():
    s = scene()
    bodies = _with(s, 0, position=(0.40004, -0.20000000298, U / 2))
    assert register_scene(bodies, s, config_for(s)).block('c0').position == (0.4, -0.2, U / 2)
    got = register_scene(bodies, s, config_for(s, resolution=0)).block('c0').position
    assert got == (0.40004, -0.20000000298, U / 2)


def test_yaw_snaps_from_just_below_360():
    s = scene()
    bodies = scene_to_bodies(s)
    bodies[2] = RigidBodyPose('i0', bodies[2].position, yaw_quaternion(-93))   # -> 270
    assert register_scene(bodies, s, config_for(s)).block('i0').yaw == 270


# ---- errors: each names the body -------------------------------------------

def _err(s, bodies, cfg=None):
    with pytest.raises(RadError) as e:
        register_scene(bodies, s, cfg or config_for(s))
    return str(e.value)


def _with(s, k, **change):
    bodies = scene_to_bodies(s)
    b = bodies[k]
    bodies[k] = RigidBodyPose(change.get('name', b.name), change.get('position', b.position),
                              change.get('quaternion', b.quaternion), change.get('tracking_valid', True))
    return bodies


def test_unknown_body():
    s = scene()
    msg = _err(s, _with(s, 0, name='wand'))
    assert "'wand'" in msg and 'unknown' in msg


def test_untracked_body():
    s = scene()
    msg = _err(s, _with(s, 1, tracking_valid=False))
    assert "'c1'" in msg and 'not tracked' in msg


def test_block_on_its_side():
    s = scene()
    msg = _err(s, _with(s, 2, quaternion=_rpy_quat(math.pi / 2, 0, 0)))
    assert "'i0'" in msg and 'tilted 90.0 deg' in msg


def test_slightly_tilted_is_refused_beyond_the_tolerance():
    s = scene()
    bodies = _with(s, 0, quaternion=_rpy_quat(0, math.radians(12), 0))
    assert "'c0'" in _err(s, bodies)
    assert register_scene(bodies, s, config_for(s, tilt_tol_deg=15)).block('c0').yaw == 0


def test_yaw_between_multiples_of_90():
    s = scene()
    msg = _err(s, _with(s, 2, quaternion=yaw_quaternion(135)))
    assert "'i0'" in msg and 'yaw 135.0 deg is 45.0 deg from a multiple of 90' in msg


def test_height_off_the_lattice():
    s = scene()
    msg = _err(s, _with(s, 0, position=(0.4, -0.2, U)))           # half a unit up: floating
    assert "'c0'" in msg and 'off the unit lattice' in msg


def test_pose_in_a_target_region_off_its_grid():
    s = scene()
    t = s.targets[0]
    # 15 mm (0.3 unit) off the cell centre along x: inside the region, off its grid.
    msg = _err(s, _with(s, 0, position=(t.origin[0] + 0.015, t.origin[1], U / 2)))
    assert "'c0'" in msg and "target region 'front'" in msg and '15.0 mm off its grid' in msg


def test_pose_in_a_target_region_near_the_grid_snaps_onto_it():
    s = scene()
    t = s.targets[0]
    got = register_scene(_with(s, 0, position=(t.origin[0] + 0.006, t.origin[1] - 0.004, U / 2 + 0.003)),
                         s, config_for(s))
    assert got.block('c0').position == pytest.approx(t.origin, abs=1e-12)


@pytest.mark.parametrize('position, quaternion', [((0.4, math.nan, U / 2), (0, 0, 0, 1)),
                                                  ((0.4, -0.2, U / 2), (0, 0, math.nan, 1)),
                                                  ((math.inf, -0.2, U / 2), (0, 0, 0, 1))])
def test_nan_or_inf_in_a_pose(position, quaternion):
    s = scene()
    msg = _err(s, _with(s, 1, position=position, quaternion=quaternion))
    assert "'c1'" in msg and 'NaN or infinity' in msg


def test_quaternion_not_unit_length():
    s = scene()
    msg = _err(s, _with(s, 1, quaternion=(0, 0, 0, 2)))
    assert "'c1'" in msg and 'not unit length' in msg
    assert "'c1'" in _err(s, _with(s, 1, quaternion=(0, 0, 0, 0)))


def test_two_bodies_mapped_to_the_same_block():
    with pytest.raises(RadError, match=r"'rb1' and 'rb2' are both mapped to block 'c0'"):
        RegistrationConfig(body_map={'rb1': ('c0', 'cube'), 'rb2': ('c0', 'cube')})


def test_body_reported_twice():
    s = scene()
    bodies = scene_to_bodies(s)
    assert "'c0' is reported twice" in _err(s, bodies + bodies[:1])


def test_block_type_not_in_the_template():
    s = scene()
    cfg = RegistrationConfig(body_map={'c0': ('c0', 'T4'), 'c1': ('c1', 'cube'), 'i0': ('i0', 'I2')})
    msg = _err(s, scene_to_bodies(s), cfg)
    assert "'c0'" in msg and "'T4'" in msg


def test_overlapping_bodies_are_named():
    s = scene()
    msg = _err(s, _with(s, 1, position=(0.4 + 0.01, -0.2, U / 2)))    # c1 onto c0
    assert "rigid body 'c1'" in msg and 'overlaps' in msg and "(rigid body 'c0')" in msg


def test_config_is_checked():
    for bad in ({'resolution': -1e-4}, {'position_tol': 0.6}, {'tilt_tol_deg': math.nan}, {'yaw_tol_deg': 0},
                {'table_z': math.inf}):
        with pytest.raises(RadError):
            RegistrationConfig(**bad)


# ---- register_world: what a scene cannot express is set aside, not fatal ------------------------------

def test_register_world_sets_a_block_on_its_side_aside_and_registers_the_rest():
    s = scene()
    on_side = (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))    # 90 deg about x
    bodies = _with(s, 0, quaternion=on_side)
    assert 'tilted' in _err(s, bodies)                                   # register_scene still refuses
    reg = register_world(bodies, s, config_for(s))
    assert [b.id for b in reg.scene.blocks] == ['c1', 'i0']
    assert set(reg.set_aside) == {'c0'} and 'tilted 90.0 deg' in reg.set_aside['c0']
    assert reg.in_regions == frozenset() and reg.blocked == {} and reg.plannable() is reg.scene


def test_register_world_blocks_the_cells_a_block_pushed_off_its_grid_occupies():
    s = scene()
    t = s.targets[0]
    # c0 placed on cell (0, 0, 0), then pushed 20 mm along +x: half way into cell (1, 0, 0).
    bodies = _with(s, 0, position=(t.origin[0] + 0.02, t.origin[1], U / 2))
    reg = register_world(bodies, s, config_for(s))
    assert set(reg.set_aside) == {'c0'} and '20.0 mm off its grid' in reg.set_aside['c0']
    assert reg.in_regions == {'c0'} and reg.blocked == {'front': ((0, 0, 0), (1, 0, 0))}
    plannable = reg.plannable()
    assert set(plannable.targets[0].filled) == {(2, 0, 0), (0, 0, 1)}
    assert reg.scene.targets == s.targets                   # coverage is still measured against the real targets


def test_register_world_leaves_a_cell_a_registered_block_sits_on_to_it():
    s = scene()
    t = s.targets[0]
    bodies = _with(s, 1, position=tuple(t.cell_center((1, 0, 0), U)))        # c1 placed on cell (1, 0, 0)
    bodies[0] = RigidBodyPose('c0', (t.origin[0] + 0.018, t.origin[1], U / 2), (0, 0, 0, 1))   # c0 pushed at it
    reg = register_world(bodies, s, config_for(s))
    assert set(reg.set_aside) == {'c0'} and reg.blocked == {'front': ((0, 0, 0),)}


def test_register_world_sets_aside_one_of_two_overlapping_blocks_and_names_the_other():
    s = scene()
    reg = register_world(_with(s, 1, position=(0.4 + 0.01, -0.2, U / 2)), s, config_for(s))
    assert set(reg.set_aside) == {'c1'} and "(rigid body 'c0')" in reg.set_aside['c1']
    assert [b.id for b in reg.scene.blocks] == ['c0', 'i0']


def test_register_world_still_refuses_set_up_errors():
    s = scene()
    for bodies, what in ((_with(s, 0, name='wand'), 'unknown'), (_with(s, 1, quaternion=(0, 0, 0, 2)), 'unit length'),
                         (_with(s, 0, tracking_valid=False), 'not tracked')):
        with pytest.raises(RadError, match=what):
            register_world(bodies, s, config_for(s))


def test_plannable_refuses_when_every_target_cell_is_blocked():
    doc_ = scene().to_dict()
    doc_['targets'] = [{'name': 'one', 'origin': [0.45, 0.1, U / 2], 'size': [1, 1, 1], 'filled': [[0, 0, 0]]}]
    s = Scene.from_dict(doc_)
    reg = register_world(_with(s, 0, position=(0.45 + 0.015, 0.1, U / 2)), s, config_for(s))
    with pytest.raises(RadError, match='every target cell is occupied'):
        reg.plannable()


def test_tolerances_follow_the_tracker_noise():
    base = RegistrationConfig()
    # 1 mm, 0.5 deg: the tolerances hold; only offsets under 3 sigma are taken for noise.
    assert RegistrationConfig.for_noise(0.001, 0.5, U) == replace(base, offset_floor=0.003)
    wide = RegistrationConfig.for_noise(0.004, 4.0, U, tilt_tol_deg=12.0)
    assert wide.position_tol == pytest.approx(0.4) and wide.yaw_tol_deg == pytest.approx(20.0)
    assert wide.tilt_tol_deg == 12.0
    with pytest.raises(RadError, match='too large to register'):
        RegistrationConfig.for_noise(0.005, 0.5, U)
    with pytest.raises(RadError, match='finite'):
        RegistrationConfig.for_noise(math.nan, 0.5, U)


def test_a_block_snapped_onto_its_cell_keeps_how_far_off_it_was_seen():
    s = with_placed(generate_scene(GeneratorConfig(grid=4), 3))
    on_grid = [s.blocks[i].id for i in blocks_on_grid(s, Grid(s))]
    bodies = scene_to_bodies(s)
    far, near = on_grid[0], on_grid[-1]
    shifted = [RigidBodyPose(b.name, (b.position[0] + (0.002 if b.name == far else 0.0001 if b.name == near else 0),
                                      b.position[1] - (0.0015 if b.name == far else 0), b.position[2]), b.quaternion)
               for b in bodies]
    got = register_world(shifted, s, config_for(s)).scene
    assert_same_scene(got, s)                   # still on its cells: the grid, the MDP and coverage see it built
    assert got.measured_offsets == {far: pytest.approx((0.002, -0.0015))}    # 0.1 mm is under the floor
    assert got.offset(far) == pytest.approx([0.002, -0.0015, 0.0])
    # The offsets travel with the scene's document (to the gamp node) and are checked there.
    assert Scene.loads(got.dumps()).measured_offsets == got.measured_offsets
    # Table blocks keep their measured x/y and need none.
    table = [b.id for b in s.blocks if b.id not in on_grid]
    assert not set(table) & set(got.measured_offsets)


def test_the_offset_floor_follows_the_tracker_noise():
    assert RegistrationConfig().offset_floor == pytest.approx(3e-4)
    assert RegistrationConfig.for_noise(0.001, 0.5, 0.05).offset_floor == pytest.approx(0.003)
    assert RegistrationConfig.for_noise(0.00005, 0.5, 0.05).offset_floor == pytest.approx(3e-4)
    with pytest.raises(RadError, match='offset_floor'):
        RegistrationConfig(offset_floor=-1.0)


def test_a_set_aside_block_is_an_obstacle_of_the_scene_where_it_lies():
    s = scene()
    turned = _rpy_quat(math.pi / 2, 0, 0)
    reg = register_world(_with(s, 2, quaternion=turned, position=(0.6, -0.2, 0.026)), s, config_for(s))
    assert set(reg.set_aside) == {'i0'} and [b.id for b in reg.scene.blocks] == ['c0', 'c1']
    (o,) = reg.scene.obstacles
    assert (o.id, o.type) == ('i0', 'I2') and o.position == pytest.approx((0.6, -0.2, 0.026))
    assert o.quaternion == pytest.approx(turned)
    assert reg.plannable().obstacles == reg.scene.obstacles


def test_a_block_turned_on_the_table_is_registered_straight_with_its_turn_kept():
    s = scene()
    bodies = _with(s, 2, quaternion=yaw_quaternion(90 + 32))          # i0, lying flat on the table
    with pytest.raises(RadError, match='32.0 deg from a multiple of 90'):
        register_scene(bodies, s, config_for(s))                     # strict: no scene has that yaw
    reg = register_world(bodies, s, config_for(s))
    assert reg.set_aside == {} and reg.scene.block('i0').yaw == 90
    assert reg.scene.turn('i0') == pytest.approx(32.0) and reg.scene.offset('i0').tolist() == [0, 0, 0]
    # In a target region, or turned and lifted off the table, it still cannot be expressed.
    placed = with_placed(generate_scene(GeneratorConfig(grid=4), 3))
    bid = next(placed.blocks[i].id for i in blocks_on_grid(placed, Grid(placed)))
    k = [b.id for b in placed.blocks].index(bid)
    turned = scene_to_bodies(placed)
    b = turned[k]
    turned[k] = RigidBodyPose(b.name, b.position, tuple(yaw_quaternion(placed.blocks[k].yaw + 30)))
    assert bid in register_world(turned, placed, config_for(placed)).set_aside

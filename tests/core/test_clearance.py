"""Scene clearance: blocks smaller than their cells on their outer side faces, everywhere.

The format (round trip, validation), the PyBullet block bodies (narrower, same height,
inside filled), the gap neighbours leave, physics verdicts, GAMP's grasps, registration,
rendering and Rerun boxes. Flush scenes (clearance 0) are covered by every other test.
"""

import math

import numpy as np
import pytest
from rad_core.cell.mocap import RegistrationConfig, RigidBodyPose, body_map_for, register_scene, scene_to_bodies
from rad_core.domain.blocks import unit_boxes
from rad_core.domain.errors import RadError, SceneError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Block, Scene
from rad_core.domain.transforms import yaw_quaternion
from rad_core.env.mdp import Action, AssemblyEnv, EnvConfig
from rad_core.sim.physics import PhysicsConfig, PhysicsStability, add_block_body, block_shape, direct_client
from rad_core.sim.world import World
from rad_core.view import viz
from rad_core.view.render import _scene_boxes, render_scene

from scenes import U, doc, scene

C = 0.2                     # 1 cm between neighbours at the 5 cm unit, the predecessor's gap


# ---- the format ------------------------------------------------------------

def test_clearance_round_trips_and_is_absent_when_flush():
    s = Scene.from_dict({**doc(), 'clearance': C})
    assert s.clearance == C
    assert s.to_dict()['clearance'] == C
    assert list(s.to_dict())[:3] == ['format', 'unit', 'clearance']
    again = Scene.loads(s.dumps())
    assert again == s and again.clearance == C and again.dumps() == s.dumps()
    flush = scene()
    assert flush.clearance == 0.0 and 'clearance' not in flush.to_dict()
    # 0 given is the same scene as 0 absent, down to the bytes.
    assert Scene.from_dict({**doc(), 'clearance': 0}).dumps() == flush.dumps()
    assert flush.with_clearance(C) == s and s.with_clearance(0).dumps() == flush.dumps()


@pytest.mark.parametrize('bad', [-0.01, 0.5, 0.7, math.nan, math.inf, '0.2', True, None, [0.2]])
def test_bad_clearance_names_the_field(bad):
    with pytest.raises(SceneError) as e:
        Scene.from_dict({**doc(), 'clearance': bad})
    assert e.value.field == 'clearance'
    with pytest.raises(RadError, match='clearance'):
        GeneratorConfig(clearance=bad).validate()


def test_with_a_clearance_blocks_may_stand_closer_than_a_unit():
    """Their outer faces face each other: 0.85 unit apart leaves 0.05 unit at clearance 0.2."""
    blocks = [{'id': 'a', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0},
              {'id': 'b', 'type': 'cube', 'position': [0.4 + 0.85 * U, -0.2, U / 2], 'yaw': 0}]
    with pytest.raises(SceneError, match="overlaps block 'a'"):
        scene(blocks=blocks)
    assert len(Scene.from_dict({**doc(blocks=blocks), 'clearance': C}).blocks) == 2
    # Heights do not shrink: a cube half a unit above another still overlaps it.
    blocks[1]['position'] = [0.4, -0.2, U]
    with pytest.raises(SceneError, match='overlaps'):
        Scene.from_dict({**doc(blocks=blocks), 'clearance': C})


def test_generated_scenes_carry_the_clearance_and_keep_their_layout():
    flush = generate_scene(GeneratorConfig(grid=4), 2)
    spaced = generate_scene(GeneratorConfig(grid=4, clearance=C), 2)
    assert spaced.clearance == C and flush.clearance == 0.0
    assert spaced.blocks == flush.blocks and spaced.targets == flush.targets
    assert Scene.loads(spaced.dumps()) == spaced


def test_unit_boxes_set_back_outer_side_faces_only():
    # An L: (0,0,0), (1,0,0), (0,1,0), plus a unit on top of the corner.
    shift, half = unit_boxes([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], 0.5, 0.5, 0.1)
    lo, hi = shift - half, shift + half
    # Corner unit: +x and +y faces touch siblings (stay at 0.5), -x and -y are outer (0.4).
    assert np.allclose(lo[0], [-0.4, -0.4, -0.5]) and np.allclose(hi[0], [0.5, 0.5, 0.5])
    assert np.allclose(lo[1], [-0.5, -0.4, -0.5]) and np.allclose(hi[1], [0.4, 0.4, 0.5])
    assert np.allclose(lo[2], [-0.4, -0.5, -0.5]) and np.allclose(hi[2], [0.4, 0.4, 0.5])
    # The top unit has a sibling below only: every side face is outer, height unchanged.
    assert np.allclose(lo[3], [-0.4, -0.4, -0.5]) and np.allclose(hi[3], [0.4, 0.4, 0.5])
    # No recess: centred boxes of exactly the given halves.
    shift, half = unit_boxes([[0, 0, 0], [1, 0, 0]], 0.3, 0.7)
    assert not shift.any() and (half == [[0.3, 0.3, 0.7]] * 2).all()


# ---- the block bodies ----------------------------------------------------------

def test_block_body_is_narrower_by_the_clearance_and_filled_inside():
    cfg = PhysicsConfig()
    p, cid = direct_client(cfg)
    try:
        offsets = np.array([[0, 0, 0], [1, 0, 0]])                  # an I2 along x
        aabbs, rays = {}, {}
        for c in (0.0, C):
            for frame in ('principal', 'anchor'):
                shape = block_shape(p, cid, offsets, U, cfg, frame=frame, clearance=c)
                position = shape.com.tolist() if frame == 'principal' else [0, 0, 0]
                orientation = shape.axes if frame == 'principal' else [0, 0, 0, 1]
                body = add_block_body(p, cid, shape, position, orientation, cfg)
                p.performCollisionDetection(physicsClientId=cid)       # the broadphase sees the new body
                lo, hi = (np.array(v) for v in p.getAABB(body, -1, physicsClientId=cid))
                aabbs[c, frame] = hi - lo, (lo + hi) / 2
                # Rays down just inside the unit boundary and just inside the outer faces.
                xs = [0.5 * U - 0.02 * U, -0.5 * U + 0.05 * U, 1.5 * U - 0.05 * U]
                hits = p.rayTestBatch([[x, 0, 1] for x in xs], [[x, 0, -1] for x in xs], physicsClientId=cid)
                rays[c, frame] = [h[0] == body for h in hits]
                p.removeBody(body, physicsClientId=cid)
        for frame in ('principal', 'anchor'):
            (flush, centre0), (spaced, centre) = aabbs[0.0, frame], aabbs[C, frame]
            assert spaced[:2] == pytest.approx(flush[:2] - C * U, abs=1e-7)      # x and y: 1 cm less
            assert spaced[2] == pytest.approx(flush[2], abs=1e-9)                 # z: the same height
            assert centre == pytest.approx(centre0, abs=1e-9)
            assert rays[0.0, frame] == [True, True, True]
            # Filled between its own units, set back 0.1 unit at its ends.
            assert rays[C, frame] == [True, False, False]
        with pytest.raises(RadError, match='clearance'):
            block_shape(p, cid, offsets, U, cfg, clearance=0.5)
    finally:
        p.disconnect(physicsClientId=cid)


def _two_cubes(clearance: float) -> Scene:
    blocks = [{'id': 'a', 'type': 'cube', 'position': [0.45, -0.2, U / 2], 'yaw': 0},
              {'id': 'b', 'type': 'cube', 'position': [0.45 + U, -0.2, U / 2], 'yaw': 0}]
    return Scene.from_dict({**doc(blocks=blocks), 'clearance': clearance})


def test_neighbouring_blocks_in_the_world_leave_the_gap():
    hair = 2 * PhysicsConfig().side_gap * U
    gaps = {}
    for c in (0.0, C):
        with World(_two_cubes(c)) as world:
            p = world.pybullet
            pts = p.getClosestPoints(world.blocks['a'], world.blocks['b'], 0.05, physicsClientId=world.client)
            gaps[c] = min(pt[8] for pt in pts)
            lo, hi = p.getAABB(world.blocks['a'], -1, physicsClientId=world.client)
            assert hi[2] - lo[2] > U                                  # height untouched (plus the hairs)
    assert gaps[0.0] == pytest.approx(hair, abs=1e-4)
    assert gaps[C] == pytest.approx(C * U + hair, abs=1e-4)          # 1 cm for the fingers


# ---- physics -----------------------------------------------------------------

def _at(*cells):
    return np.array([0.4, 0.1, U / 2]) + U * np.asarray(cells, dtype=float)


def test_a_tower_with_clearance_still_stands():
    with PhysicsStability() as check:
        tower = [_at((0, 0, z)) for z in range(4)]
        for k in range(1, 4):
            assert check(U, tower[:k], tower[k], clearance=C) == (True, '')
        # An I2 bridging two columns, and a cube on its middle.
        placed = [_at((0, 0, 0)), _at((1, 0, 0)), _at((0, 0, 1), (1, 0, 1))]
        assert check(U, placed, _at((1, 0, 2)), clearance=C) == (True, '')
        with pytest.raises(RadError, match='clearance'):
            check(U, [], _at((0, 0, 0)), clearance=-0.1)


def test_clearance_narrows_the_support_a_block_rests_on():
    """A 2-wide block on one cube, its centre of mass 3/7 unit off the cube's centre: inside the
    flush top face (0.49 unit with the blocks' play), outside it at clearance 0.2 (0.39 unit), inside
    at 0.05 (0.465)."""
    cube = _at((0, 0, 0))
    block = _at(*[(0, 0, z) for z in range(1, 5)], *[(1, 0, z) for z in range(1, 4)])
    with PhysicsStability() as check:
        assert check(U, [cube], block) == (True, '')
        assert check(U, [cube], block, clearance=0.05) == (True, '')
        stable, reason = check(U, [cube], block, clearance=C)
        assert not stable and 'new block' in reason


def test_the_mdp_passes_its_scenes_clearance_to_the_stability_check():
    calls = []

    def check(unit, placed, new, **kw):
        calls.append(kw)
        return True, ''

    for c in (0.0, C):
        s = Scene.from_dict({**doc(), 'clearance': c})
        env = AssemblyEnv(s, EnvConfig(stability='physics'), stability=check)
        env.step(Action(0, 0, env.grid.index(0, (0, 0, 0)), 0))
    assert calls == [{}, {'clearance': C}]


# ---- GAMP ----------------------------------------------------------------------

def test_gamp_plans_a_pick_and_place_with_the_fingers_on_the_narrower_faces():
    from rad_core.allocation import AllocationParams, solve
    from rad_core.gamp import allocated_pose, plan_action
    scene_ = generate_scene(GeneratorConfig(grid=4, clearance=C), seed=1)
    alloc = solve(scene_, AllocationParams(time_limit_s=5.0))
    placement = next(p for p in alloc.placements if p.type == 'I2_up')
    block = next(b for b in scene_.blocks if b.type == 'I2_up')
    position, yaw = allocated_pose(scene_, placement)
    with World(scene_) as world:
        r = plan_action(world, block.id, position, yaw)
    assert r.success, r.reason
    width = U * (1 - C)
    grasp = next(g for g in r.motion.gripper if g.action == 'grasp')
    opening = next(g for g in r.motion.gripper if g.action == 'open')
    assert grasp.position == pytest.approx(width / 2 - 0.001)                   # closed on the 4 cm unit
    assert grasp.expected_position == pytest.approx(width / 2)                  # and held at its faces
    assert opening.position == pytest.approx(width / 2 + 0.01)                  # open 1 cm off its faces


# ---- registration and the twin ------------------------------------------------

def _placed_cube_scene(clearance: float) -> Scene:
    """One cube on a target cell, one on the table."""
    s = scene()
    origin = s.target('front').origin
    blocks = [Block('c0', 'cube', tuple(origin), 0), Block('c1', 'cube', (0.5, -0.2, U / 2), 0)]
    return Scene.from_dict({**s.to_dict(), 'blocks': [b.to_dict() for b in blocks], 'clearance': clearance})


def test_registration_keeps_the_clearance_and_snaps_a_block_that_used_its_room():
    for c in (0.0, C):
        s = _placed_cube_scene(c)
        config = RegistrationConfig(body_map=body_map_for(s))
        assert register_scene(scene_to_bodies(s), s, config) == s
        # 0.3 unit off its cell centre: a block with 0.1 unit of room each side, plus 0.2 unit of
        # placement error, still sits on its cell; a flush block cannot be there.
        bodies = scene_to_bodies(s)
        x, y, z = bodies[0].position
        bodies[0] = RigidBodyPose('c0', (x + 0.3 * U, y, z), bodies[0].quaternion)
        if c:
            got = register_scene(bodies, s, config)
            assert got == s and blocks_on_grid(got, Grid(got)).keys() == {0}
        else:
            with pytest.raises(RadError, match='off its grid'):
                register_scene(bodies, s, config)


def test_a_twin_at_rest_reports_its_scene_with_the_clearance():
    from rad_core.sim.twin import Twin
    s = generate_scene(GeneratorConfig(grid=4, clearance=C), 3)
    with World() as world:
        twin = Twin(world)
        twin.load_scene(s)
        twin.settle(1.0)
        assert twin.current_scene(s) == s


# ---- rendering and Rerun ---------------------------------------------------------

def test_render_draws_the_narrower_blocks():
    flush, spaced = _two_cubes(0.0), _two_cubes(C)
    half = U * 0.94 / 2
    (ca, ha, _), (cb, hb, _) = _scene_boxes(spaced, [], None)[:2]
    assert ha == pytest.approx((half - C * U / 2, half - C * U / 2, half))
    assert hb == ha and cb[0] - ca[0] == pytest.approx(U)
    assert _scene_boxes(flush, [], None)[0][1] == half
    image = render_scene(spaced, width=160, height=120)
    assert image.shape == (120, 160, 3)
    assert not np.array_equal(image, render_scene(flush, width=160, height=120))
    # Placed at grid cells (occupancy), an I2 stays filled between its units.
    s = Scene.from_dict({**doc(), 'clearance': C})
    env = AssemblyEnv(s, EnvConfig(stability='none'))
    assert env.step(Action(2, 0, env.grid.index(0, (0, 0, 0)), 3)).outcome.value == 'placed'   # along x
    boxes = _scene_boxes(s, [], env.state.occupancy)
    i2 = [(c, h) for c, h, _ in boxes[2:4]]
    lo = min(c[0] - h[0] for c, h in i2)
    hi = max(c[0] + h[0] for c, h in i2)
    assert hi - lo == pytest.approx(2 * U - (1 - 0.94) * U - C * U)
    render_scene(s, occupancy=env.state.occupancy, width=80, height=60)


def test_viz_boxes_use_the_narrower_size_and_turn_with_the_block():
    s = Scene.from_dict({**doc(), 'clearance': C})
    half = U * 0.94 / 2
    shape = viz.block_shape(s, 'I2')                      # along x in its own frame
    assert np.allclose(shape.half_sizes, [[half - C * U / 4, half - C * U / 2, half]] * 2)
    assert np.allclose(shape.centers[:, 0], [C * U / 4, U - C * U / 4])
    boxes = viz.block_boxes(s)['i0']                       # i0 lies at yaw 90: along y
    assert np.allclose(boxes.half_sizes, [[half - C * U / 2, half - C * U / 4, half]] * 2)
    assert np.allclose(viz.block_shape(scene(), 'I2').half_sizes, half)
    moved = viz.block_boxes(s, {'i0': ((0.1, 0.2, U / 2), yaw_quaternion(0))})['i0']
    assert np.allclose(moved.half_sizes, shape.half_sizes)

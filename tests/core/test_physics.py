"""PyBullet stability check: verdicts on hand-made structures, reasons, determinism.

Structures are given in integer cell coordinates; `at` turns them into world
unit centres the way the MDP does (cell centre = origin + unit * [i, j, k],
lowest layer resting on the table).
"""

import numpy as np
import pytest
from rad_core.domain.errors import RadError
from rad_core.env.mdp import Action, AssemblyEnv, EnvConfig, Outcome
from rad_core.sim.physics import (
    BLOCK_PLAY,
    PhysicsConfig,
    PhysicsStability,
    add_block_body,
    block_shape,
    direct_client,
    polycube_inertia,
)

from scenes import U, scene

ORIGIN = np.array([0.4, 0.1, U / 2])


def at(*cells, unit=U):
    return ORIGIN * unit / U + unit * np.asarray(cells, dtype=float)


def column(x, height, y=0):
    """One cube per layer, each its own block (as a robot would stack them)."""
    return [at((x, y, z)) for z in range(height)]


@pytest.fixture(scope='module')
def check():
    with PhysicsStability() as c:
        yield c


def test_cube_on_the_table_stands(check):
    assert check(U, [], at((0, 0, 0))) == (True, '')


def test_cube_on_a_cube_stands(check):
    assert check(U, column(0, 1), at((0, 0, 1))) == (True, '')


def test_tall_tower_of_cubes_stands(check):
    assert check(U, column(0, 7), at((0, 0, 7))) == (True, '')


def test_bar_with_its_centre_of_mass_exactly_over_the_edge_falls(check):
    # I2 along x, one unit on a 1-high column, the other over nothing: the centre
    # of mass is exactly above the column's edge. Counted unstable (documented):
    # no real placement is that exact, and the narrowed boxes put it just beyond.
    ok, reason = check(U, column(0, 1), at((0, 0, 1), (1, 0, 1)))
    assert not ok and reason.startswith('new block tipped')


def test_l_with_its_centre_of_mass_over_the_support_stands(check):
    # L3 flat with its corner on a column: centre of mass (1/3, 1/3) unit from the
    # column's axis, inside its top face.
    assert check(U, column(0, 1), at((0, 0, 1), (1, 0, 1), (0, 1, 1))) == (True, '')


def test_l_with_its_centre_of_mass_clearly_outside_falls(check):
    # The same L resting on one end unit: centre of mass 2/3 unit off the column's axis.
    ok, reason = check(U, column(1, 1), at((0, 0, 1), (1, 0, 1), (0, 1, 1)))
    assert not ok and reason.startswith('new block')


def test_cantilever_on_its_end_cube_falls(check):
    ok, reason = check(U, column(0, 2), at((0, 0, 2), (1, 0, 2), (2, 0, 2)))
    assert not ok and reason.startswith('new block')


def test_bridge_over_two_towers_stands(check):
    towers = column(0, 2) + column(2, 2)
    assert check(U, towers, at((0, 0, 2), (1, 0, 2), (2, 0, 2))) == (True, '')


def test_block_floating_high_above_everything_falls(check):
    ok, reason = check(U, column(0, 1), at((3, 0, 4)))
    assert not ok and reason.startswith('new block moved')


def test_pyramid_of_ten_bricks_stands(check):
    layers = ((0, (0, 2, 4, 6)), (1, (1, 3, 5)), (2, (2, 4)))
    bricks = [at((x, 0, z), (x + 1, 0, z)) for z, xs in layers for x in xs]
    assert check(U, bricks, at((3, 0, 3), (4, 0, 3))) == (True, '')


# A seesaw: an I3 balanced on a one-cube column; load on its end tips it.
SEESAW = [at((0, 0, 0)), at((-1, 0, 1), (0, 0, 1), (1, 0, 1))]


def test_light_load_on_the_seesaw_end_stands(check):
    # Centre of mass of I3 + 2 cubes at x = 2/5 unit, inside the column's face.
    assert check(U, SEESAW, at((1, 0, 2), (1, 0, 3))) == (True, '')


def test_heavy_load_knocks_the_seesaw_over_and_the_reason_says_so(check):
    # Four cubes on the end: centre of mass at x = 4/7 unit, beyond the column's edge.
    ok, reason = check(U, SEESAW, at((1, 0, 2), (1, 0, 3), (1, 0, 4), (1, 0, 5)))
    assert not ok
    assert 'placed block 1' in reason


def test_unstable_placed_structure_is_reported_as_destroyed(check):
    # The placed bar already overhangs; the new cube far away is innocent.
    ok, reason = check(U, column(0, 1) + [at((0, 0, 1), (1, 0, 1))], at((5, 0, 0)))
    assert not ok
    assert reason.startswith('placed block 1') and 'structure destroyed' in reason


def test_same_question_same_answer_whatever_was_asked_before():
    cases = [
        (column(0, 2), at((0, 0, 2), (1, 0, 2), (2, 0, 2))),
        (SEESAW, at((1, 0, 2), (1, 0, 3), (1, 0, 4), (1, 0, 5))),
        (column(0, 3), at((0, 0, 3))),
    ]
    with PhysicsStability() as fresh:
        first = [fresh(U, placed, new) for placed, new in cases]
        again = [fresh(U, placed, new) for placed, new in reversed(cases)][::-1]
    with PhysicsStability() as other:
        other(U, column(4, 5), at((4, 0, 5)))
        third = [other(U, placed, new) for placed, new in cases]
    assert first == again == third
    assert [ok for ok, _ in first] == [False, False, True]


def test_verdict_does_not_depend_on_the_unit(check):
    small, big = 0.02, 0.2
    for unit in (small, big):
        assert check(unit, [at((0, 0, 0), unit=unit)], at((0, 0, 1), unit=unit)) == (True, '')
        ok, reason = check(unit, [at((0, 0, 0), unit=unit)], at((0, 0, 1), (1, 0, 1), unit=unit))
        assert not ok
    # Reasons are in the caller's millimetres: a floating block moves at least 5% of its unit.
    for unit in (small, big):
        ok, reason = check(unit, [], at((0, 0, 3), unit=unit))
        mm = float(reason.split('moved ')[1].split(' mm')[0])
        assert not ok and 0.05 * unit * 1000 <= mm <= 0.5 * unit * 1000


def test_close_and_reuse():
    c = PhysicsStability()
    assert c(U, [], at((0, 0, 0)))[0]
    c.close()
    c.close()
    assert c(U, [], at((0, 0, 0)))[0]
    c.close()


def test_bad_inputs_raise():
    with pytest.raises(RadError):
        PhysicsConfig(max_steps=0)
    with pytest.raises(RadError):
        PhysicsConfig(side_gap=-0.1)
    with PhysicsStability() as c:
        with pytest.raises(RadError):
            c(0.0, [], at((0, 0, 0)))
        with pytest.raises(RadError):
            c(U, [], np.zeros((0, 3)))


def test_polycube_inertia_matches_a_solid_box():
    # An I3 is a 3x1x1 box: I = m (b^2 + c^2) / 12 about each axis.
    com, tensor = polycube_inertia(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]]), 0.05, 0.1)
    m, a, b = 0.3, 0.15, 0.05
    assert com == pytest.approx([0.05, 0, 0])
    assert np.diag(tensor) == pytest.approx([m * 2 * b * b / 12, m * (a * a + b * b) / 12, m * (a * a + b * b) / 12])
    # An L3 has a product of inertia: its principal axes are diagonal in x-y.
    _, tensor = polycube_inertia(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), 1.0, 1.0)
    assert tensor[0, 1] == pytest.approx(1 / 3)


def test_both_body_frames_build_the_same_block():
    """block_shape/add_block_body, shared by the stability check ('principal': body frame at the
    centre of mass) and the twin's World ('anchor': the block's frame): one block either way."""
    cfg = PhysicsConfig()
    p, cid = direct_client(cfg)
    try:
        offsets = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 1]])     # an S4-like block: skew inertia
        anchor = np.array([0.3, -0.1, U / 2])
        principal = block_shape(p, cid, offsets, U, cfg)
        own = block_shape(p, cid, offsets, U, cfg, frame='anchor', visual_half=0.49 * U)
        assert principal.visual == -1 and own.visual >= 0
        assert (own.mass, own.inertia) == (principal.mass, principal.inertia) and own.mass == pytest.approx(0.4)
        side, height = U / 2 - cfg.side_gap * U, U / 2 + cfg.overlap * U
        centres = anchor + U * offsets
        bodies = ((principal, (anchor + principal.com).tolist(), principal.axes, {'maximal_coordinates': True,
                                                                                  'damping': 0.0}),
                  (own, anchor.tolist(), [0, 0, 0, 1], {}))
        for shape, position, orientation, kwargs in bodies:
            body = add_block_body(p, cid, shape, position, orientation, cfg, **kwargs)
            # Collision boxes at the cube centres, axis-aligned, a hair narrower and taller: a ray down
            # through a cube meets its column's top, a ray along +x its row's first side face.
            down = p.rayTestBatch((centres + [0, 0, 1]).tolist(), (centres - [0, 0, 1]).tolist(), physicsClientId=cid)
            along = p.rayTestBatch((centres - [1, 0, 0]).tolist(), (centres + [1, 0, 0]).tolist(), physicsClientId=cid)
            for o, hit_down, hit_along in zip(offsets, down, along):
                column = offsets[(offsets[:, 0] == o[0]) & (offsets[:, 1] == o[1])]
                row = offsets[(offsets[:, 1] == o[1]) & (offsets[:, 2] == o[2])]
                assert hit_down[0] == body and hit_along[0] == body
                assert hit_down[3][2] == pytest.approx(anchor[2] + U * column[:, 2].max() + height, abs=1e-6)
                assert hit_along[3][0] == pytest.approx(anchor[0] + U * row[:, 0].min() - side, abs=1e-6)
            info = p.getDynamicsInfo(body, -1, physicsClientId=cid)
            assert info[0] == pytest.approx(0.4) and info[2] == pytest.approx(principal.inertia)
            assert info[1] == pytest.approx(cfg.lateral_friction)
            assert info[3] == pytest.approx(own.com.tolist() if shape is own else [0, 0, 0])   # inertial frame
            p.removeBody(body, physicsClientId=cid)
        with pytest.raises(RadError):
            block_shape(p, cid, offsets, U, cfg, frame='world')
    finally:
        p.disconnect(physicsClientId=cid)


def test_mdp_uses_physics_by_default():
    s = scene()                       # region 'front': 3 x 1 x 2 cells
    env = AssemblyEnv(s, EnvConfig())
    assert env.step(Action(0, 0, env.grid.index(0, (0, 0, 0)), 0)).outcome == Outcome.PLACED
    # I2 (yaw 90) turned to lie along x on top of the cube, its second unit over nothing.
    r = env.step(Action(2, 0, env.grid.index(0, (0, 0, 1)), 3))
    assert r.outcome == Outcome.INVALID_UNSTABLE and r.reason.startswith('new block')


def test_a_block_of_more_units_than_a_pybullet_compound_holds_collides_on_every_unit():
    """PyBullet keeps 16 children of a compound shape and drops the rest without a word: a LEGO 2 x 6
    brick, 36 units of a plate's height, must still be solid at every one of them."""
    import pybullet as p
    from rad_core.sim.physics import MAX_COMPOUND_BOXES, PhysicsConfig, add_block_body, block_shape
    offsets = np.array([[x, y, z] for x in range(6) for y in range(2) for z in range(3)])
    pitch = np.array([0.03, 0.03, 0.012])
    client = p.connect(p.DIRECT)
    try:
        config = PhysicsConfig()
        shape = block_shape(p, client, offsets, pitch, config, frame='anchor')
        assert len(p.getCollisionShapeData(add_block_body(p, client, shape, (0, 0, 0), (0, 0, 0, 1), config), -1,
                                           physicsClientId=client)) <= MAX_COMPOUND_BOXES
        body = add_block_body(p, client, shape, (0, 0, 0), (0, 0, 0, 1), config)
        ball = p.createCollisionShape(p.GEOM_SPHERE, radius=0.001, physicsClientId=client)
        probe = p.createMultiBody(0, ball, basePosition=(5, 5, 5), physicsClientId=client)
        for unit in offsets * pitch:       # a grain of sand at every unit's centre touches the brick
            p.resetBasePositionAndOrientation(probe, unit, (0, 0, 0, 1), physicsClientId=client)
            assert p.getClosestPoints(body, probe, 0.0, physicsClientId=client), f'no collision at unit {unit}'
        p.resetBasePositionAndOrientation(probe, (0.2, 0.0, 0.0), (0, 0, 0, 1), physicsClientId=client)
        assert not p.getClosestPoints(body, probe, 0.0, physicsClientId=client)
    finally:
        p.disconnect(client)


def test_the_check_gives_its_blocks_the_twins_play():
    # The stability check and the twin model the same blocks: what the check holds up by friction
    # against a neighbour across a hairline, the twin's blocks, with play, let fall.
    from rad_core.sim.twin import twin_world_config
    with PhysicsStability() as c:
        assert c.config.side_gap == BLOCK_PLAY == twin_world_config().physics.side_gap > PhysicsConfig().side_gap
    assert PhysicsStability(PhysicsConfig()).config.side_gap == PhysicsConfig().side_gap

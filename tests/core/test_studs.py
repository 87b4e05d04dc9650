"""Scenes of studded bricks: the ``studs`` field, and a lattice whose courses are not a unit high."""

import numpy as np
import pytest
from rad_core.domain.errors import SceneError
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Scene
from rad_core.domain.studs import SYSTEMS

UNIT = 0.03
COURSE = UNIT * 19.2 / 16          # a Duplo brick's height on its pitch, at a 3 cm stud pitch


def brick_doc(studs='duplo', **extra) -> dict:
    """A 2 x 2 brick on the table and a 2 x 4 target two courses high."""
    course = COURSE if studs != 'none' else UNIT
    return {'format': 'rad-scene/1', 'unit': UNIT, 'studs': studs,
            'block_types': {'B22': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]},
            'blocks': [{'id': 'b0', 'type': 'B22', 'position': [0.45, -0.25, course / 2], 'yaw': 0}],
            'targets': [{'name': 't', 'origin': [0.45, 0.05, course / 2], 'size': [4, 2, 2],
                         'filled': [[i, j, k] for i in range(4) for j in range(2) for k in range(2)]}],
            **extra}


def test_a_named_system_fills_in_its_course_and_clutch():
    s = Scene.from_dict(brick_doc())
    assert s.studs.system == 'duplo'
    assert s.course == pytest.approx(COURSE)
    assert s.studs.clutch == SYSTEMS['duplo'].clutch
    assert s.studs.mass == pytest.approx(0.014 / 8 * (UNIT / 0.016) ** 3)        # a Duplo brick scaled up
    assert s.studs.clutch_in_weights == pytest.approx(2.0 / (s.studs.mass * 9.81))
    assert s.pitch == pytest.approx([UNIT, UNIT, COURSE])
    again = Scene.loads(s.dumps())
    assert again.studs == s.studs and again.to_dict() == s.to_dict()
    assert not s.studs.baseplate and 'baseplate' not in s.to_dict()['studs']


def test_a_baseplate_is_kept_and_read_back():
    s = Scene.from_dict(brick_doc({'system': 'duplo', 'baseplate': True}))
    assert s.studs.baseplate and s.to_dict()['studs']['baseplate'] is True
    assert Scene.loads(s.dumps()).studs == s.studs


def test_without_studs_the_lattice_is_cubes_and_the_document_unchanged():
    s = Scene.from_dict(brick_doc('none'))
    assert s.studs is None and s.course == UNIT
    assert 'studs' not in s.to_dict()


def test_the_grid_follows_the_course_height():
    s = Scene.from_dict(brick_doc())
    grid = Grid(s)
    top = grid.index(0, (1, 1, 1))
    assert grid.centres[top] == pytest.approx([0.45 + UNIT, 0.05 + UNIT, COURSE * 1.5])
    assert grid.below_idx[top] == grid.index(0, (1, 1, 0))
    assert grid.on_table.sum() == 8
    assert grid.cell_at(grid.centres[top]) == top
    positions = s.unit_positions(s.block('b0'))
    assert positions[:, 2] == pytest.approx([COURSE / 2] * 4)


@pytest.mark.parametrize('studs,expected', [
    ({'system': 'mine'}, "studs: system 'mine' is not one rad knows"),
    ({'system': 'mine', 'course': 0.03}, 'give its clutch'),
    ({'system': 'duplo', 'course': 0.2}, 'studs.course: 0.2 m is outside 0.2..3 units'),
    ({'system': 'duplo', 'clutch': 0}, 'studs.clutch: 0.0 N is outside'),
    ({'system': 'duplo', 'pull': 3}, "studs: unknown field 'pull'"),
    ({'system': 'mine', 'course': 0.03, 'clutch': 1}, 'give its mass'),
    ({'system': 'duplo', 'mass': 2}, 'studs.mass: 2.0 kg is outside'),
    (7, "studs: expected 'none', a system name"),
    ({'system': 'duplo', 'baseplate': 'yes'}, 'studs.baseplate: expected true or false, got "yes"'),
])
def test_bad_studs_are_named(studs, expected):
    with pytest.raises(SceneError) as e:
        Scene.from_dict(brick_doc(studs))
    assert expected in str(e.value)


def test_a_block_off_the_courses_in_a_region_is_refused():
    doc = brick_doc()
    doc['blocks'].append({'id': 'b1', 'type': 'B22', 'position': [0.45, 0.05, UNIT / 2 + UNIT], 'yaw': 0})
    with pytest.raises(SceneError) as e:
        Scene.from_dict(doc)
    assert 'not on its grid' in str(e.value)


def test_bodies_are_a_course_high_in_the_physics_world():
    from rad_core.sim.world import World

    s = Scene.from_dict(brick_doc())
    with World() as world:
        world.load_scene(s)
        p = world.pybullet
        lo, hi = p.getAABB(world.blocks['b0'], physicsClientId=world.client)
        assert hi[2] - lo[2] == pytest.approx(COURSE, abs=0.002)
        assert hi[0] - lo[0] == pytest.approx(2 * UNIT, abs=0.002)
        for _ in range(240):
            p.stepSimulation(physicsClientId=world.client)
        position, _ = world.block_pose('b0')
        assert position[2] == pytest.approx(COURSE / 2, abs=0.002)      # at rest on the table, not sunk


def test_gamp_places_a_brick_on_its_course():
    from rad_core.gamp.action import SceneAction
    from rad_core.gamp.action import MotionPlanner

    s = Scene.from_dict(brick_doc())
    planner = MotionPlanner()
    try:
        result, position, yaw = planner(s, SceneAction('b0', 0, 't', (0, 0, 0), 0))
    finally:
        planner.close()
    assert result.success, result.reason
    assert position == pytest.approx([0.45, 0.05, COURSE / 2])
    assert np.isclose(position[2], COURSE / 2)

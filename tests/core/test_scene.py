import copy
import json
import math

import numpy as np
import pytest
from rad_core.domain.errors import SceneError
from rad_core.domain.scene import MAX_GRID_CELLS, Scene

from scenes import U, doc, mutated, scene


def test_round_trip_through_json_is_lossless():
    s = scene()
    again = Scene.loads(s.dumps())
    assert again.to_dict() == s.to_dict()
    assert again.blocks[2].yaw == 90
    assert s.num_target_cells == 4


def test_unit_positions_follow_yaw_about_the_anchor():
    s = scene()
    pts = s.unit_positions(s.block('i0'))
    assert pts[0] == pytest.approx([0.6, -0.2, U / 2])
    assert pts[1] == pytest.approx([0.6, -0.2 + U, U / 2])


def test_first_cell_of_a_type_is_the_anchor_even_if_not_origin():
    d = doc(types={'cube': [[0, 0, 0]], 'I2': [[1, 1, 0], [2, 1, 0]], 'L3_up': [[0, 0, 0], [1, 0, 0], [0, 0, 1]]})
    assert Scene.from_dict(d).block_types['I2'].offsets == ((0, 0, 0), (1, 0, 0))


def _error(d) -> str:
    with pytest.raises(SceneError) as e:
        Scene.from_dict(d)
    return str(e.value)


@pytest.mark.parametrize('path,value,expected', [
    ('format', 'rad-scene/2', 'format: expected'),
    ('unit', -1, 'unit:'),
    ('unit', float('nan'), 'unit: must be finite'),
    ('unit', float('inf'), 'unit: must be finite'),
    ('unit', True, 'unit: expected a number'),
    ('blocks[0].type', 'Z9', "blocks[0].type: unknown block type 'Z9'"),
    ('blocks[0].yaw', 45, 'blocks[0].yaw: 45 is not a multiple of 90'),
    ('blocks[0].yaw', 'ninety', 'blocks[0].yaw: expected degrees'),
    ('blocks[0].position', [0.4, float('nan'), 0.025], 'blocks[0].position[1]: must be finite'),
    ('blocks[0].position', [0.4, 0.1], 'blocks[0].position: expected a list of 3 numbers'),
    ('blocks[0].position', [0.4, -0.2, -0.5], 'below the table'),
    ('blocks[0].position', [1e9, 0, 0.025], 'out of range'),
    ('blocks[1].id', 'c0', "duplicate id 'c0'"),
    ('blocks[0].id', '', 'blocks[0].id: expected a non-empty string'),
    ('blocks[1].position', [0.4, -0.2, U / 2], "blocks[1]: block 'c1' overlaps block 'c0'"),
    ('blocks[1].position', [0.4 + U * 0.5, -0.2, U / 2], 'overlaps'),
    ('block_types.I2', [[0, 0, 0], [0.5, 0, 0]], 'block_types.I2[1][0]: expected an integer'),
    ('block_types.I2', [[0, 0, 0], [0, 0, 0]], 'same cell twice'),
    ('block_types.I2', [[0, 0, 0], [2, 0, 0]], 'not face-connected'),
    ('block_types.I2', [], 'block_types.I2: expected a list'),
    ('targets', [], 'targets: expected a non-empty list'),
    ('targets[0].filled', [], 'targets[0].filled: is empty'),
    ('targets[0].filled', [[0, 0, 0], [3, 0, 0]], 'targets[0].filled[1]: cell [3, 0, 0] is outside the box'),
    ('targets[0].filled', [[0, 0, 0], [1.5, 0, 0]], 'targets[0].filled[1][0]: expected an integer'),
    ('targets[0].filled', [[0, 0, 0], [0, 0, 0]], 'same cell twice'),
    ('targets[0].size', [3, 1, 0], 'targets[0].size[2]: 0 cells'),
    ('targets[0].size', [500, 1, 2], 'targets[0].size[0]: 500 cells is outside'),
    ('targets[0].origin', [0.45, float('inf'), 0.025], 'targets[0].origin[1]: must be finite'),
    ('blocks[0].colour', 'red', "blocks[0]: unknown field 'colour'"),
    ('blocks[0].yaw', KeyError, "blocks[0]: missing field 'yaw'"),
])
def test_bad_input_names_the_field(path, value, expected):
    assert expected in _error(mutated(path, value))


def test_integer_valued_floats_are_accepted_for_cells():
    d = mutated('targets[0].filled', [[0.0, 0, 0]])
    assert Scene.from_dict(d).targets[0].filled == ((0, 0, 0),)


def test_not_json_and_nan_literals():
    with pytest.raises(SceneError, match='not valid JSON'):
        Scene.loads('{"format": ')
    text = json.dumps(doc()).replace('0.4,', 'NaN,', 1)
    with pytest.raises(SceneError, match='must be finite'):
        Scene.loads(text)
    with pytest.raises(SceneError, match='a scene must be a JSON object'):
        Scene.loads('[1, 2]')


def test_huge_grid_is_refused_quickly():
    targets = [{'name': f't{n}', 'origin': [0.3 + n * 1.3, 0.3, U / 2], 'size': [24, 24, 24],
                'filled': [[0, 0, 0]]} for n in range(2)]
    assert f'exceed the limit of {MAX_GRID_CELLS}' in _error(doc(targets=targets))


def test_overlapping_regions_are_refused():
    t = doc()['targets'][0]
    other = dict(t, name='back', origin=[0.45 + U, 0.1, U / 2])
    assert "overlaps region 'front'" in _error(doc(targets=[t, other]))


def test_block_on_the_grid_is_accepted_and_off_grid_in_region_refused():
    blocks = doc()['blocks']
    on_grid = dict(blocks[0], position=[0.45, 0.1, U / 2])
    assert Scene.from_dict(doc(blocks=[on_grid] + blocks[1:])).blocks[0].position[0] == 0.45
    off_grid = dict(blocks[0], position=[0.45 + 0.4 * U, 0.1, U / 2])
    assert 'sticks into' in _error(doc(blocks=[off_grid] + blocks[1:])) or 'not on its grid' in _error(
        doc(blocks=[off_grid] + blocks[1:]))
    half_in = dict(blocks[2], position=[0.45, 0.1 - U, U / 2])  # I2 at yaw 90: one unit in, one out
    assert 'sticks out' in _error(doc(blocks=blocks[:2] + [half_in]))


def test_error_messages_are_single_lines():
    for path, value in [('unit', math.nan), ('blocks[0].type', 'nope'), ('targets', [])]:
        assert '\n' not in _error(mutated(path, value))


def test_type_counts_and_positions_are_numpy_friendly():
    s = scene()
    assert s.type_counts() == {'cube': 2, 'I2': 1, 'L3_up': 0}
    assert isinstance(s.unit_positions(s.blocks[0]), np.ndarray)


def test_measured_offsets_round_trip_and_are_checked():
    d = doc()
    d['measured_offsets'] = {'c1': [0.002, -0.001]}
    s = Scene.from_dict(d)
    assert s.measured_offsets == {'c1': (0.002, -0.001)} and s.offset('c0').tolist() == [0, 0, 0]
    assert Scene.loads(s.dumps()).measured_offsets == s.measured_offsets
    assert 'measured_offsets' not in scene().to_dict()        # scenes without them keep their documents
    assert s == scene()                                         # the same scene: only the planning world differs
    for bad, field, problem in [({'x9': [0, 0]}, 'measured_offsets.x9', 'unknown block id'),
                                ({'c1': [0.03, 0]}, 'measured_offsets.c1', 'half a unit'),
                                ({'c1': [0.001]}, 'measured_offsets.c1', r'expected \[dx, dy\] \(m\) or'),
                                ([1, 2], 'measured_offsets', 'expected an object')]:
        d['measured_offsets'] = bad
        with pytest.raises(SceneError, match=problem) as e:
            Scene.from_dict(d)
        assert e.value.field == field


def test_moving_a_block_drops_its_measured_offset_only():
    from rad_core.sequencing.planning.plan import moved
    d = doc()
    d['measured_offsets'] = {'c0': [0.002, 0.0], 'c1': [0.0, 0.001]}
    s = moved(Scene.from_dict(d), 'c1', (0.5, -0.3, U / 2), 0)
    assert s.measured_offsets == {'c0': (0.002, 0.0)}


def test_obstacles_round_trip_and_are_checked():
    d = doc()
    d['obstacles'] = [{'id': 'x0', 'type': 'cube', 'position': [0.3, 0.3, 0.025], 'quaternion': [0, 0, 0.5, 0.8660254]}]
    s = Scene.from_dict(d)
    assert s.obstacles[0].id == 'x0' and s.obstacles[0].quaternion == pytest.approx((0, 0, 0.5, 0.8660254))
    assert Scene.loads(s.dumps()).obstacles == s.obstacles and s == scene()
    for change, field, problem in [({'id': 'c0'}, 'obstacles[0].id', 'also a block'),
                                   ({'type': 'dodecahedron'}, 'obstacles[0].type', 'unknown block type'),
                                   ({'type': ['cube']}, 'obstacles[0].type', 'unknown block type'),
                                   ({'quaternion': [0, 0, 0, 2]}, 'obstacles[0].quaternion', 'not unit length'),
                                   ({'position': [0.3, 0.3]}, 'obstacles[0].position', 'expected')]:
        bad = copy.deepcopy(d)
        bad['obstacles'][0].update(change)
        with pytest.raises(SceneError, match=problem) as e:
            Scene.from_dict(bad)
        assert e.value.field == field


def test_a_measured_turn_is_an_offset_of_at_most_45_degrees():
    d = doc()
    d['measured_offsets'] = {'c1': [0.0, 0.0, -30.0]}
    s = Scene.from_dict(d)
    assert s.turn('c1') == -30.0 and s.turn('c0') == 0.0 and s.offset('c1').tolist() == [0, 0, 0]
    d['measured_offsets'] = {'c1': [0.0, 0.0, 50.0]}
    with pytest.raises(SceneError, match='more than 45'):
        Scene.from_dict(d)


def test_a_design_round_trips_and_each_pose_is_checked():
    d = doc()
    d['design'] = [{'type': 'L3_up', 'target': 'front', 'yaw': 0, 'cells': [[0, 0, 0], [1, 0, 0], [0, 0, 1]]},
                   {'type': 'I2', 'target': 'front', 'yaw': 90, 'cells': [[2, 0, 1], [2, 0, 0]]}]
    with pytest.raises(SceneError, match=r'not the cells of a I2 at yaw 90') as e:
        Scene.from_dict(d)                  # at yaw 90 an I2 lies along y; the region is one cell deep
    assert e.value.field == 'design[1].cells'
    d['design'][1] = {'type': 'cube', 'target': 'front', 'yaw': 0, 'cells': [[2, 0, 0]]}
    s = Scene.from_dict(d)
    assert [(p.type, p.cells) for p in s.design] == [('L3_up', ((0, 0, 0), (1, 0, 0), (0, 0, 1))),
                                                     ('cube', ((2, 0, 0),))]
    assert Scene.loads(s.dumps()) == s and 'design' not in scene().to_dict()
    cube = {'type': 'cube', 'target': 'front', 'yaw': 0}
    for pose, field, problem in [({**cube, 'cells': [[0, 0, 1]]}, 'design[2].cells', r'also in design\[0\]'),
                                 ({**cube, 'cells': [[3, 0, 0]]}, 'design[2].cells', 'outside region'),
                                 ({**cube, 'cells': [[2, 0, 1], [1, 0, 1]]}, 'design[2].cells', 'the 1 cells'),
                                 ({**cube, 'target': 'back', 'cells': [[2, 0, 1]]}, 'design[2].target',
                                  'unknown target region'),
                                 ({**cube, 'type': 'S4', 'cells': [[2, 0, 1]]}, 'design[2].type', 'unknown block'),
                                 ({**cube, 'yaw': 45, 'cells': [[2, 0, 1]]}, 'design[2].yaw', 'multiple of 90'),
                                 ({'type': 'cube', 'cells': [[2, 0, 1]]}, 'design[2]', 'missing field')]:
        bad = copy.deepcopy(d)
        bad['design'].append(pose)
        with pytest.raises(SceneError, match=problem) as e:
            Scene.from_dict(bad)
        assert e.value.field == field

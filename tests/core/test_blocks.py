import numpy as np
import pytest
from rad_core.domain.blocks import DEFAULT_LIBRARY, BlockType, canonical_shape, rotation_z


def test_rotation_is_exact_and_counter_clockwise():
    assert rotation_z(90) @ np.array([1, 0, 0]) == pytest.approx([0, 1, 0])
    assert np.array_equal(rotation_z(360), np.eye(3))
    for yaw in (0, 90, 180, 270):
        r = rotation_z(yaw)
        assert np.array_equal(r @ r.T, np.eye(3, dtype=int))


def test_library_has_the_predecessor_set_and_anchors_at_origin():
    for name in ('cube', 'I2', 'I3', 'I2_up', 'L3', 'L3_up', 'T4', 'T4_up', 'O4_up', 'S4_up'):
        t = DEFAULT_LIBRARY[name]
        assert t.offsets[0] == (0, 0, 0)
        assert t.is_connected()
    assert DEFAULT_LIBRARY['T4'].size == 4
    assert all(o[2] == 0 for o in DEFAULT_LIBRARY['L3'].offsets)       # flat
    assert any(o[2] == 1 for o in DEFAULT_LIBRARY['L3_up'].offsets)    # upright
    assert all(o[1] == 0 for o in DEFAULT_LIBRARY['S4_up'].offsets)    # in the x-z plane


@pytest.mark.parametrize('name,expected', [('cube', 1), ('I2', 2), ('I3', 2), ('I2_up', 1), ('L3', 4),
                                           ('O4_up', 2), ('T4', 4)])
def test_distinct_yaws_counts_symmetries(name, expected):
    assert len(DEFAULT_LIBRARY[name].distinct_yaws()) == expected


def test_rotated_keeps_anchor_and_turns_about_z():
    l3 = DEFAULT_LIBRARY['L3']
    assert l3.rotated(90).tolist() == [[0, 0, 0], [0, 1, 0], [-1, 0, 0]]


def test_from_cells_shifts_to_first_cell_and_detects_disconnected():
    t = BlockType.from_cells('x', [[2, 2, 0], [3, 2, 0]])
    assert t.offsets == ((0, 0, 0), (1, 0, 0))
    assert not BlockType.from_cells('gap', [[0, 0, 0], [2, 0, 0]]).is_connected()


def test_canonical_shape_ignores_translation_and_order():
    a = np.array([[0, 0, 0], [1, 0, 0]])
    assert canonical_shape(a + 5) == canonical_shape(a[::-1])
    assert canonical_shape(a) != canonical_shape(np.array([[0, 0, 0], [0, 1, 0]]))

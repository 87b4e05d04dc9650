import numpy as np
import pytest

from rad_core.errors import RadError
from rad_core.generator import GeneratorConfig, generate_scene, inside_polygon, target_statistics
from rad_core.scene import Scene


def test_same_seed_same_scene_other_seed_other_scene():
    a = generate_scene(GeneratorConfig(grid=4), 11)
    assert generate_scene(GeneratorConfig(grid=4), 11).to_dict() == a.to_dict()
    assert generate_scene(GeneratorConfig(grid=4), 12).to_dict() != a.to_dict()


@pytest.mark.parametrize('grid', [1, 3, 5, 8])
@pytest.mark.parametrize('sides', [1, 2])
def test_generated_scenes_are_valid_documents(grid, sides):
    for seed in range(5):
        s = generate_scene(GeneratorConfig(grid=grid, sides=sides), seed)
        again = Scene.loads(s.dumps())   # full validation: no overlaps, nothing in the regions
        assert len(again.targets) == sides
        for t in again.targets:
            assert t.size == (grid, 1, grid)
            assert all(c[2] < grid and c[0] < grid for c in t.filled)
        # Every target shape stands on the table.
        assert any(c[2] == 0 for t in again.targets for c in t.filled)


def test_two_sided_regions_form_one_structure_two_cells_deep():
    s = generate_scene(GeneratorConfig(grid=4, sides=2), 0)
    left, right = s.targets
    assert (left.name, right.name) == ('left', 'right')
    assert left.origin[1] - right.origin[1] == pytest.approx(s.unit)
    assert left.origin[0] == right.origin[0] and left.origin[2] == pytest.approx(s.unit / 2)


def test_calibrated_to_the_papers_target_sizes():
    # The paper: about 5 target cells on average at g=3 and about 12 at g=5.
    g3 = target_statistics(GeneratorConfig(grid=3), 300)['target_cells_mean']
    g5 = target_statistics(GeneratorConfig(grid=5), 300)['target_cells_mean']
    assert 4.5 <= g3 <= 6.5
    assert 10.5 <= g5 <= 13.5


def test_blocks_lie_on_the_table_clear_of_the_structure():
    s = generate_scene(GeneratorConfig(grid=6), 3)
    for b in s.blocks:
        pts = s.unit_positions(b)
        assert np.allclose(pts[:, 2].min(), s.unit / 2)
        assert pts[:, 1].max() < -0.05


def test_point_in_polygon():
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    pts = np.array([[1, 1], [3, 1], [0.5, 1.9], [-0.1, 0.5]])
    assert inside_polygon(pts, square).tolist() == [True, False, True, False]


@pytest.mark.parametrize('kw', [{'grid': 0}, {'grid': 40}, {'sides': 3}, {'unit': 5.0}])
def test_bad_generator_settings(kw):
    with pytest.raises(RadError):
        generate_scene(GeneratorConfig(**kw))

import math

import numpy as np
import pytest
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene, inside_polygon, target_statistics
from rad_core.domain.scene import Scene


def test_same_seed_same_scene_other_seed_other_scene():
    a = generate_scene(GeneratorConfig(grid=4), 11)
    assert generate_scene(GeneratorConfig(grid=4), 11).to_dict() == a.to_dict()
    assert generate_scene(GeneratorConfig(grid=4), 12).to_dict() != a.to_dict()


@pytest.mark.parametrize('grid', [1, 3, 5, 8])
@pytest.mark.parametrize('sides', [1, 2])
def test_generated_scenes_are_valid_documents(grid, sides):
    # Two g = 8 faces often have more blocks than fit within the arm's reach.
    reach = math.inf if grid == 8 else GeneratorConfig.reach
    for seed in range(5):
        s = generate_scene(GeneratorConfig(grid=grid, sides=sides, reach=reach), seed)
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


def _footprint(scene, block):
    """(x0, x1, y0, y1) of a block's footprint on the table."""
    pts, h = scene.unit_positions(block), scene.unit / 2
    return pts[:, 0].min() - h, pts[:, 0].max() + h, pts[:, 1].min() - h, pts[:, 1].max() + h


def _apart(a, b, gap) -> bool:
    return a[1] + gap <= b[0] + 1e-9 or b[1] + gap <= a[0] + 1e-9 or \
        a[3] + gap <= b[2] + 1e-9 or b[3] + gap <= a[2] + 1e-9


def test_blocks_lie_on_the_table_clear_of_the_structure():
    config = GeneratorConfig(grid=6)
    s = generate_scene(config, 3)
    assert any(b.position[1] > 0 for b in s.blocks) and any(b.position[1] < 0 for b in s.blocks)
    for b in s.blocks:
        pts = s.unit_positions(b)
        assert np.allclose(pts[:, 2].min(), s.unit / 2)
        x0, x1, y0, y1 = _footprint(s, b)
        assert y0 >= s.unit + config.gap - 1e-9 or y1 <= -s.unit - config.gap + 1e-9


@pytest.mark.parametrize('grid', [5, 6])
def test_every_block_within_the_arms_reach_and_gap_apart(grid):
    config = GeneratorConfig(grid=grid)
    for seed in range(8):
        s = generate_scene(config, seed)
        for b in s.blocks:
            assert np.hypot(*s.unit_positions(b)[:, :2].T).max() <= config.reach
        boxes = [_footprint(s, b) for b in s.blocks]
        assert all(_apart(a, b, config.gap) for i, a in enumerate(boxes) for b in boxes[:i])


def test_scenes_within_reach_keep_their_layout():
    # reach=inf is the layout from before reach existed (every block on the right).
    kept = 0
    for grid in (3, 4, 5):
        for seed in range(10):
            old = generate_scene(GeneratorConfig(grid=grid, reach=math.inf), seed)
            new = generate_scene(GeneratorConfig(grid=grid), seed)
            if all(np.hypot(*old.unit_positions(b)[:, :2].T).max() <= 0.77 for b in old.blocks):
                assert new.to_dict() == old.to_dict()
                kept += 1
            else:   # only the blocks out of reach move, to the left; nothing else changes
                assert new.targets == old.targets
                moved = [n for n, b in enumerate(old.blocks) if new.blocks[n] != b]
                assert moved and all(new.blocks[n].position[1] > 0 for n in moved)
                assert [(b.type, b.yaw) for b in new.blocks] == [(b.type, b.yaw) for b in old.blocks]
    assert kept >= 20
    assert generate_scene(GeneratorConfig(grid=3), 0).blocks[0].position == (0.325, -0.145, 0.025)


def test_too_many_blocks_for_the_reach():
    with pytest.raises(RadError, match=r'blocks of a g=4 scene do not fit .* reach of 0.77 m.*smaller extra_fraction'):
        generate_scene(GeneratorConfig(grid=4, extra_fraction=20.0, supply='table'), 0)
    # By default (supply 'auto') such a scene gets a feeder instead.
    assert generate_scene(GeneratorConfig(grid=4, extra_fraction=20.0), 0).feeder is not None


def test_point_in_polygon():
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    pts = np.array([[1, 1], [3, 1], [0.5, 1.9], [-0.1, 0.5]])
    assert inside_polygon(pts, square).tolist() == [True, False, True, False]


@pytest.mark.parametrize('kw', [{'grid': 0}, {'grid': 40}, {'sides': 3}, {'unit': 5.0},
                                {'reach': 0}, {'reach': -1.0}, {'reach': math.nan}, {'reach': '0.8'},
                                {'supply': 'shelf'}, {'feeder_order': 'fifo'}, {'feeder_window': 0}])
def test_bad_generator_settings(kw):
    with pytest.raises(RadError):
        generate_scene(GeneratorConfig(**kw))

"""The hard hand-made cases: valid scenes, buildable tilings, layouts in reach, decoys, splits."""

from collections import Counter
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from rad_core.domain import hard_shapes as hs
from rad_core.domain import shapes
from rad_core.domain.blocks import canonical_shape
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.gamp.grasps import block_grasps

REPO = Path(__file__).resolve().parents[2]
SCENE_DIR = REPO / 'scenes' / 'hard'
NAMES = list(hs.CASES)


@lru_cache(maxsize=None)
def scene_of(name: str, seed: int = 0) -> Scene:
    return hs.hard_scene(name, seed)


def world_order(case) -> list[tuple]:
    return [piece[2] for _, piece in hs.buildable_tiling(case.spec)]


def test_enough_cases_both_units_and_every_kind_of_hardness():
    cases = hs.CASES.values()
    assert len(hs.CASES) >= 16
    assert {c.unit for c in cases} == {0.04, 0.05}
    assert sum(c.layout.gap <= 0.02 for c in cases) >= 4                       # blocks packed tight
    assert sum(c.layout.reach[1] >= 0.7 for c in cases) >= 3                   # blocks near the edge of reach
    assert sum(hs.edge_distance(c) >= 0.7 for c in cases) >= 5                 # targets near the edge of reach
    assert sum(abs(c.at[1]) >= 0.15 for c in cases) >= 2                       # targets off to one side
    assert sum(bool(c.spec.decoys) for c in cases) >= 6                        # ungraspable decoys
    used = {n for c in cases for n in c.spec.tiling_types}
    assert {'P5', 'L5', 'T5', 'I5'} <= used
    assert any(c.spec.num_target_cells >= 40 and len(scene_of(c.name).blocks) >= 28 for c in cases)  # large slab


def test_split_is_disjoint_covers_every_case_and_holds_out_ten():
    train, held = set(hs.HARD_SPLITS['train']), set(hs.HARD_SPLITS['holdout'])
    assert not train & held
    assert train | held == set(hs.CASES)
    assert len(held) >= 10
    # Every family that is trained on is also measured.
    assert {hs.CASES[n].spec.family for n in train} <= {hs.CASES[n].spec.family for n in held}


@pytest.mark.parametrize('name', NAMES)
def test_case_is_a_valid_scene_that_round_trips(name):
    scene = scene_of(name)
    again = Scene.from_dict(scene.to_dict())
    assert again.to_dict() == scene.to_dict()
    case = hs.CASES[name]
    assert scene.unit == case.unit
    assert [(t.name, t.size, t.filled) for t in scene.targets] == \
        [(r.name, r.size, tuple(sorted(r.cells))) for r in case.spec.regions]
    for t in scene.targets:
        assert t.origin[2] == pytest.approx(case.unit / 2)


@pytest.mark.parametrize('name', NAMES)
def test_blocks_lie_on_the_table_within_the_layouts_reach_and_gap(name):
    case, scene = hs.CASES[name], scene_of(name)
    u, layout = case.unit, case.layout
    taken = []
    for b in scene.blocks:
        pts = scene.unit_positions(b)
        assert pts[:, 2].min() == pytest.approx(u / 2), b
        r = np.linalg.norm(pts[:, :2], axis=1)
        assert r.min() >= layout.reach[0] - 1e-9 and r.max() <= layout.reach[1] + 1e-9, (b, r)
        for t in scene.targets:
            lo, hi = t.bounds(u)
            assert not np.any(np.all((pts[:, :2] > lo[:2] - u) & (pts[:, :2] < hi[:2] + u), axis=1)), b
        taken.append(pts)
    for i in range(len(taken)):
        for j in range(i + 1, len(taken)):
            d = np.abs(taken[i][:, None, :2] - taken[j][None, :, :2]).max(axis=-1)
            assert d.min() >= u + layout.gap - 1e-6


@pytest.mark.parametrize('name', NAMES)
def test_tiling_is_exact_stable_and_buildable_by_a_top_down_hand(name):
    case = hs.CASES[name]
    pieces = hs.hard_tiling(case.spec)
    for region, region_pieces in zip(case.spec.regions, pieces):
        cells = [c for _, _, p in region_pieces for c in p]
        assert sorted(cells) == sorted(region.cells)                        # exact: every cell once
        for kind, yaw, p in region_pieces:
            assert kind in case.spec.tiling_types and kind not in hs.UNGRASPABLE
            assert canonical_shape(np.asarray(p)) == canonical_shape(hs.HARD_LIBRARY[kind].rotated(yaw))
        assert shapes.stable_order([p for _, _, p in region_pieces]) is not None
    # The search's order, checked on its own: stable and with free finger sides at every step.
    assert hs.order_problem(world_order(case)) == ''
    assert hs.edge_distance(case) <= hs.EDGE_RADIUS


@pytest.mark.parametrize('name', NAMES)
def test_blocks_are_the_tiling_plus_spares_plus_decoys_and_decoys_are_not_needed(name):
    case, scene = hs.CASES[name], scene_of(name)
    have = Counter(b.type for b in scene.blocks)
    need = Counter(kind for region in hs.hard_tiling(case.spec) for kind, _, _ in region)
    assert all(have[k] >= n for k, n in need.items())                        # a perfect build exists
    assert sum(have.values()) == sum(need.values()) + case.spec.n_spare + len(case.spec.decoys)
    for kind in case.spec.decoys:
        assert block_grasps(scene.block_types[kind], scene.unit) == ()        # the hand cannot take them
    graspable = Counter({k: n for k, n in have.items() if k not in hs.UNGRASPABLE})
    assert sum(graspable.values()) - sum(need.values()) == case.spec.n_spare


def test_the_order_check_refuses_what_a_flush_hand_cannot_do():
    # A 2x1 row: the second cube has a built neighbour on one side along x and nothing
    # along y, so it is held across y; a 2x2 layer's last cube has a neighbour both ways.
    row = [((0, 0, 0),), ((1, 0, 0),)]
    assert hs.order_problem(row) == ''
    square = [((0, 0, 0),), ((1, 0, 0),), ((0, 1, 0),), ((1, 1, 0),)]
    assert 'no unit with free finger sides' in hs.order_problem(square)
    # A cube floating over nothing; one brought in under a cantilever already built.
    assert 'rest stably' in hs.order_problem([((0, 0, 1),)])
    cantilever = ((0, 0, 0), (0, 0, 1), (1, 0, 1))
    assert hs.order_problem([cantilever]) == ''
    assert 'cannot come down from above' in hs.order_problem([cantilever, ((1, 0, 0),)])


def test_a_flush_solid_square_top_has_no_buildable_tiling():
    spec = hs.HardSpec('square', 'test', shapes.one_sided(shapes.layers(['##', '##'])), ('cube', 'I2'))
    with pytest.raises(RadError, match='no exact tiling .* top-down'):
        hs.buildable_tiling(spec)


def test_seed_moves_blocks_only_and_one_seed_is_reproducible():
    a, b, again = scene_of('large_slab', 0), scene_of('large_slab', 1), hs.hard_scene('large_slab', 0)
    assert a.to_dict() == again.to_dict()
    assert a.targets == b.targets
    assert Counter(x.type for x in a.blocks) == Counter(x.type for x in b.blocks)
    assert [x.position for x in a.blocks] != [x.position for x in b.blocks]


def test_bad_names_and_types_are_refused_by_name():
    with pytest.raises(RadError, match="unknown hard shape 'nope'"):
        hs.hard_scene('nope')
    with pytest.raises(RadError, match='unknown hard split'):
        hs.split_scenes('test')
    with pytest.raises(RadError, match='cannot be grasped'):
        hs.HardSpec('x', 'test', shapes.one_sided(shapes.face('##')), ('O4',))
    with pytest.raises(RadError, match='unknown block types'):
        hs.HardSpec('x', 'test', shapes.one_sided(shapes.face('##')), ('Q9',))


@pytest.mark.parametrize('name', NAMES)
def test_committed_scene_file_is_what_the_module_makes(name):
    path = SCENE_DIR / f'{name}.json'
    assert path.is_file(), f'{path} missing: run scripts/make_hard_shapes.py'
    assert path.read_text() == scene_of(name).dumps() + '\n', f'{path} is stale: run scripts/make_hard_shapes.py'


@pytest.mark.slow
def test_every_target_cell_and_table_block_is_reachable_top_down():
    """IK (no collisions) for a top-down hand at every target cell and every block's units,
    and above each target cell at the approach height: near the edge, but in reach."""
    from rad_core.gamp.ik import solve_top_down
    from rad_core.sim.world import World
    with World() as world:
        for name in NAMES:
            scene = scene_of(name)
            points = [t.cell_center(c, scene.unit) for t in scene.targets for c in t.filled]
            points += [p + np.array([0, 0, 0.12]) for p in points]
            points += [p for b in scene.blocks for p in scene.unit_positions(b)]
            for p in points:
                assert any(solve_top_down(world, p, yaw).ok for yaw in (0.0, np.pi / 2)), (name, p)

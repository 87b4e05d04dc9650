"""The hand-designed shapes: valid scenes, exact tilings, committed files, splits, allocations."""

from collections import Counter
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from rad_core.allocation import solve, validate_allocation
from rad_core.domain import shapes
from rad_core.domain.coverage import placements_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene

REPO = Path(__file__).resolve().parents[2]
SCENE_DIR = REPO / 'scenes' / 'shapes'
NAMES = list(shapes.SPECS)


@lru_cache(maxsize=None)
def scene_of(name: str, seed: int = 0) -> Scene:
    return shapes.shape_scene(name, seed)


@pytest.mark.parametrize('name', NAMES)
def test_shape_is_a_valid_scene_with_its_drawn_target(name):
    scene = shapes.SHAPES[name]()
    again = Scene.from_dict(scene.to_dict())
    assert again.to_dict() == scene.to_dict()
    spec = shapes.SPECS[name]
    assert [(t.name, t.size, t.filled) for t in again.targets] == \
        [(r.name, r.size, tuple(sorted(r.cells))) for r in spec.regions]
    for t in again.targets:
        assert t.origin[2] == pytest.approx(scene.unit / 2)      # stands on the table
        assert any(c[2] == 0 for c in t.filled)


@pytest.mark.parametrize('name', NAMES)
def test_blocks_lie_on_the_table_in_reach_and_clear_of_the_structure(name):
    scene = scene_of(name)
    u = scene.unit
    taken = []
    for b in scene.blocks:
        pts = scene.unit_positions(b)
        assert pts[:, 2].min() == pytest.approx(u / 2), b     # resting on the table, not in or under it
        r = np.linalg.norm(pts[:, :2], axis=1)
        assert r.min() >= 0.3 and r.max() <= 0.65, (b, r)
        for t in scene.targets:
            lo, hi = t.bounds(u)
            inside = np.all((pts[:, :2] > lo[:2] - u) & (pts[:, :2] < hi[:2] + u), axis=1)
            assert not inside.any(), (b, t.name)
        taken.append(pts)
    # Gripper room: units of different blocks at least a unit plus a gap apart (Chebyshev, in xy).
    for i in range(len(taken)):
        for j in range(i + 1, len(taken)):
            d = np.abs(taken[i][:, None, :2] - taken[j][None, :, :2]).max(axis=-1)
            assert d.min() >= u + shapes.LayoutConfig().gap - 1e-6


@pytest.mark.parametrize('name', NAMES)
def test_blocks_tile_the_target_exactly_with_spares(name):
    spec = shapes.SPECS[name]
    scene = scene_of(name)
    tiling = shapes.tiling(spec)
    for region, pieces in zip(spec.regions, tiling):
        cells = [c for _, _, placed in pieces for c in placed]
        assert sorted(cells) == sorted(region.cells)                # exact: no gap, no overlap
        assert shapes.stable_order([p for _, _, p in pieces]) is not None
    needed = Counter(n for pieces in tiling for n, _, _ in pieces)
    have = Counter(b.type for b in scene.blocks)
    assert not needed - have
    assert sum(have.values()) - sum(needed.values()) == spec.n_spare > 0


def test_committed_files_are_what_the_module_writes():
    files = sorted(p.stem for p in SCENE_DIR.glob('*.json'))
    assert files == sorted(NAMES), 'run: .venv/bin/python scripts/make_shapes.py'
    for name in NAMES:
        assert (SCENE_DIR / f'{name}.json').read_text() == scene_of(name).dumps() + '\n', \
            f'{name}.json is stale: run .venv/bin/python scripts/make_shapes.py'


def test_splits_are_disjoint_and_cover_every_shape():
    train, holdout = set(shapes.SPLITS['train']), set(shapes.SPLITS['holdout'])
    assert set(shapes.SPLITS) == {'train', 'holdout'}
    assert len(train) == len(shapes.SPLITS['train']) and len(holdout) == len(shapes.SPLITS['holdout'])
    assert not train & holdout
    assert train | holdout == set(NAMES)
    assert 0.5 <= len(train) / len(NAMES) <= 0.7
    held = [shapes.SPECS[n] for n in holdout]
    assert any(s.custom for s in held)
    assert any(s.family in ('arch', 'bridge') for s in held)
    assert any(shapes.SPECS[n].custom for n in train)


def test_the_shape_set_has_what_it_is_for():
    families = Counter(s.family for s in shapes.SPECS.values())
    for family in ('arch', 'bridge', 'tower', 'stairs', 'tee', 'overhang', 'frame', 'solid', 'cluster', 'two-sided'):
        assert families[family] >= 1, family
    custom = [n for n in NAMES if shapes.SPECS[n].custom]
    assert len(custom) >= 2
    for name in custom:
        scene = scene_of(name)
        assert set(scene.block_types) & set(shapes.CUSTOM_TYPES), name
    deep = [n for n in NAMES if any(r.size[1] >= 2 for r in shapes.SPECS[n].regions)]
    assert len(deep) >= 3
    one = [n for n in NAMES if len(shapes.SPECS[n].regions) == 1]
    assert 0 < len(one) < len(NAMES)
    # The arch block's anchor is in the air: it must have been lifted onto its legs.
    aq = scene_of('aqueduct')
    assert any(b.type == 'A5' and b.position[2] == pytest.approx(1.5 * aq.unit) for b in aq.blocks)


@pytest.mark.parametrize('name', NAMES)
def test_allocation_fills_the_target(name):
    scene = scene_of(name)
    result = solve(scene)
    assert result.has_solution
    assert validate_allocation(scene, result) == []
    assert placements_coverage(scene, result.placements) >= 0.9


def test_seed_moves_the_blocks_only():
    for name in ('aqueduct', 'spire_cup'):
        a, b = scene_of(name, 0), scene_of(name, 1)
        assert shapes.shape_scene(name, 1).to_dict() == b.to_dict()            # reproducible
        assert a.targets == b.targets
        assert Counter(x.type for x in a.blocks) == Counter(x.type for x in b.blocks)
        assert [(x.position, x.yaw) for x in a.blocks] != [(x.position, x.yaw) for x in b.blocks]


def test_unknown_shape_is_a_clear_error():
    with pytest.raises(RadError, match='unknown shape'):
        shapes.shape_scene('no_such_shape')


def test_tiler_finds_exact_tilings_and_refuses_impossible_ones():
    lib = shapes.LIBRARY
    rng = np.random.default_rng(0)
    cells = [(0, 0, 0), (1, 0, 0), (2, 0, 0)]
    with pytest.raises(RadError, match='no stable exact tiling'):
        shapes.tile_exact(cells, {'I2': lib['I2']}, rng)
    assert [n for n, _, _ in shapes.tile_exact(cells, {'I2': lib['I2'], 'I3': lib['I3']}, rng)] == ['I3']
    # An arch: cubes alone leave the lintel's middle afloat; a bar spans it.
    _, arch = shapes.face('###', '#.#')
    with pytest.raises(RadError):
        shapes.tile_exact(arch, {'cube': lib['cube'], 'I2_up': lib['I2_up']}, rng)
    pieces = shapes.tile_exact(arch, {'cube': lib['cube'], 'I3': lib['I3']}, rng)
    assert sorted(n for n, _, _ in pieces) == ['I3', 'cube', 'cube']
    assert shapes.tile_exact(arch, {'cube': lib['cube']}, rng, stable=False)


def test_static_stability_rule():
    floating = [(1, 0, 1)]
    assert not shapes.rests_stably(floating, set())
    assert not shapes.rests_stably(floating, {(0, 0, 0), (2, 0, 0)})
    lintel = [(0, 0, 1), (1, 0, 1), (2, 0, 1)]
    assert shapes.rests_stably(lintel, {(0, 0, 0), (2, 0, 0)})
    assert not shapes.rests_stably(lintel, {(0, 0, 0)})          # centre one cell beyond its only foot
    assert not shapes.rests_stably([(0, 0, 1), (1, 0, 1)], {(0, 0, 0)})   # balanced on the edge: tips
    # Order matters only through support: the lintel goes last.
    assert shapes.stable_order([lintel, [(0, 0, 0)], [(2, 0, 0)]]) == [1, 2, 0]
    assert shapes.stable_order([lintel, [(0, 0, 0)]]) is None

"""The stability-aware allocation (support='stable') and the ceiling search."""

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.validate import validate_allocation
from rad_core.domain import support
from rad_core.domain.coverage import optimum_coverage
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.sequencing.bounds.ceiling import coverage_ceiling
from rad_core.sequencing.decide.actions import AllocationActions
from rad_core.sim.physics import PhysicsStability

from scenes import U, scene

STABLE = AllocationParams(support='stable')
TYPES = {'cube': [[0, 0, 0]], 'I2': [[0, 0, 0], [1, 0, 0]], 'I2_up': [[0, 0, 0], [0, 0, 1]]}


def blocks(*types):
    return [{'id': f'b{n}', 'type': t, 'position': [0.3 + 0.1 * n, -0.25, U / 2], 'yaw': 0}
            for n, t in enumerate(types)]


def region(filled, size=(3, 1, 2)):
    return [{'name': 'front', 'origin': [0.45, 0.1, U / 2], 'size': list(size), 'filled': filled}]


@pytest.fixture(scope='module')
def physics():
    p = PhysicsStability()
    yield p
    p.close()


def test_com_rule():
    one = np.array([[0.0, 0.0]])
    assert support.com_inside(one, np.array([0.0, 0.0]))
    assert not support.com_inside(one, np.array([0.5, 0.0]))       # over the edge: tips
    two = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert support.com_inside(two, np.array([0.5, 0.0]))
    # A flat bar of 2 resting on one end only holds with neither end alone.
    cells = np.array([[0, 0, 1], [1, 0, 1]])
    assert support.sufficient_supports(cells, [0, 1]) == [(0, 1)]
    # A flat bar of 3: the middle unit alone holds it.
    bar3 = np.array([[0, 0, 1], [1, 0, 1], [2, 0, 1]])
    assert (1,) in support.sufficient_supports(bar3, [0, 1, 2])


def test_a_floating_cube_is_not_allocated_but_a_filler_that_holds_it_up_is():
    # Target: only the upper cell of a column; the cell under it is a non-target cell.
    s = scene(types=TYPES, blocks=blocks('cube', 'I2_up'), targets=region([[0, 0, 1]], (1, 1, 2)))
    paper = solve(s)
    assert paper.objective == 1 and [p.type for p in paper.placements] == ['cube']
    stable = solve(s, STABLE)
    assert stable.status == 'OPTIMAL' and validate_allocation(s, stable) == []
    # c^T g is 0 now (a non-target cell filled too) but the target cell is covered and can be built.
    assert stable.objective == 0 and [p.type for p in stable.placements] == ['I2_up']


def test_a_cantilever_over_a_hole_is_replaced_by_a_buildable_allocation(physics):
    # Targets: a column of two at x = 0 and the cell at x = 1 on top; (1, 0, 0) is a hole.
    s = scene(types=TYPES, blocks=blocks('I2', 'cube', 'cube'),
              targets=region([[0, 0, 0], [0, 0, 1], [1, 0, 1]], (2, 1, 2)))
    paper = solve(s)
    assert paper.objective == 3   # the bar or a cube over the hole: no order can build it
    env = AssemblyEnv(s, EnvConfig(stability='physics'), stability=physics)
    assert coverage_ceiling(env, AllocationActions(env, paper.placements)) < 1
    stable = solve(s, STABLE)
    assert validate_allocation(s, stable) == []
    # The bar goes under as a filler (c^T g 2 instead of 3), and every target cell is built.
    assert stable.objective == 2
    assert any(p.type == 'I2' and all(c[2] == 0 for c in p.cells) for p in stable.placements)
    assert coverage_ceiling(env, AllocationActions(env, stable.placements)) == 1.0


def test_stable_allocations_are_valid_and_buildable_where_the_papers_are_not(physics):
    gaps_paper, gaps_stable = [], []
    for seed in range(15):
        s = generate_scene(GeneratorConfig(grid=4), seed)
        for params, gaps in ((AllocationParams(), gaps_paper), (STABLE, gaps_stable)):
            result = solve(s, params)
            assert result.status == 'OPTIMAL' and validate_allocation(s, result) == []
            env = AssemblyEnv(s, EnvConfig(stability='physics'), stability=physics)
            space = AllocationActions(env, result.placements)
            ceiling = coverage_ceiling(env, space)
            assert ceiling is not None
            gaps.append(optimum_coverage(env, space.guide) - ceiling)
    # What the allocation proposes and what any order can build: far closer with 'stable'.
    assert np.mean(gaps_stable) < 0.5 * np.mean(gaps_paper)
    assert np.mean(gaps_paper) > 0.03


def test_ceiling_leaves_the_env_as_it_was_and_gives_up_cleanly(physics):
    s = generate_scene(GeneratorConfig(grid=4), 3)
    env = AssemblyEnv(s, EnvConfig(stability='physics'), stability=physics)
    space = AllocationActions(env, solve(s).placements)
    before = env.snapshot()
    full = coverage_ceiling(env, space)
    assert 0 < full <= 1
    assert (env.state.occupancy == before.occupancy).all() and env.state.placed.keys() == before.placed.keys()
    assert coverage_ceiling(env, space, max_states=1) is None


def test_unknown_support_mode_is_an_error():
    with pytest.raises(Exception, match='support must be one of'):
        solve(scene(), AllocationParams(support='magic'))

"""support='hand': the allocation a top-down hand can place in some order (`allocation.cpsat`)."""

import pytest
from rad_core.allocation.cpsat import AllocationParams, solve
from rad_core.allocation.order import hand_order
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.grid import Grid
from rad_core.sequencing.agent.agent_plan import AgentPlanner
from rad_core.sequencing.decide.agents import label, parse
from rad_core.sequencing.planning.reallocation import reallocation_support

from scenes import flush_square, scene


def hand_cells(sc, placements) -> int:
    grid = Grid(sc)
    return sum(int(grid.is_target[list(cells)].sum()) for cells in hand_order(sc, placements).order)


def test_the_hand_allocation_trades_an_unplaceable_cover_for_one_the_hand_can_place_more_of(set_down_hand):
    sc = flush_square()
    # Two I2s side by side fill it, but the second is flush against the first on one side and 10 cm
    # long the other way: the hand places only one. An I2 and two cubes let it place three.
    arm = solve(sc, AllocationParams(support='arm'))
    assert arm.objective == 4 and hand_cells(sc, arm.placements) == 2      # what 'arm' picks here
    hand = solve(sc, AllocationParams(support='hand'))
    assert hand.objective == 4 and hand.bound == 4
    assert hand_cells(sc, hand.placements) == 3                            # no order places all four
    assert sorted(p.type for p in hand.placements) == ['I2', 'cube', 'cube']


def test_where_the_hand_can_place_everything_the_first_answer_stands():
    sc = scene()      # a row of three cells and one on top of its end: the hand places it whole
    arm, hand = (solve(sc, AllocationParams(support=s)) for s in ('arm', 'hand'))
    assert hand.placements == arm.placements and hand_cells(sc, hand.placements) == hand.objective == 4


def test_agents_and_reallocations_name_the_hand_support():
    agent = parse('milp-dqn-mixed+verify+realloc+repair+support:hand')
    assert agent.support == 'hand' and parse(label(agent)) == agent
    assert reallocation_support('hand') == 'hand' and reallocation_support('arm') == 'arm'
    assert reallocation_support('none') == 'stable'


@pytest.mark.slow   # plans a g = 5 scene with GAMP, two agents (a few seconds)
def test_where_the_hands_allocation_falls_short_the_arms_plan_is_kept(set_down_hand):
    # g = 5 seed 9009: the hand's allocation is one its order places whole, but the plans of it stop
    # at 0.8; the arm's allocation has a pair the order cannot place both of, and its plan, with a
    # re-allocation on the way, builds everything. The default agent plans both and keeps the better.
    scene = generate_scene(GeneratorConfig(grid=5, sides=2), 9009)
    planners = {name: AgentPlanner(f'milp-dqn-mixed+verify+realloc+repair+support:{name}') for name in ('arm', 'hand')}
    try:
        arm, hand = (planners[n](scene) for n in ('arm', 'hand'))
    finally:
        for p in planners.values():
            p.close()
    assert arm.predicted_coverage == 1.0 and hand.predicted_coverage == 1.0
    assert hand.anytime[0]['coverage'] < 1.0              # its first plan, of the hand's allocation
    first_hand = solve(scene, AllocationParams(support='hand'))
    assert hand_cells(scene, first_hand.placements) == scene.num_target_cells == 5


@pytest.mark.slow   # the ceiling's search and three plans of a g = 5 scene with GAMP (about 30 s)
def test_the_ceiling_part_builds_what_the_allocations_cannot(set_down_hand):
    # g = 5 seed 16 (flush): the arm's and the hand's allocations fill every cell exactly, and no
    # order of either builds more than 7 of 9 (the ceiling's search exhausts them). Every pose
    # searched, an I3 one cell past the target where they take an exact I2 builds all 9.
    from rad_core.experiment.evaluation import evaluate
    scene = generate_scene(GeneratorConfig(grid=5, sides=2), 16)
    plain = evaluate('default', [('s16', scene)], robot=True, seed=0)['scenes'][0]
    more = evaluate('default+ceiling:30', [('s16', scene)], robot=True, seed=0)['scenes'][0]
    assert plain['coverage'] == pytest.approx(7 / 9)
    assert more['coverage'] == 1.0 and more['outcome'] == 'completed'

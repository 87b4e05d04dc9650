"""Anytime planning (sequencing.agent.agent_plan.plan_for_agent): a first plan by the scorer alone, the
agent's own (searched) plan only while time remains and only where it fills more."""

from __future__ import annotations

from dataclasses import replace

import pytest
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.sequencing.agent.agent_plan import AgentPlanner, plan_for_agent


def steps_of(plan):
    return [(s.block, s.target, tuple(map(tuple, s.cells))) for s in plan.steps]


LOOKAHEAD = 'milp-dqn-mixed+lookahead:5+verify+realloc+support:arm'   # the default preset until 2026-12-03


@pytest.fixture(scope='module')
def planners():
    made = {name: AgentPlanner(name) for name in ('default', 'greedy')}
    made['lookahead'] = AgentPlanner(LOOKAHEAD, policy=made['default'].sequencer.policy)
    made['no-improving'] = AgentPlanner(LOOKAHEAD, improve_time_s=0.0, policy=made['default'].sequencer.policy)
    yield made
    for p in made.values():
        p.close()


@pytest.mark.slow
def test_the_first_plan_is_the_scorers_and_the_search_runs_only_when_cells_are_left(planners):
    seen_partial = seen_full = False
    for seed in (1000, 1001, 1002, 1003):
        scene = generate_scene(GeneratorConfig(grid=5), seed)
        quick = planners['no-improving'](scene)
        greedy = planners['greedy'](scene)
        # The first plan is the scorer's alone: what the greedy agent (the same scorer, verified) plans.
        assert steps_of(quick) == steps_of(greedy) and quick.predicted_coverage == greedy.predicted_coverage
        assert [a['plan'] for a in quick.anytime] == ['scorer']
        best = planners['lookahead'](scene)
        times = [a['t'] for a in best.anytime]
        assert times == sorted(times) and best.anytime[0]['coverage'] == quick.predicted_coverage
        assert best.predicted_coverage >= quick.predicted_coverage
        assert best.anytime[-1]['coverage'] == best.predicted_coverage
        if quick.predicted_coverage < 1.0:
            seen_partial = True
            assert len(best.anytime) == 2          # the searched plan was tried within the budget
            assert best.anytime[1]['plan'] in ('scorer', 'search')
        else:
            seen_full = True
            assert len(best.anytime) == 1 and steps_of(best) == steps_of(quick)
    assert seen_partial and seen_full


def test_agents_without_a_search_plan_once_and_a_bad_budget_is_refused(planners):
    scene = generate_scene(GeneratorConfig(grid=4), 3)
    once = planners['greedy'](scene)
    assert [a['plan'] for a in once.anytime] == ['scorer'] and once.anytime[0]['coverage'] == once.predicted_coverage
    # The default agent is the greedy one with order repair (tests/core/test_repair.py) and the hand's
    # allocation (tests/core/test_hand_allocation.py).
    assert planners['default'].spec == replace(planners['greedy'].spec, repair=True, support='hand')
    p = planners['lookahead']
    with pytest.raises(RadError, match='improve_time_s'):
        plan_for_agent(p.spec, scene, p.allocate, p.motion, p.sequencer.rank, quick_rank=p.quick_rank,
                       improve_time_s=-1.0)

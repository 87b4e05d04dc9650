"""The sequencer interface, HEUR, and whole-assembly planning in-process."""

import time

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.allocation.result import AllocationResult
from rad_core.domain import support
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.sequencing import HeurPolicy, ranked_actions
from rad_core.sequencing.planning.plan import MotionPlan, plan_assembly


def test_heur_ranks_only_fully_supported_actions_and_is_seeded():
    scene = generate_scene(GeneratorConfig(grid=4), 0)
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    actions = AllocationGuide(scene, solve(scene).placements).allowed_actions(env.state)
    heur = HeurPolicy()
    ranked = ranked_actions(heur, env, actions, np.random.default_rng(3))
    assert ranked and len(ranked) < len(actions)
    assert all(support.fully_supported(env.grid, env.state.occupancy, env.resulting_cells(a)[0]) for a in ranked)
    # The scores are a function of state and generator: asking again with an equally
    # seeded generator gives the same ranking, another seed another one.
    assert ranked == ranked_actions(heur, env, actions, np.random.default_rng(3))
    assert ranked != ranked_actions(heur, env, actions, np.random.default_rng(4))


def test_a_complete_plan_puts_every_allocated_pose_in_order(motion):
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    plan = plan_assembly(scene, solve, motion, HeurPolicy(), seed=1)
    assert plan.success and plan.reason == ''
    assert plan.predicted_coverage == 1.0
    assert len(plan.steps) == len(plan.allocation.placements)
    assert {(s.type, s.target, tuple(map(tuple, sorted(s.cells)))) for s in plan.steps} == \
        {(p.type, p.target, tuple(sorted(p.cells))) for p in plan.allocation.placements}
    # Each step's motion starts where the previous one ended (the controller starts from the arm's state).
    for before, after in zip(plan.steps, plan.steps[1:]):
        assert after.motion['trajectories'][0]['points'][0]['time_from_start'] > 0
        assert before.block != after.block
    for stage in ('allocation', 'sequencing', 'motion', 'total'):
        assert plan.timings[stage] >= 0
    # GAMP's own time (what the gamp node reports as planning_time_s) lies within the time waited for it.
    assert 0 < plan.timings['gamp'] <= plan.timings['motion']
    moved = {b.id: b for b in plan.final_scene.blocks}
    for s in plan.steps:
        assert np.allclose(moved[s.block].position, s.position) and moved[s.block].yaw == s.yaw


def test_infeasible_motions_give_a_partial_plan_with_the_reason():
    scene = generate_scene(GeneratorConfig(grid=3), 1)

    def nothing_works(scene, action, start):
        return MotionPlan(False, 'grasp', f'grasp: {action.block_id} is glued down')

    plan = plan_assembly(scene, solve, nothing_works, HeurPolicy(), seed=1)
    assert not plan.success and plan.steps == []
    assert plan.reason.startswith('no feasible next action') and 'glued down' in plan.reason


def test_failed_allocation_and_time_limit_are_reasons(motion):
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    plan = plan_assembly(scene, lambda s: AllocationResult('UNKNOWN', 0, 0, 0.0), motion, HeurPolicy())
    assert not plan.success and plan.reason == 'allocation failed: UNKNOWN (CP-SAT found none within its time limit)'
    plan = plan_assembly(scene, solve, motion, HeurPolicy(), time_limit_s=0.0)
    assert not plan.success and 'time limit' in plan.reason


def test_a_plan_can_ask_a_ranking_callable_as_the_sequencer_node_is_asked(motion):
    from rad_core.sequencing.decide.sequencer import Sequencer, SequencerConfig
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    sequencer = Sequencer(SequencerConfig(policy='heur', seed=1))
    asked = []

    def rank(state, placements, start):
        asked.append((state, start))
        return sequencer.rank(state, placements, start)
    plan = plan_assembly(scene, solve, motion, rank)
    assert plan.success, plan.reason
    assert plan.predicted_coverage == 1.0 and len(plan.steps) == len(plan.allocation.placements)
    assert len(asked) == len(plan.steps) and asked[0] == (scene, None)
    # Each question carries the planning copy: the blocks placed so far at their poses, the arm where it ended.
    placed = {b.id: b for b in asked[1][0].blocks}[plan.steps[0].block]
    assert np.allclose(placed.position, plan.steps[0].position)
    assert np.allclose(asked[1][1][:7], plan.steps[0].motion['trajectories'][-1]['points'][-1]['positions'])
    assert np.allclose(asked[1][1][7:], plan.steps[0].motion['gripper'][-1]['position'])   # the hand as released
    assert plan.timings['sequencing'] > 0 and plan.timings['sequencer_call'] >= plan.timings['sequencing']


def test_a_ranking_outside_the_allocation_is_never_taken_and_a_failing_sequencer_propagates(motion):
    from rad_core.domain.errors import RadError
    from rad_core.gamp.action import SceneAction
    from rad_core.sequencing.decide.sequencer import Ranking
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    wrong = Ranking([SceneAction(scene.blocks[0].id, 0, scene.targets[0].name, (2, 0, 2), 0),
                     SceneAction('nosuch', 0, scene.targets[0].name, (0, 0, 0), 0)], [1.0, 0.5], False, '', {})
    plan = plan_assembly(scene, solve, motion, lambda *_: wrong)
    assert not plan.success and plan.steps == []
    assert 'the sequencer proposed 2 actions, none of them among the' in plan.reason
    stop = Ranking([], [], True, '3 allocated poses left, stopping is valued above all of them', {})
    plan = plan_assembly(scene, solve, motion, lambda *_: stop)
    assert not plan.success and plan.reason == stop.reason

    def down(*_):
        raise RadError('service sequence is not available')
    with pytest.raises(RadError, match='service sequence is not available'):
        plan_assembly(scene, solve, motion, down)


class _Highest:
    """A policy that wants the highest cells first: it ranks blocks that would rest on nothing first."""
    name = 'highest'

    def scores(self, env, actions, rng):
        heights = [float(env.grid.centres[env.resulting_cells(a)[0]][:, 2].min()) for a in actions]
        return np.array(heights + [-1.0])


class _Shy:
    """A policy that values stopping above every action (a network can learn that where it could
    not check what it does)."""
    name = 'shy'
    why_none = 'it values stopping more'

    def scores(self, env, actions, rng):
        return np.array([-float(n) for n in range(len(actions))] + [1.0])


def test_fallbacks_are_a_last_resort_after_re_allocating(motion):
    """A verified plan re-allocates where nothing above stopping can be built, and goes below
    stopping only when that offers nothing new: a fallback taken first would change what the
    re-allocations propose."""
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    calls = []

    def reallocate(state, exclude, limit):
        calls.append(len(state.blocks))
        return solve(state)
    plan = plan_assembly(scene, solve, motion, _Shy(), seed=1, reallocate=reallocate)
    assert plan.success and plan.predicted_coverage == 1.0, plan.reason
    assert plan.reallocations and plan.reallocations[0].step == 0 and not plan.reallocations[0].changed
    assert 'values stopping more' in plan.reallocations[0].reason and calls


def test_a_pose_whose_block_would_tip_the_structure_is_a_no_good_of_the_robots_re_allocation(motion, monkeypatch):
    """Re-allocation checks the open poses as the plan's own steps are checked: stability first,
    then GAMP. A pose the arm can reach but whose block would bring the structure down is
    excluded like one the arm cannot reach (it was not: GAMP alone said it could be built, so
    the re-solve proposed it again and the plan ended)."""
    import rad_core.sequencing.planning.plan as plan_module
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    floor = float(AssemblyEnv(scene).grid.centres[:, 2].min())

    def upper_layers_tip(unit, placed, new, clearance=0.0):      # a fault physics will not make on demand
        high = float(np.asarray(new).reshape(-1, 3)[:, 2].min()) > floor + 1e-9
        return (False, 'placed block 0 tipped 9.9 deg (on purpose)') if high else (True, '')
    monkeypatch.setattr(plan_module, '_STABILITY', upper_layers_tip)
    plan = plan_assembly(scene, solve, motion, HeurPolicy(), seed=1, reallocate=lambda s, ex, t: solve(s, exclude=ex))
    no_goods = [n for e in plan.reallocations for n in e.no_goods]
    assert no_goods and all('on purpose' in n['reason'] for n in no_goods), plan.reallocations
    assert all(min(c[2] for c in n['cells']) > 0 for n in no_goods)


def test_with_fallbacks_asks_for_them_only_where_the_first_answer_is_to_stop():
    from rad_core.env.mdp import Action
    from rad_core.sequencing.decide.deciders import with_fallbacks
    from rad_core.sequencing.decide.episode import Decision, stop
    build, asked = Decision(Action(0, 0, 0, 0)), []

    def decide(env, rng, fallbacks=False):
        asked.append(fallbacks)
        return build if fallbacks else stop('nothing above stopping')
    assert with_fallbacks(decide)(None, None) is build and asked == [False, True]
    asked.clear()
    assert with_fallbacks(decide, lambda env, rng: build)(None, None) is build and asked == []
    none = with_fallbacks(lambda env, rng, fallbacks=False: stop('no fallback' if fallbacks else 'why it stopped'))
    assert none(None, None).reason == 'why it stopped'      # the first answer's reason stands


def test_ranked_indices_puts_the_fallbacks_below_stopping_after_the_rest_and_never_a_ruled_out_one():
    from rad_core.sequencing.decide.policy import ranked_indices
    scores = np.array([0.2, 0.9, -np.inf, 0.5, 0.1, 0.4])   # the last one: stopping
    assert ranked_indices(scores) == [1, 3]
    assert ranked_indices(scores, fallbacks=True) == [1, 3, 0, 4]


def test_a_verified_plan_goes_on_below_the_value_of_stopping_and_an_unverified_one_stops(motion):
    """Stopping while allocated poses remain is the agent's choice only where it cannot check: a
    verified plan tries what its scorer values below stopping, best first, and builds it."""
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    blind = plan_assembly(scene, solve, motion, _Shy(), seed=1, verify=False)
    assert blind.steps == [] and blind.predicted_coverage == 0.0
    checked = plan_assembly(scene, solve, motion, _Shy(), seed=1)
    assert checked.success and checked.predicted_coverage == 1.0, checked.reason
    # The sequencer (what the node serves) answers the same way: stopping is its choice, and the
    # actions below it are there for a verified caller.
    from rad_core.sequencing.decide.sequencer import Sequencer, SequencerConfig
    ranking = Sequencer(SequencerConfig(policy='heur'), policy=_Shy()).rank(scene, solve(scene).placements)
    assert ranking.terminate and 'it values stopping more' in ranking.reason
    assert ranking.fallbacks == len(ranking.actions)      # every one of them is valued below stopping
    assert ranking.actions and ranking.values == sorted(ranking.values, reverse=True)
    # Fallbacks are only blocks that would stand on their supports alone, well inside them (a
    # cantilever valued below stopping can pass the check at exact cells and still bring the built
    # structure down).
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    every = AllocationGuide(scene, solve(scene).placements).allowed_actions(env.state)
    from rad_core.sequencing.decide.actions import mdp_actions
    ranked = mdp_actions(env, ranking.actions, every)
    assert len(ranked) == len(ranking.actions)
    from rad_core.sequencing.decide.policy import FIRM_MARGIN
    firm = [a for a in every if support.rests_on_its_own(env.grid, env.state.occupancy, env.resulting_cells(a)[0],
                                                         FIRM_MARGIN)]
    assert set(ranked) == set(firm) and len(firm) < len(every)
    through_node = plan_assembly(scene, solve, motion, lambda *_: ranking, seed=1)
    assert through_node.steps, through_node.reason


def test_a_lintel_on_two_piers_stands_on_its_own_a_cantilever_or_a_balanced_block_does_not():
    """support.rests_on_its_own, what fallbacks below stopping are held to, and `firm`."""
    from rad_core.sequencing.decide.policy import FIRM_MARGIN, firm
    scene = generate_scene(GeneratorConfig(grid=4), 0)
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    grid, occ = env.grid, env.state.occupancy.copy()
    r = 0
    cell = lambda i, k: grid.index(r, (i, 0, k))     # noqa: E731
    occ[[cell(0, 0), cell(3, 0)]] = 0                # two piers one layer high, two cells apart
    lintel = np.array([cell(i, 1) for i in range(4)])
    cantilever = np.array([cell(i, 1) for i in range(3, 0, -1)])       # on the right pier only
    assert support.rests_on_its_own(grid, occ, lintel, FIRM_MARGIN)
    assert not support.rests_on_its_own(grid, occ, cantilever)
    balanced = np.array([cell(3, 1), cell(2, 1)])                        # half on a pier: on the edge
    assert not support.rests_on_its_own(grid, occ, balanced, FIRM_MARGIN)
    assert support.rests_on_its_own(grid, occ, np.array([cell(0, 1)]), FIRM_MARGIN)
    env.state.occupancy[:] = occ
    env.state.placed = {0: (np.array([cell(0, 0)]), 0), 1: (np.array([cell(3, 0)]), 0)}
    assert firm(env)
    env.state.occupancy[balanced] = 2
    env.state.placed[2] = (balanced, 0)
    assert not firm(env)


def test_a_block_that_would_rest_on_nothing_is_never_planned(motion):
    scene = generate_scene(GeneratorConfig(grid=4), 0)
    plan = plan_assembly(scene, solve, motion, _Highest(), seed=1)
    assert plan.steps
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    regions = [t.name for t in scene.targets]
    for step in plan.steps:
        cells = np.array([env.grid.index(regions.index(step.target), c) for c in step.cells])
        assert support.any_support(env.grid, env.state.occupancy, cells), step.to_dict()
        env.state.occupancy[cells] = 0


def test_an_unverified_plan_stops_where_its_best_ranked_action_fails_and_a_verified_one_goes_on(motion):
    """The paper's agents take the best-ranked action blindly; /plan_assembly's default checks with GAMP."""
    from rad_core.sequencing.agent.agent_plan import plan_for_agent
    from rad_core.sequencing.decide.agents import parse
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    first = plan_assembly(scene, solve, motion, HeurPolicy(), seed=1).steps[0].block
    asked = []

    def glued_first(scene_now, action, start):
        asked.append(action.block_id)
        if action.block_id == first:     # GAMP refuses what it would do on a real cell; here on demand
            return MotionPlan(False, 'grasp', f'grasp: {action.block_id} is glued down')
        return motion(scene_now, action, start)

    def allocate(s, support):
        return solve(s)
    blind = plan_for_agent(parse('heur'), scene, allocate, glued_first, HeurPolicy(), seed=1)
    assert not blind.success and blind.steps == [] and asked == [first]
    # The refused action ends the episode as a failed grasp (f_g), with GAMP's reason.
    assert blind.reason == f'grasp: {first} is glued down' and blind.episode.outcome.value == 'invalid_grasp'
    checked = plan_for_agent(parse('heur+verify'), scene, allocate, glued_first, HeurPolicy(), seed=1)
    assert checked.steps and first not in [s.block for s in checked.steps]   # it built around the glued block


def test_a_search_plan_the_improvement_budget_ends_before_its_first_step_is_not_an_error(motion):
    """Anytime planning: the first plan stops early, the search's gets almost no time (its episode
    has no outcome then); the answer is the first plan, not a crash."""
    from rad_core.sequencing.agent.agent_plan import plan_for_agent
    from rad_core.sequencing.decide.agents import parse
    from rad_core.sequencing.decide.sequencer import Ranking
    scene = generate_scene(GeneratorConfig(grid=3), 1)

    def quick(*_):
        return Ranking([], [], True, 'nothing, on purpose', {})
    calls = []

    def slow_allocate(s, support):
        calls.append(1)
        if len(calls) > 1:    # the search plan's: longer than its budget, it ends before its first step
            time.sleep(0.2)
        return solve(s)
    plan = plan_for_agent(parse('heur+lookahead:1+verify'), scene, slow_allocate, motion,
                          HeurPolicy(), quick_rank=quick, improve_time_s=5e-3)
    assert len(calls) == 2 and plan.anytime[0]['t'] < 0.2
    assert plan.steps == [] and plan.reason == 'nothing, on purpose'
    assert [a['plan'] for a in plan.anytime] == ['scorer', 'scorer']


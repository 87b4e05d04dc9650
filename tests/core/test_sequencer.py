"""The sequencer (rad_core.sequencing.decide.sequencer): what the sequencer node serves."""

import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.placements import Placement
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene_sources import generated_scenes
from rad_core.experiment.evaluation import evaluate, get_agent
from rad_core.learning.checkpoint import CheckpointError
from rad_core.sequencing.decide.sequencer import POLICIES, Sequencer, SequencerConfig

SCENE = generate_scene(GeneratorConfig(grid=3), 4)
PLACEMENTS = solve(SCENE, AllocationParams()).placements


@pytest.fixture(scope='module')
def sequencers():
    return {p: Sequencer(SequencerConfig(policy=p, budget=3)) for p in POLICIES}


def allocated(scene, placements, action) -> bool:
    """Whether a SceneAction puts a block of an allocated type into an allocated pose's region."""
    types = {b.id: b.type for b in scene.blocks}
    return any(p.type == types[action.block_id] and p.target == action.target for p in placements)


@pytest.mark.parametrize('policy', POLICIES)
def test_every_policy_ranks_allocated_actions_and_answers_the_same_twice(sequencers, policy):
    s = sequencers[policy]
    first = s.rank(SCENE, PLACEMENTS)
    again = s.rank(SCENE, PLACEMENTS)
    assert first.actions and not first.terminate and not first.reason
    assert first.actions == again.actions and first.values == again.values
    assert len(first.values) == len(first.actions)
    assert all(allocated(SCENE, PLACEMENTS, a) for a in first.actions)
    assert 'sequencing' in first.timings
    if policy in ('milp-dqn', 'heur'):
        assert first.values == sorted(first.values, reverse=True)
    if policy.endswith(('mcts', 'halving')):
        assert first.search is not None and 1 <= first.search['simulations'] <= 3


def test_the_searched_move_is_feasible_for_gamp(sequencers):
    """The search steps its own planning twin with GAMP: its first proposal must plan."""
    from rad_core.gamp.action import MotionPlanner
    s = sequencers['milp-dqn-halving']
    top = s.rank(SCENE, PLACEMENTS).actions[0]
    planner = MotionPlanner()
    result, _, _ = planner(SCENE, top)
    assert result.success, result.reason


def test_max_actions_truncates(sequencers):
    r = sequencers['milp-dqn'].rank(SCENE, PLACEMENTS, max_actions=1)
    assert len(r.actions) == len(r.values) == 1


def test_a_finished_assembly_terminates_with_a_reason(sequencers):
    r = sequencers['milp-dqn'].rank(SCENE, [])
    assert r.terminate and not r.actions and r.reason == 'every allocated pose is built'


def test_bad_requests_are_refused_with_the_reason(sequencers):
    s = sequencers['milp-dqn']
    region = SCENE.targets[0].name
    with pytest.raises(RadError, match='unknown target region'):
        s.rank(SCENE, [Placement(PLACEMENTS[0].type, 'nowhere', 0, PLACEMENTS[0].cells)])
    with pytest.raises(RadError, match="block type 'nonesuch'"):
        s.rank(SCENE, [Placement('nonesuch', region, 0, ((0, 0, 0),))])
    with pytest.raises(RadError, match='outside region'):
        s.rank(SCENE, [Placement(PLACEMENTS[0].type, region, 0, ((99, 0, 0),))])
    with pytest.raises(RadError, match='start_positions'):
        s.rank(SCENE, PLACEMENTS, start=[0.0] * 3)
    assert s.rank(SCENE, PLACEMENTS).actions   # and it serves the next request


def test_bad_configs_and_checkpoints_name_the_problem(tmp_path):
    with pytest.raises(RadError, match='policy must be one of'):
        Sequencer(SequencerConfig(policy='alphazero'))
    with pytest.raises(RadError, match='budget'):
        Sequencer(SequencerConfig(budget=0))
    bad = tmp_path / 'broken.pt'
    bad.write_bytes(b'not a model')
    with pytest.raises(CheckpointError, match='broken.pt'):
        Sequencer(SequencerConfig(policy='milp-dqn', checkpoint=str(bad)))
    with pytest.raises(CheckpointError, match='missing.pt'):
        Sequencer(SequencerConfig(checkpoint=str(tmp_path / 'missing.pt')))
    with pytest.raises(RadError, match='was trained on'):
        Sequencer(SequencerConfig(policy='milp-dqn', checkpoint='dqn'))


def test_search_agents_with_verification_never_fail_and_are_reproducible():
    agent = get_agent('milp-dqn-halving', verify=True, budget=3)
    assert agent.name == 'milp-dqn+halving:3+verify' and agent.search == 'halving' and agent.budget == 3
    runs = [evaluate(agent, generated_scenes(3, 2, 2, 10), robot=True, seed=0) for _ in range(2)]
    assert runs[0]['f'] == 0.0
    assert [r['return'] for r in runs[0]['scenes']] == [r['return'] for r in runs[1]['scenes']]
    assert runs[0]['coverage'] > 0


def test_budget_only_for_search_agents():
    with pytest.raises(RadError, match='--budget applies to agents with a simulation search'):
        get_agent('milp-dqn', budget=3)
    with pytest.raises(RadError, match='>= 1'):
        get_agent('milp-dqn-mcts', budget=0)


def test_dfs_answers_along_its_best_line_without_searching_again():
    from rad_core.gamp.action import MotionPlanner
    from rad_core.sequencing.planning.plan import local_motion_planner, plan_assembly
    s = Sequencer(SequencerConfig(policy='milp-dqn-dfs', search_time_s=30.0))
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    stable = solve(scene, AllocationParams(support='stable')).placements
    first = s.rank(scene, stable)
    assert first.search is not None and first.search['complete'] and first.search['coverage'] == 1.0
    assert first.values[0] == 1.0 and 'search' in first.timings
    planner = MotionPlanner()
    try:
        asked = []

        def rank(scene, placements, start):
            ranking = s.rank(scene, placements, start)
            asked.append(ranking)
            return ranking
        plan = plan_assembly(scene, lambda sc: solve(sc, AllocationParams(support='stable')),
                             local_motion_planner(planner), rank)
    finally:
        planner.close()
    assert plan.success and plan.predicted_coverage == 1.0
    assert all('search' not in r.timings for r in asked)     # every state was on the known line
    assert [st.block for st in plan.steps][0] == first.actions[0].block_id

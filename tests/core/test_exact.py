"""The exact planner: branch and bound over pose orders with the robot in the loop."""

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, Placement, solve
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
from rad_core.sequencing.decide.actions import AllocationActions
from rad_core.sequencing.decide.exact import exact_search
from rad_core.sequencing.decide.policy import HeurPolicy
from rad_core.sequencing.decide.search import SEARCHES, EnvModel

from scenes import scene as default_scene

U = 0.05
FAR = (0.9, -0.6, U / 2)   # 1.08 m from the base: the arm cannot grasp there


def row_scene(cubes, far=False, extra=()):
    """A row of three target cells on the table; cubes (and one out of reach) to fill it."""
    blocks = [{'id': f'c{n}', 'type': 'cube', 'position': [0.4 + 0.1 * n, -0.2, U / 2], 'yaw': 0}
              for n in range(cubes)]
    if far:
        blocks.append({'id': 'far', 'type': 'cube', 'position': list(FAR), 'yaw': 0})
    blocks += list(extra)
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': U,
        'block_types': {'cube': [[0, 0, 0]], 'I2': [[0, 0, 0], [1, 0, 0]]}, 'blocks': blocks,
        'targets': [{'name': 't', 'origin': [0.45, 0.15, U / 2], 'size': [3, 1, 1],
                     'filled': [[0, 0, 0], [1, 0, 0], [2, 0, 0]]}]})


def robot_env(scene):
    renv = RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport'))
    renv.reset()
    return renv


def stable_space(renv):
    return AllocationActions(renv.env, solve(renv.scene, AllocationParams(support='stable')).placements)


def model(renv, space):
    """The search model the branch and bound steps (no scorer: its default child order)."""
    return EnvModel(renv, None, space)


def world_poses(renv):
    return np.array([np.concatenate(renv.world.block_pose(b)) for b in renv.world.blocks])


def test_finds_full_coverage_and_its_line_builds_it_with_the_robot():
    with robot_env(default_scene()) as renv:
        space = stable_space(renv)
        before, poses = renv.env.snapshot(), world_poses(renv)
        result = exact_search(model(renv, space), time_limit_s=30)
        assert result.complete and result.reason == '' and result.proof == 'bound'
        assert result.coverage == result.bound == 1.0 and len(result.actions) == 3
        # The env is back where it was given.
        assert renv.env.state.placed == before.placed and not renv.env.state.done
        assert np.allclose(world_poses(renv), poses, atol=1e-9)
        for action in result.actions:
            assert not renv.step(action).outcome.is_invalid
        assert renv.env.coverage() == 1.0


def test_a_pose_only_an_unreachable_block_can_fill_gives_a_proven_lower_coverage():
    # Two cubes within reach, the third out of it: two of the three cells at best. The
    # search must exhaust: 1 + 2*3 + 3*2 = 13 sets of placements, though 6 + 2*6 = 18 orders
    # reach them; each set is stepped into once (a cube's four yaws are one state too).
    with robot_env(row_scene(2, far=True)) as renv:
        valid, step = [], renv.step

        def counting_step(action, plan=None):
            result = step(action, plan)
            valid.append(not result.outcome.is_invalid)
            return result
        renv.step = counting_step
        result = exact_search(model(renv, stable_space(renv)), time_limit_s=60)
        assert result.complete and result.bound == 1.0
        assert result.coverage == pytest.approx(2 / 3) and len(result.actions) == 2
        assert result.proof == 'exhausted'      # below the allocation's bound: no proof over others
        assert result.states == 13 and sum(valid) == 12 < 18
        assert not renv.env.state.placed


def test_an_incumbent_prunes_and_an_incumbent_at_the_bound_ends_the_search_at_once():
    # Two of the three cells at best (the third cube out of reach), 13 states without an incumbent.
    with robot_env(row_scene(2, far=True)) as renv:
        below = exact_search(model(renv, stable_space(renv)), time_limit_s=60, incumbent=1 / 3)
        assert below.complete and below.coverage == pytest.approx(2 / 3) and len(below.actions) == 2
        known = exact_search(model(renv, stable_space(renv)), time_limit_s=60, incumbent=2 / 3)
        # Nothing beats the plan known to reach 2/3: the answer is its coverage, with no line of its own.
        assert known.complete and known.coverage == pytest.approx(2 / 3) and known.actions == []
        with pytest.raises(RadError, match='incumbent'):
            exact_search(model(renv, stable_space(renv)), incumbent=1.5)
        assert not renv.env.state.placed
    with robot_env(default_scene()) as renv:
        at_bound = exact_search(model(renv, stable_space(renv)), time_limit_s=60, incumbent=1.0)
        assert at_bound.complete and at_bound.coverage == 1.0 and at_bound.states == 1 and at_bound.actions == []
        assert at_bound.proof == 'bound' and known.proof == 'exhausted'


def test_a_cut_search_answers_a_lower_bound_and_says_why():
    with robot_env(default_scene()) as renv:
        result = exact_search(model(renv, stable_space(renv)), time_limit_s=1e-6)
        assert not result.complete and result.coverage == 0.0 and result.actions == [] and result.proof == ''
        assert 'time limit of 1e-06 s reached after 1 states; 0.00 is a lower bound' == result.reason
        result = exact_search(model(renv, stable_space(renv)), max_states=2)
        assert not result.complete and result.states == 2 and 'state limit of 2' in result.reason
        assert result.coverage > 0 and len(result.actions) == 1
        assert not renv.env.state.placed and not renv.env.state.done


def test_on_dead_end_is_called_and_its_space_is_searched():
    # The allocation asks for cubes in cells 0 and 1, but only one cube is within reach;
    # where the far cube fails, the hook hands over an I2 pose on cells 1 and 2.
    i2 = {'id': 'i2', 'type': 'I2', 'position': [0.5, -0.35, U / 2], 'yaw': 0}
    with robot_env(row_scene(1, far=True, extra=[i2])) as renv:
        cube = [Placement('cube', 't', 0, ((0, 0, 0),)), Placement('cube', 't', 0, ((1, 0, 0),))]
        calls = []

        def reallocate(at, space):
            assert space.guide.placements == tuple(cube)
            calls.append(dict(at.env.state.placed))
            cells = {int(c) for cells, _ in at.env.state.placed.values() for c in cells}
            if cells != {at.env.grid.index(0, (0, 0, 0))}:
                return None
            return AllocationActions(at.env, [Placement('I2', 't', 0, ((1, 0, 0), (2, 0, 0)))])

        result = exact_search(model(renv, AllocationActions(renv.env, cube)), time_limit_s=60, on_dead_end=reallocate)
        assert calls and result.coverage == 1.0
        assert [renv.scene.blocks[a.block].id for a in result.actions] == ['c0', 'i2']


def test_bad_limits_and_orders_are_refused_and_the_env_is_left_as_given():
    with robot_env(default_scene()) as renv:
        space = stable_space(renv)
        with pytest.raises(RadError, match='time_limit_s'):
            exact_search(model(renv, space), time_limit_s=0)
        with pytest.raises(RadError, match='max_states'):
            exact_search(model(renv, space), max_states=0)
        with pytest.raises(RadError, match='order'):
            exact_search(model(renv, space), order=lambda env, actions: actions[:1])
        calls = []

        def fails_below_the_root(env, actions):
            calls.append(len(env.state.placed))
            if env.state.placed:
                raise RuntimeError('ranking failed')
            return actions
        with pytest.raises(RuntimeError, match='ranking failed'):
            exact_search(model(renv, space), order=fails_below_the_root)
        assert calls[-1] == 1 and not renv.env.state.placed and not renv.env.state.done


def test_bnb_is_a_search_whose_move_starts_its_best_line():
    rng = np.random.default_rng(0)
    with robot_env(row_scene(2, far=True)) as renv:     # two cubes within reach, one out of it
        space = stable_space(renv)
        result = SEARCHES['bnb'](EnvModel(renv, HeurPolicy(), space), rng, budget=60)
        assert result.info['complete'] and result.info['coverage'] == pytest.approx(2 / 3)
        assert len(result.line) == 2 and result.action == result.line[0]
        proposals = [a for a, _ in result.proposals()]
        assert proposals[0] == result.line[0] and not renv.env.state.placed
        cut = SEARCHES['bnb'](EnvModel(renv, HeurPolicy(), space), rng, budget=1e-6)
        assert not cut.info['complete'] and 'time limit' in cut.info['reason']
        # Cut before it found a line: no verdict, the ranking is the scorer's.
        assert cut.line is None and cut.children == [] and len(cut.proposals()) == len(cut.actions) > 0


def test_rad_eval_exact_plans_and_builds_its_best_line():
    from rad_core.experiment.evaluation import evaluate, get_agent
    scene = row_scene(2, far=True)      # two cubes within reach, one out of it: 2 of 3 cells at best
    result = evaluate(get_agent('exact'), [('row', scene)], robot=True, seed=0)
    row = result['scenes'][0]
    assert result['agent'] == 'heur+bnb:60+verify+realloc+support:arm'
    assert result['f'] == 0.0 and row['coverage'] == pytest.approx(2 / 3) and row['steps'] == 2


def test_the_networks_bnb_agent_builds_within_its_time_and_a_cut_one_stops_without_failing():
    from rad_core.experiment.evaluation import evaluate, get_agent
    agent = get_agent('milp-dqn-mixed-dfs')
    assert agent.search == 'bnb' and agent.verified and agent.robot and agent.budget == 10
    result = evaluate(agent, [('row', row_scene(3))], robot=True, seed=0)
    assert result['scenes'][0]['coverage'] == 1.0
    cut = evaluate('milp-dqn-mixed+bnb:1e-06+verify', [('row', row_scene(3))], robot=True, seed=0)
    row = cut['scenes'][0]
    assert cut['f'] == 0.0 and row['steps'] >= 1     # cut searches fall back on the network's ranking


def test_the_robot_ceiling_searches_orders_and_reallocations_to_a_proven_answer():
    from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling
    found = robot_ceiling(row_scene(2, far=True), time_limit_s=60)
    assert found.complete and found.reason == '' and found.coverage == pytest.approx(2 / 3)
    # The arm's bound leaves out the cube it cannot pick: 2/3 is the ceiling over every allocation.
    assert found.proof == 'bound' and found.bound == pytest.approx(2 / 3)
    i2 = {'id': 'i2', 'type': 'I2', 'position': [0.5, -0.35, U / 2], 'yaw': 0}
    # A cube out of reach, an I2 within it: only re-allocating around the far cube fills the row.
    found = robot_ceiling(row_scene(1, far=True, extra=[i2]), time_limit_s=60)
    assert found.complete and found.coverage == 1.0


def test_an_exhausted_ceiling_searches_the_hands_allocation_then_every_pose_and_says_how_it_ended(set_down_hand):
    from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling

    from scenes import flush_square
    sc = flush_square()
    # Without the hand order in its bound (ordered=False), the bound counts every cell.
    arm = robot_ceiling(sc, time_limit_s=60, support='arm', every_pose=False, ordered=False)
    both = robot_ceiling(sc, time_limit_s=60, every_pose=False, ordered=False)   # the arm's allocation, then the hand's
    # Three of the four flush cells: no top-down hand that sets blocks down (`set_down_hand`: a drop closes
    # it, tests/core/test_drop.py) closes the square. The bound (every cell) is
    # not reached, so the answer is the best of what was searched, and both allocations were.
    for found in (arm, both):
        assert found.complete and found.coverage == pytest.approx(0.75) and found.bound == 1.0
        assert found.proof == 'exhausted' and found.reason == ''
    assert both.states > arm.states
    # Every sequence of every pose the bound counts (each I2 and cube pose in the square) searched:
    # three cells is the true ceiling, whatever the allocation.
    every = robot_ceiling(sc, time_limit_s=120, ordered=False)
    assert every.complete and every.coverage == pytest.approx(0.75) and every.proof == 'all poses'
    assert every.states > both.states
    # With it (the default), the bound itself sees that the last block of the closed square has
    # nowhere for the fingers: three cells at most, reached by the first line, so no more is searched.
    ordered = robot_ceiling(sc, time_limit_s=60)
    assert ordered.complete and ordered.coverage == pytest.approx(0.75) and ordered.proof == 'bound'
    assert ordered.bound == pytest.approx(0.75) and ordered.states < arm.states
    cut = robot_ceiling(sc, time_limit_s=1e-6)
    assert not cut.complete and cut.proof == '' and 'lower bound' in cut.reason
    with pytest.raises(RadError, match='support'):
        robot_ceiling(sc, support=())


def test_the_ceilings_twin_plans_a_failed_move_once_per_state_and_answers_it_again_as_before():
    from rad_core.env.mdp import Outcome
    from rad_core.sequencing.bounds.robot_ceiling import _FailedMoves
    with robot_env(row_scene(2, far=True)) as renv:
        planned, plan = [], renv.plan

        def counting_plan(action):
            planned.append(action)
            return plan(action)
        renv.plan = counting_plan
        memo = _FailedMoves(renv)
        actions = list(stable_space(renv)(renv.env))
        far = next(a for a in actions if a.block == 2)       # the cube out of reach
        near = next(a for a in actions if a.block == 0 and a.cell != far.cell)
        root = memo.snapshot()
        first = memo.step(far)
        assert first.outcome is Outcome.INVALID_GRASP and len(planned) == 1
        memo.restore(root)
        poses = world_poses(renv)
        again = memo.step(far)
        # Booked as the first time, without planning, the world left as it was.
        assert (again.outcome, again.reason, again.reward, again.done) == (first.outcome, first.reason,
                                                                           first.reward, first.done)
        assert len(planned) == 1 and memo.hits == 1 and np.array_equal(world_poses(renv), poses)
        memo.restore(root)
        check = memo.check()(far)
        assert (check.success, check.reason, check.failure) == (False, first.reason, 'grasp')
        assert len(planned) == 1 and memo.hits == 2
        # From another state (a cube placed) the move is planned again.
        assert not memo.step(near).outcome.is_invalid
        assert memo.step(far).outcome is Outcome.INVALID_GRASP and len(planned) == 3 and memo.hits == 2
        memo.restore(root)
        # What the MDP itself refuses is not remembered: the block is placed already.
        assert memo.key(far) is not None and memo.step(near) and memo.key(near) is None

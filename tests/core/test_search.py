"""The test-time searches (rad_core.sequencing.decide.search): golden trees on a toy model,
the paper's rules checked one by one, and a real robot env left as it was found.

Golden trees: tests/core/golden/search_trees.json, written with
RAD_REGEN_GOLDEN=1 pytest tests/core/test_search.py (review the diff before committing).
"""

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from rad_core.env.mdp import TERMINATE, Action
from rad_core.sequencing.decide.agents import SIMULATION_SEARCHES
from rad_core.sequencing.decide.search import SEARCHES, EnvModel, first_round, halving, mcts

# The searches whose budget counts simulations (bnb's is seconds; tests/core/test_exact.py has its own).
SIMULATED = {name: SEARCHES[name] for name in SIMULATION_SEARCHES}

GOLDEN = Path(__file__).parent / 'golden' / 'search_trees.json'
GAMMA = 0.9


class ToyModel:
    """A deterministic toy MDP: n items to place in any order; placing item i earns
    reward[i], item `bad` fails (-1, done) unless placed last... and Q is a fixed
    function of (state, action) so that trees are reproducible to the bit."""

    gamma = GAMMA

    def __init__(self, n=6, bad=(2,), trap=4):
        self.n, self.bad, self.trap = n, set(bad), trap
        self.placed: tuple = ()
        self.done = False
        self.steps = 0

    def actions(self):
        if self.done:
            return []
        return [Action(i, 0, i, 0) for i in range(self.n) if i not in self.placed]

    def q_values(self, actions):
        s = len(self.placed)
        q = [0.5 + 0.3 * math.sin(1.7 * a.block + 0.9 * s) for a in actions]
        return np.array(q + [0.1 * (self.n - s)])

    def step(self, action):
        self.steps += 1
        if action.is_terminate:
            self.done = True
            return 0.0, True, False
        if action.block in self.bad:
            self.done = True
            return -1.0, True, True
        self.placed = self.placed + (action.block,)
        if self.trap in self.placed[:1]:
            self.done = True          # placing the trap first leaves nothing buildable
            return 0.2, True, False
        self.done = len(self.placed) == self.n
        return 0.2, self.done, False

    def snapshot(self):
        return (self.placed, self.done)

    def restore(self, snap):
        self.placed, self.done = snap


def trees():
    out = {}
    for name, search in SIMULATED.items():
        for seed in (0, 1, 2):
            for budget in (1, 3, 5, 10):
                for eps in (0.0, 0.5):
                    model = ToyModel()
                    result = search(model, np.random.default_rng(seed), budget=budget, epsilon=eps)
                    out[f'{name}/seed{seed}/budget{budget}/eps{eps}'] = result.to_dict()
    return out


def test_golden_trees():
    got = trees()
    if os.environ.get('RAD_REGEN_GOLDEN'):
        GOLDEN.write_text(json.dumps(got, indent=1, sort_keys=True) + '\n')
    want = json.loads(GOLDEN.read_text())
    assert got.keys() == want.keys()
    for key in want:
        assert got[key] == want[key], key


def test_mcts_follows_the_papers_rules():
    model = ToyModel()
    q = model.q_values(model.actions())
    r = mcts(model, np.random.default_rng(0), budget=5, epsilon=0.0)
    # Greedy expansion: the 5 best candidates by Q (termination included), in that order.
    candidates = model.actions() + [TERMINATE]
    expected = [candidates[i] for i in np.argsort(-q, kind='stable')[:5]]
    assert [c.action for c in r.children] == expected
    for c in r.children:
        assert c.visits == 2
        k = candidates.index(c.action)
        # leaf value: r (done) or r + gamma max Q(s')
        m = ToyModel()
        rew, done, _ = m.step(c.action)
        leaf = rew if done else rew + GAMMA * float(np.max(m.q_values(m.actions())))
        assert c.value == pytest.approx((q[k] + leaf) / 2)
    assert r.action == max(r.children, key=lambda c: c.value).action
    assert model.placed == () and not model.done      # the root state is left as it was
    assert r.simulations == 5 and model.steps == 5


def test_mcts_stops_when_everything_is_expanded():
    model = ToyModel(n=2, bad=(), trap=-1)
    r = mcts(model, np.random.default_rng(0), budget=10, epsilon=0.0)
    assert r.simulations == 3 and len(r.children) == 3   # two items + terminate


def test_a_failing_action_is_ranked_last_and_never_chosen_greedily():
    for search in SIMULATED.values():
        model = ToyModel(bad=(0, 1, 2, 3))   # Q ranks some of these first
        r = search(model, np.random.default_rng(0), budget=10, epsilon=0.0)
        assert not any(c.invalid and c.action == r.action for c in r.children)
        ranking = [a for a, _ in r.ranking()]
        invalid = [c.action for c in r.children if c.invalid]
        assert invalid and ranking[0] == r.action
        # every root action once, the failed ones last
        assert sorted(ranking) == sorted(ToyModel(bad=(0, 1, 2, 3)).actions() + [TERMINATE])
        assert ranking[-len(invalid):] == invalid


def test_the_ranking_keeps_every_rotation_and_stopping_does_not_hide_better_actions():
    """Actions with the same outcome key are simulated once but all ranked; a searched
    termination is ranked by its Q, so unsearched actions valued above it stay listed."""
    class Rotations(ToyModel):
        def actions(self):
            return [Action(a.block, 0, a.cell, rot) for a in super().actions() for rot in (0, 1)]

        def key(self, action):
            return action.block

        def q_values(self, actions):
            q = super().q_values([Action(a.block, 0, a.cell, 0) for a in actions])
            q[-1] = 0.45   # terminating is worth less than most actions
            return q
    model = Rotations(bad=(), trap=-1)
    r = SEARCHES['mcts'](model, np.random.default_rng(0), budget=2, epsilon=1.0)   # explores at random
    ranking = [a for a, _ in r.ranking()]
    assert sorted(ranking) == sorted(model.actions() + [TERMINATE])
    q = dict(zip(model.actions() + [TERMINATE], model.q_values(model.actions())))
    searched = {c.action for c in r.children}
    above = [a for a in model.actions() if q[a] > q[TERMINATE] and a not in searched]
    assert above and all(ranking.index(a) < ranking.index(TERMINATE) for a in above)


def test_halving_sees_a_dead_end_that_one_step_does_not():
    """Item 4 looks best by Q but leaves nothing buildable after it: halving's deeper
    line shows it, so it picks another first move."""
    class Trap(ToyModel):
        def q_values(self, actions):
            q = super().q_values(actions)
            for i, a in enumerate(actions):
                if a.block == 4 and not self.placed:
                    q[i] = 2.0
            return q
    r = halving(Trap(bad=()), np.random.default_rng(0), budget=5)
    assert r.action.block != 4
    assert any(c.action.block == 4 and c.depth == 1 for c in r.children)


def test_first_round_leaves_budget_to_deepen_half():
    assert [first_round(b) for b in (1, 2, 3, 4, 5, 6, 9, 10)] == [1, 1, 2, 2, 3, 4, 6, 6]


def test_budget_and_epsilon_are_validated():
    with pytest.raises(ValueError, match='budget'):
        mcts(ToyModel(), np.random.default_rng(0), budget=0)
    with pytest.raises(ValueError, match='epsilon'):
        mcts(ToyModel(), np.random.default_rng(0), epsilon=1.5)
    with pytest.raises(ValueError, match='budget'):
        halving(ToyModel(), np.random.default_rng(0), budget=0)


@pytest.fixture(scope='module')
def robot_case():
    from rad_core.allocation import AllocationParams, solve
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
    from rad_core.learning.policy import QPolicy
    from rad_core.sequencing.decide.actions import action_space
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    renv = RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport'))
    renv.reset()
    space = action_space('milp', renv.env, solve(scene, AllocationParams()).placements)
    yield renv, EnvModel(renv, QPolicy.load('milp-dqn'), space)
    renv.close()


@pytest.mark.parametrize('name', sorted(SIMULATED))
def test_search_on_the_robot_env_is_repeatable_and_leaves_it_unchanged(robot_case, name):
    renv, model = robot_case
    poses = {b: renv.world.block_pose(b) for b in renv.world.blocks}
    state, q = renv.env.state.copy(), renv.world.joint_positions()
    first = SEARCHES[name](model, np.random.default_rng(3), budget=4)
    again = SEARCHES[name](model, np.random.default_rng(3), budget=4)
    assert first.to_dict() == again.to_dict()
    assert 1 <= first.simulations <= 4
    assert renv.env.state.placed == state.placed and (renv.env.state.occupancy == state.occupancy).all()
    assert np.allclose(renv.world.joint_positions(), q)
    for b, (p, o) in poses.items():
        assert np.allclose(renv.world.block_pose(b)[0], p, atol=1e-7)
    # one action per outcome: no two searched children put the same block on the same cells
    keys = [model.key(c.action) for c in first.children if not c.action.is_terminate]
    assert len(keys) == len(set(keys))


def test_lookahead_keeps_the_networks_order_unless_a_step_or_the_next_one_fails():
    # Without traps or failures it takes the greedy action.
    model = ToyModel(bad=(), trap=-1)
    q = model.q_values(model.actions())
    r = SEARCHES['lookahead'](model, np.random.default_rng(0), budget=5)
    assert r.action == model.actions()[int(np.argmax(q[:-1]))]
    # A failing greedy action is skipped for the next one by Q.
    model = ToyModel(bad=(1,), trap=-1)
    r = SEARCHES['lookahead'](model, np.random.default_rng(0), budget=5)
    order = np.argsort(-model.q_values(model.actions())[:-1], kind='stable')
    assert model.actions()[order[0]].block == 1 and r.action == model.actions()[order[1]]
    assert r.children[0].invalid and not r.children[1].invalid


def test_lookahead_skips_a_move_into_a_dead_end_but_takes_it_when_nothing_else_works():
    class DeadEnd(ToyModel):
        """After item 1, every other item fails; item 1 has the best Q."""
        def q_values(self, actions):
            q = super().q_values(actions)
            for i, a in enumerate(actions):
                if a.block == 1 and not self.placed:
                    q[i] = 3.0
            return q

        def step(self, action):
            if self.placed == (1,) and not action.is_terminate:
                self.done = True
                return -1.0, True, True
            return super().step(action)
    r = SEARCHES['lookahead'](DeadEnd(n=3, bad=(), trap=-1), np.random.default_rng(0), budget=10)
    assert r.action.block != 1
    r = SEARCHES['lookahead'](DeadEnd(n=3, bad=(0, 2), trap=-1), np.random.default_rng(0), budget=10)
    assert r.action.block == 1     # a dead end, but the only block that can be placed at all


def test_a_verified_callers_fallbacks_go_on_below_stopping_but_never_to_a_failed_child():
    """proposals() ends at termination; with fallbacks it goes on with the actions not simulated,
    valued below stopping, and still never offers a child whose simulated step failed."""
    class Shy(ToyModel):
        def q_values(self, actions):
            q = super().q_values(actions)
            q[-1] = 0.7      # stopping is worth more than most actions
            return q
    model = Shy(bad=(0, 1, 2, 3), trap=-1)
    r = SEARCHES['lookahead'](model, np.random.default_rng(0), budget=3, epsilon=0.0)
    failed = {c.action for c in r.children if c.invalid}
    short, long = [a for a, _ in r.proposals()], [a for a, _ in r.proposals(fallbacks=True)]
    assert long[:len(short)] == short and len(long) > len(short)
    assert failed and not failed & set(long) and TERMINATE not in long
    q = dict(zip(model.actions() + [TERMINATE], model.q_values(model.actions())))
    assert any(q[a] <= q[TERMINATE] for a in long[len(short):])

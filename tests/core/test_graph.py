"""Graph observations and the Q-network: nodes, mask, candidates, batching."""

import numpy as np
import pytest
import torch
from rad_core.allocation import solve
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.shapes import shape_scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.learning.graph import NON_TARGET, PLACED, TARGET, UNPLACED, Observer, attention_allowed
from rad_core.learning.network import NetConfig, QNetwork, collate, graph_max
from rad_core.sequencing.decide.actions import action_space, all_actions, relative_actions

GEOM = EnvConfig(stability='none')


def env_with_actions(grid=3, seed=2):
    scene = generate_scene(GeneratorConfig(grid=grid), seed)
    env = AssemblyEnv(scene, GEOM)
    return env, action_space('milp', env, solve(scene).placements)


def test_nodes_are_units_and_free_cells_with_their_kinds():
    env, space = env_with_actions()
    observe = Observer(env)
    obs = observe(env, space(env))
    units = sum(env.types[b].size for b in range(len(env.scene.blocks)))
    assert obs.num_nodes == units + env.grid.num_cells
    assert (obs.kind == UNPLACED).sum() == units
    assert (obs.kind == TARGET).sum() == env.grid.is_target.sum()
    assert (obs.kind == NON_TARGET).sum() == (~env.grid.is_target).sum()
    # After a placement its units become placed nodes and its cells are no longer nodes.
    action = space(env)[0]
    size = env.types[action.block].size
    env.step(action)
    after = observe(env, space(env))
    assert (after.kind == PLACED).sum() == size
    assert (after.kind == UNPLACED).sum() == units - size
    assert after.num_nodes == obs.num_nodes - size


def test_candidates_point_at_the_unit_and_cell_of_each_action():
    env, space = env_with_actions()
    observe = Observer(env)
    actions = space(env)
    obs = observe(env, actions)
    free = env.free_cells()
    cell_nodes = np.flatnonzero(obs.kind >= TARGET)
    for a, (u, c), r in zip(actions, obs.pairs, obs.rot):
        assert obs.kind[u] == UNPLACED and obs.group[u] == a.block
        assert free[c - cell_nodes[0]] == a.cell
        assert r == a.rotation
        # The unit node's position is that unit's position on the table.
        want = observe.table_pos[a.block][a.unit]
        assert np.allclose(obs.pos[u], want)


def test_dense_action_mask_holds_exactly_the_candidates():
    env, space = env_with_actions()
    actions = space(env)
    obs = Observer(env)(env, actions)
    mask = obs.action_mask()
    assert mask.shape == (len(env.unplaced_units()), len(env.free_cells()), 4)
    assert mask.sum() == len(set(actions))
    units = env.unplaced_units()
    free = list(env.free_cells())
    for a in actions:
        assert mask[units.index((a.block, a.unit)), free.index(a.cell), a.rotation]


def test_mask_cuts_only_unplaced_units_of_different_blocks_and_keeps_self():
    kind = np.array([UNPLACED, UNPLACED, UNPLACED, PLACED, TARGET, NON_TARGET])
    group = np.array([0, 0, 1, 2, -1, -1])
    allowed = attention_allowed(kind, group)
    assert allowed.diagonal().all()
    assert allowed[0, 1] and allowed[1, 0]            # same block
    assert not allowed[0, 2] and not allowed[2, 1]    # different unplaced blocks
    assert allowed[2, 3:].all() and allowed[3:, :].all()


def test_batched_q_values_equal_one_graph_at_a_time():
    torch.manual_seed(0)
    net = QNetwork(NetConfig(dim=32, heads=4, ff=64, readout=32)).eval()
    obs = []
    for grid, seed in ((3, 1), (5, 4), (4, 7)):
        env, space = env_with_actions(grid, seed)
        obs.append(Observer(env)(env, space(env)))
    with torch.no_grad():
        qa, qs = net(collate(obs))
        offsets = np.cumsum([0] + [o.num_actions for o in obs])
        for i, o in enumerate(obs):
            qa1, qs1 = net(collate([o]))
            assert torch.allclose(qa[offsets[i]:offsets[i + 1]], qa1, atol=1e-5)
            assert torch.allclose(qs[i], qs1[0], atol=1e-5)


def test_graph_max_picks_best_candidate_or_terminate():
    env, space = env_with_actions()
    o = Observer(env)(env, space(env))
    batch = collate([o, o])
    qa = torch.arange(2 * o.num_actions, dtype=torch.float32)
    qs = torch.tensor([-1.0, 1e6])
    best, arg = graph_max(qa, qs, batch)
    assert arg.tolist() == [o.num_actions - 1, -1]
    assert best.tolist() == [float(o.num_actions - 1), 1e6]


def test_network_takes_scene_defined_block_types_and_any_size():
    scene = shape_scene('log_cabin', 0)   # custom block type bar4
    env = AssemblyEnv(scene, GEOM)
    space = action_space('milp', env, solve(scene).placements)
    o = Observer(env)(env, space(env))
    qa, qs = QNetwork()(collate([o]))
    assert qa.shape == (o.num_actions,) and qs.shape == (1,)
    assert torch.isfinite(qa).all() and torch.isfinite(qs).all()


def test_baseline_action_spaces():
    env, _ = env_with_actions()
    everything = all_actions(env)
    n_units = len(env.unplaced_units())
    assert len(everything) == n_units * len(env.free_cells()) * 4
    first = relative_actions(env)
    assert {a.cell for a in first} == set(np.flatnonzero(env.grid.is_target).tolist())
    env.step(next(a for a in everything if env.evaluate(a)[0] is None))
    placed = env.state.occupancy >= 0
    for a in relative_actions(env):
        nb = env.grid.face_neighbours[a.cell]
        assert any(n >= 0 and placed[n] for n in nb)


@pytest.mark.parametrize('method', ['milp', 'all', 'rel'])
def test_every_candidate_maps_to_the_graph(method):
    env, milp = env_with_actions(4, 3)
    space = milp if method == 'milp' else action_space(method, env)
    o = Observer(env)(env, space(env))
    assert o.num_actions == len(space(env)) > 0


def test_a_small_graph_is_scored_on_one_thread_and_the_process_setting_is_kept(monkeypatch):
    import rad_core.learning.policy as policy_module
    from rad_core.learning.policy import QPolicy
    torch.manual_seed(0)
    net = QNetwork(NetConfig(dim=32, heads=4, ff=64, readout=32)).eval()
    seen = []
    forward = net.forward
    monkeypatch.setattr(net, 'forward', lambda batch: (seen.append(torch.get_num_threads()), forward(batch))[1])
    env, space = env_with_actions()
    actions = space(env)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        scores = QPolicy(net).scores(env, actions)
        assert seen == [1] and torch.get_num_threads() == 2
        # A graph at or above the threshold keeps the process's threads.
        monkeypatch.setattr(policy_module, 'ONE_THREAD_BELOW', 1)
        again = QPolicy(net).scores(env, actions)
        assert seen == [1, 2] and np.allclose(scores, again, atol=1e-5)
    finally:
        torch.set_num_threads(before)

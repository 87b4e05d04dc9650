"""Expert iteration (`rad_core.training.expert`): demonstrations from the lines the verified planner
keeps, the DQfD loss that teaches them, and a run that resumes."""

from __future__ import annotations

import json

import pytest
import torch
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import Action, AssemblyEnv, EnvConfig
from rad_core.learning import checkpoint as ckpt
from rad_core.learning.network import QNetwork, collate
from rad_core.learning.policy import QPolicy
from rad_core.sequencing.agent.agent_plan import AgentPlanner
from rad_core.training.expert import (
    ExpertConfig,
    ExpertIteration,
    RecordingPolicy,
    agreement,
    demonstrations,
    dqfd_loss,
    plan_scene,
)

MODEL = str(ckpt.resolve('milp-dqn-mixed'))


@pytest.fixture(scope='module')
def planned():
    """A g = 4 scene planned by the default agent around a recording network, and its demonstrations."""
    scene = generate_scene(GeneratorConfig(grid=4), 3)
    policy = RecordingPolicy(QPolicy.load(MODEL))
    planner = AgentPlanner('default', policy=policy)
    try:
        plan = planner(scene)
    finally:
        planner.close()
    return scene, plan, policy.records, demonstrations(scene, plan, policy.records)


def test_the_demonstrations_are_the_kept_plan_step_by_step(planned):
    scene, plan, records, demos = planned
    assert plan.steps and len(demos) >= len(plan.steps)
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    regions = [t.name for t in scene.targets]
    ids = [b.id for b in scene.blocks]
    for step, demo in zip(plan.steps, demos):
        action = Action(ids.index(step.block), step.unit, env.grid.index(regions.index(step.target), step.cell),
                        step.rotation)
        obs = demo.obs
        # the candidate the label points at is the plan's step: its rotation, and its unit and cell nodes
        assert demo.action >= 0 and int(obs.rot[demo.action]) == step.rotation
        unit_node, cell_node = obs.pairs[demo.action]
        assert obs.group[unit_node] == action.block and obs.group[cell_node] == -1
        result = env.step(action)
        assert demo.reward == pytest.approx(result.reward) and demo.done == result.done
    for before, after in zip(demos, demos[1:]):
        assert not before.done and before.next_obs is after.obs    # one state, one observation
    assert demos[-1].done and demos[-1].next_obs is None
    if len(demos) > len(plan.steps):
        assert demos[-1].action == -1 and plan.predicted_coverage < 1.0     # it stopped short: terminate


def test_a_world_nobody_scored_ends_the_line_there(planned):
    scene, plan, records, demos = planned
    second = plan.steps[0].scene_after(scene).dumps()
    cut = {k: v for k, v in records.items() if k != second}
    short = demonstrations(scene, plan, cut)
    assert len(short) == 1 and short[0].next_obs is None and not short[0].done


def test_the_margin_loss_teaches_the_expert_choice_the_network_did_not_make(planned):
    """Labels moved to the candidate the network values least: the network disagrees with every
    one; a few hundred DQfD steps on them make it agree with all."""
    _, _, _, demos = planned
    torch.manual_seed(0)
    net = QPolicy.load(MODEL).net
    net.train()
    relabelled = []
    with torch.no_grad():
        for d in demos:
            if d.obs.num_actions < 2:
                continue
            qa, _ = net(collate([d.obs]))
            relabelled.append(d._replace(action=int(torch.argmin(qa))))
    assert relabelled and agreement(net, relabelled, 'cpu') == 0.0
    target = QNetwork(net.cfg)
    target.load_state_dict(net.state_dict())
    _, before = dqfd_loss(net, target, relabelled, 0.999, 0.1, 1.0, 'cpu')
    opt = torch.optim.Adam(net.parameters(), lr=3e-4)
    for _ in range(200):
        loss, info = dqfd_loss(net, target, relabelled, 0.999, 0.1, 1.0, 'cpu')
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert info['margin'] < before['margin']
    assert agreement(net, relabelled, 'cpu') == 1.0


def test_the_margin_loss_is_zero_where_the_expert_leads_by_the_margin(planned):
    _, _, _, demos = planned
    net = QPolicy.load(MODEL).net
    with torch.no_grad():
        qa, qs = net(collate([demos[0].obs]))
    best = int(torch.argmax(qa)) if float(qa.max()) > float(qs[0]) else -1
    gap = float(torch.sort(torch.cat([qa, qs]), descending=True).values[:2].diff().abs())
    demo = demos[0]._replace(action=best)
    _, info = dqfd_loss(net, net, [demo], 0.999, gap * 0.5, 1.0, 'cpu')
    assert info['margin'] == pytest.approx(0.0, abs=1e-6)
    _, info = dqfd_loss(net, net, [demo], 0.999, gap * 2.0, 1.0, 'cpu')
    assert info['margin'] == pytest.approx(gap, rel=1e-3)


def test_the_expert_must_be_a_verified_learned_agent():
    with pytest.raises(RadError, match='learned, verified'):
        ExpertConfig(agent='heur+verify').validate()
    with pytest.raises(RadError, match='learned, verified'):
        ExpertConfig(agent='milp-dqn-mixed').validate()
    with pytest.raises(RadError, match='grids'):
        ExpertConfig(grids='4,x').validate()


def test_plan_scene_returns_the_line_and_what_it_reached():
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    result = plan_scene('s', scene.to_dict(), 'default', MODEL, 60.0)
    assert result['name'] == 's' and 0 < result['coverage'] <= 1 and result['demos']
    assert result['steps'] <= len(result['demos'])


def test_a_run_resumes_with_the_next_round_planned_by_the_last_rounds_network(tmp_path):
    cfg = ExpertConfig(grids='3', scenes=2, shapes=False, rounds=1, steps=5, workers=1, holdout=0.0)
    first = ExpertIteration(cfg, tmp_path).run(log=lambda _: None)
    assert [r['round'] for r in first] == [0] and (tmp_path / 'r0.pt').is_file()
    with pytest.raises(RadError, match='--resume'):
        ExpertIteration(cfg, tmp_path).run(log=lambda _: None)
    with pytest.raises(RadError, match='only --rounds may change, not --lr'):
        ExpertIteration(ExpertConfig(**{**cfg.__dict__, 'rounds': 2, 'lr': 1e-3}), tmp_path).run(
            resume=True, log=lambda _: None)
    rows = ExpertIteration(ExpertConfig(**{**cfg.__dict__, 'rounds': 2}), tmp_path).run(resume=True,
                                                                                         log=lambda _: None)
    assert [r['round'] for r in rows] == [0, 1]
    assert rows[1]['expert_model'] == str((tmp_path / 'r0.pt').resolve())
    assert rows[1]['demos'] > rows[0]['demos']        # the rounds' demonstrations add up
    saved = [json.loads(line) for line in (tmp_path / 'progress.jsonl').read_text().splitlines()]
    assert [r['round'] for r in saved] == [0, 1]
    policy = QPolicy.load(tmp_path / 'model.pt')       # a model file like any other
    assert policy.actions == 'milp' and policy.support == QPolicy.load(MODEL).support


def test_the_anchor_term_holds_the_values_the_round_started_from(planned):
    _, _, _, demos = planned
    net = QPolicy.load(MODEL).net
    anchor = QPolicy.load(MODEL).net
    _, info = dqfd_loss(net, net, demos, 0.999, 0.02, 1.0, 'cpu', anchor=anchor, anchor_weight=10.0)
    assert info['anchor'] == pytest.approx(0.0, abs=1e-12)
    with torch.no_grad():
        net.stop_head[-1].bias += 0.5
    _, info = dqfd_loss(net, net, demos, 0.999, 0.02, 1.0, 'cpu', anchor=anchor, anchor_weight=10.0)
    assert info['anchor'] > 0.0

"""rad_core.sequencing.decide.agents: an agent is a value made of parts, with one text form that parses back to it."""

import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from rad_core.domain.errors import RadError
from rad_core.experiment.evaluation import get_agent
from rad_core.sequencing.decide.agents import LEGACY, PRESETS, AgentSpec, label, parse, parse_with_robot
from rad_core.sequencing.decide.sequencer import SequencerConfig

CONFIG = Path(__file__).resolve().parents[2] / 'ros_ws' / 'src' / 'rad_planner' / 'config' / 'graph.yaml'


@pytest.mark.parametrize('name', [*PRESETS, *LEGACY, 'heur-verified+realloc', 'milp-dqn-mcts@10',
                                  'runs/a/model.pt+halving:3+verify', 'dqn-rel'])
def test_every_name_parses_to_an_agent_whose_text_parses_back_to_it(name):
    agent = parse(name)
    assert parse(label(agent)) == agent
    assert label(parse(label(agent))) == label(agent)


def test_parts_have_their_defaults_and_a_canonical_order():
    assert label(AgentSpec('milp-dqn', 'mcts')) == 'milp-dqn+mcts:5'
    assert label(AgentSpec('heur', 'bnb', verify=True)) == 'heur+bnb:10+verify'
    assert parse('milp-dqn+support:stable+verify+mcts') == AgentSpec('milp-dqn', 'mcts', 5, True, False, 'stable')
    assert parse('milp-dqn-mixed-lookahead') == parse('milp-dqn-mixed+lookahead:5')
    assert parse('milp-dqn-mcts@10+verify') == AgentSpec('milp-dqn', 'mcts', 10, verify=True)
    assert parse_with_robot('heur-norobot') == (AgentSpec('heur'), False)
    assert parse_with_robot('exact')[1] is True and parse_with_robot('heur+verify')[1] is None


def test_the_ceiling_part_is_seconds_and_reads_back():
    agent = parse('default+ceiling:30')
    assert agent.ceiling == 30.0 and agent.repair and agent.support == 'hand'
    assert label(agent) == 'milp-dqn-mixed+verify+realloc+repair+ceiling:30+support:hand'
    assert parse(label(agent)) == agent and parse('default').ceiling == 0.0


def test_the_default_preset_is_what_the_node_graph_runs():
    default = parse('default')
    graph = yaml.safe_load(CONFIG.read_text())
    assert graph['sequencer']['ros__parameters']['agent'] == 'default'
    assert SequencerConfig().spec() == default                          # scorer, search, budget
    assembly = graph['assembly']['ros__parameters']
    assert assembly['agent'] == 'default' and default.verify and default.realloc and default.support == 'hand'
    # The older node policy names keep meaning what they meant on the node (the mixed network).
    assert SequencerConfig(policy='milp-dqn-lookahead').spec() == AgentSpec('milp-dqn-mixed', 'lookahead')
    assert SequencerConfig(policy='milp-dqn-dfs', search_time_s=30.0).spec() == \
        AgentSpec('milp-dqn-mixed', 'bnb', 30.0, verify=True)


@pytest.mark.parametrize('text, message', [
    ('', 'an agent is a preset'),
    ('alphazero', "unknown scorer 'alphazero'"),
    ('milp-dqn+mcts+halving', 'names two searches'),
    ('milp-dqn+mcts:0', 'budget must be a positive number'),
    ('milp-dqn+mcts:2.5', 'whole number'),
    ('milp-dqn+mcts:x', "bad mcts budget 'x'"),
    ('heur+bnb:10', 'add \\+verify'),
    ('milp-dqn+fast', "unknown part 'fast'"),
    ('milp-dqn+support:maybe', "unknown allocation support 'maybe'"),
    ('milp-dqn+ceiling:20', 'add \\+verify'),
    ('milp-dqn+verify+ceiling:-1', 'seconds of search, 0 to 3600'),
    ('milp-dqn+verify+ceiling:soon', "bad ceiling seconds 'soon'"),
])
def test_bad_agents_are_refused_with_what_is_wrong(text, message):
    with pytest.raises(RadError, match=message):
        parse(text)


def test_a_budget_needs_a_search():
    with pytest.raises(RadError, match='needs a search'):
        AgentSpec('milp-dqn', budget=3)


def test_model_files_record_their_action_space_and_allocation():
    mixed, paper = AgentSpec('milp-dqn-mixed'), AgentSpec('milp-dqn')
    assert mixed.resolved_support() == 'stable' and paper.resolved_support() == 'none'
    assert AgentSpec('heur').resolved_support() == 'none'
    assert AgentSpec('milp-dqn-mixed', support='none').resolved_support() == 'none'
    assert get_agent('milp-dqn-mixed').support == 'stable' and get_agent('dqn-rel').actions == 'rel'


def test_results_name_agents_by_their_canonical_text_whatever_name_was_used():
    assert get_agent('milp-dqn-mcts').name == get_agent('milp-dqn+mcts:5').name == 'milp-dqn+mcts:5'
    assert get_agent('paper').name == 'milp-dqn+mcts:5+support:none'
    assert get_agent('milp-dqn', verify=True, reallocate=True).name == 'milp-dqn+verify+realloc'


def test_parsing_agents_imports_neither_torch_nor_pybullet():
    code = ('import sys; from rad_core.sequencing.decide.agents import parse, label; '
            '[label(parse(n)) for n in ("default", "paper", "exact")]; '
            'print(sorted(m for m in ("torch", "pybullet") if m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == '[]'

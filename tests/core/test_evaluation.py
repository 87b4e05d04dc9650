"""`rad eval` and rad_core.experiment.evaluation: the paper's metrics, each agent's setting, reproducibility."""

import json
import shutil
import subprocess
import sys

import pytest
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.domain.scene_sources import generated_scenes
from rad_core.env.mdp import Outcome
from rad_core.experiment.evaluation import KEYS, evaluate, summarize

FAILS = {Outcome.INVALID_GRASP.value, Outcome.INVALID_PLACEMENT.value, Outcome.INVALID_DISTURBED.value}
# g=4 two-sided scenes 0..3: HEUR's blind choice fails with the robot on some of them.
ROBOT_SCENES = list(generated_scenes(4, 2, 4, 0))


def rad(*args):
    exe = shutil.which('rad')
    cmd = [exe] if exe else [sys.executable, '-m', 'rad_core.cli']
    return subprocess.run(cmd + list(args), check=False, capture_output=True, text=True, timeout=300)


def short_scene(blocks: int) -> Scene:
    """Three target cells in a row on the table and `blocks` cubes to fill them."""
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': 0.05, 'block_types': {'cube': [[0, 0, 0]]},
        'blocks': [{'id': f'c{i}', 'type': 'cube', 'position': [0.4 + 0.1 * i, -0.25, 0.025], 'yaw': 0}
                   for i in range(blocks)],
        'targets': [{'name': 't', 'origin': [0.45, 0.15, 0.025], 'size': [3, 1, 1],
                     'filled': [[0, 0, 0], [1, 0, 0], [2, 0, 0]]}]})


def no_blocks_left(result) -> float:
    """Fraction of episodes that ran out of blocks (neither d, e nor f)."""
    return sum(r['outcome'] == Outcome.NO_BLOCKS.value for r in result['scenes']) / result['n']


def test_keys_are_exactly_the_papers_and_fractions_add_up():
    scenes = list(generated_scenes(3, 2, 4, 0))
    for agent, robot in (('heur-norobot', False), ('heur', True)):
        result = evaluate(agent, scenes, robot=robot, seed=0)
        assert tuple(result) == KEYS
        assert result['n'] == 4 == len(result['scenes'])
        assert result['d'] + result['e'] + result['f'] + no_blocks_left(result) == pytest.approx(1.0)
        for row in result['scenes']:
            assert {'name', 'return', 'outcome', 'coverage', 'coverage_opt', 'steps'} <= set(row)
            assert ('reason' in row) == robot
            assert 0 <= row['coverage'] <= row['coverage_opt'] + 1e-9 <= 1 + 1e-9


def test_running_out_of_blocks_is_its_own_ending_and_coverage_rel_uses_the_optimum():
    # One cube for three target cells: the optimum covers 1/3, HEUR reaches it.
    result = evaluate('heur-norobot', [('short', short_scene(1))], robot=False, seed=0)
    row = result['scenes'][0]
    assert row['outcome'] == Outcome.NO_BLOCKS.value
    assert result['d'] == result['e'] == result['f'] == 0.0
    assert row['coverage_opt'] == pytest.approx(1 / 3) and result['coverage'] == pytest.approx(1 / 3)
    assert result['coverage_rel'] == pytest.approx(1.0)
    # Enough cubes: completed, with the paper's return 3 * 0.2 discounted plus the bonus.
    result = evaluate('heur-norobot', [('full', short_scene(3))], robot=False, seed=0)
    assert result['d'] == 1.0 and result['coverage'] == 1.0
    g = 0.999
    assert result['R'] == pytest.approx(0.2 + 0.2 * g + (0.2 + 1.0) * g * g)


def test_heur_norobot_never_uses_the_robot():
    result = evaluate('heur-norobot', ROBOT_SCENES, robot=True, seed=0)
    assert result['f_g'] == result['f_p'] == 0.0
    assert all('reason' not in row and row['outcome'] not in FAILS for row in result['scenes'])


def test_heur_fails_with_the_robot_where_heur_verified_does_not():
    heur = evaluate('heur', ROBOT_SCENES, robot=True, seed=0)
    verified = evaluate('heur-verified', ROBOT_SCENES, robot=True, seed=0)
    assert heur['f_g'] + heur['f_p'] > 0
    assert verified['f_g'] == verified['f_p'] == 0.0
    rescued = [h['name'] for h, v in zip(heur['scenes'], verified['scenes'])
               if h['outcome'] in FAILS and not Outcome(v['outcome']).is_invalid]
    assert rescued, 'no scene where the GAMP pre-check avoided a failure'
    failed = [h for h in heur['scenes'] if h['outcome'] in FAILS]
    assert all(h['reason'].startswith(('grasp', 'placement', 'the motion')) for h in failed)


def test_heur_verified_always_has_the_robot():
    verified = evaluate('heur-verified', ROBOT_SCENES[:1], robot=False, seed=0)
    assert 'reason' in verified['scenes'][0]


def test_execution_mode_reaches_the_robot_env():
    scene = ROBOT_SCENES[2]   # heur completes it in teleport mode
    teleport = evaluate('heur', [scene], robot=True, seed=0)
    simulate = evaluate('heur', [scene], robot=True, seed=0, execution='simulate')
    assert teleport['scenes'][0]['outcome'] == Outcome.COMPLETED.value
    assert simulate['n'] == 1 and tuple(simulate) == KEYS
    from rad_core.domain.errors import RadError
    with pytest.raises(RadError, match='execution'):
        evaluate('heur', [scene], robot=True, seed=0, execution='warp')


def test_same_seed_same_numbers_and_the_seed_matters():
    scenes = list(generated_scenes(4, 2, 3, 10))
    a = evaluate('heur', scenes, robot=True, seed=7)
    b = evaluate('heur', scenes, robot=True, seed=7)
    assert a == b
    c = evaluate('heur-norobot', scenes, robot=False, seed=7)
    d = evaluate('heur-norobot', scenes, robot=False, seed=7)
    assert c == d


def test_progress_is_called_once_per_scene():
    seen = []
    evaluate('heur-norobot', generated_scenes(3, 2, 3, 0), robot=False, seed=0, progress=seen.append)
    assert [r['name'] for r in seen] == [f'g3-sides2-seed{s}' for s in range(3)]


def test_summarize_rejects_no_scenes():
    from rad_core.domain.errors import RadError
    with pytest.raises(RadError):
        summarize([])


def test_cli_writes_the_json(tmp_path):
    out = tmp_path / 'out.json'
    r = rad('eval', '--agent', 'heur', '--grid', '4', '--robot', '--scenes', '2', '--seed', '0',
            '--json', str(out))
    assert r.returncode == 0, r.stderr
    assert 'heur on 2 scenes' in r.stdout and 'f_g' in r.stdout
    doc = json.loads(out.read_text())
    assert tuple(doc) == KEYS and doc['n'] == 2
    assert doc == evaluate('heur', generated_scenes(4, 2, 2, 0), robot=True, seed=0)


def test_cli_scene_dir_reads_every_file_and_names_a_bad_one(tmp_path):
    (tmp_path / 'a.json').write_text(generate_scene(GeneratorConfig(grid=3), 1).dumps())
    (tmp_path / 'b.json').write_text(generate_scene(GeneratorConfig(grid=3), 2).dumps())
    out = tmp_path / 'o.json'
    r = rad('eval', '--agent', 'heur-norobot', '--scene-dir', str(tmp_path), '--json', str(out))
    assert r.returncode == 0, r.stderr
    assert [row['name'] for row in json.loads(out.read_text())['scenes']] == ['a', 'b']
    (tmp_path / 'c.json').write_text('{"format": "rad-scene/1", "unit": ')
    r = rad('eval', '--agent', 'heur-norobot', '--scene-dir', str(tmp_path))
    assert r.returncode == 2
    assert 'c.json' in r.stderr and 'Traceback' not in r.stderr
    r = rad('eval', '--scene-dir', str(tmp_path / 'missing'))
    assert r.returncode == 2 and 'missing' in r.stderr

"""The `rad` command as users run it: the installed executable, in a subprocess."""

import json
import os
import shutil
import subprocess
import sys

import pytest

from scenes import doc


def rad(*args, stdin=None, env=None):
    exe = shutil.which('rad')
    cmd = [exe] if exe else [sys.executable, '-m', 'rad_core.cli']
    return subprocess.run(cmd + list(args), input=stdin, capture_output=True, text=True, timeout=120,
                          env=None if env is None else {**os.environ, **env})


SET_DOWN = {'RAD_GAMP_DROP': '0'}
"""The environment of a `rad` whose hand only sets blocks down (`gamp.planner.DROP_BY_DEFAULT`)."""


def test_installed_rad_is_on_path_under_the_project_environment():
    if 'RAD_TEST_HARNESS' not in os.environ:
        pytest.skip('only meaningful under scripts/test.sh')
    assert shutil.which('rad'), 'rad is not on PATH: is install/setup.bash sourced?'


def test_generate_then_allocate(tmp_path):
    scene = tmp_path / 'scene.json'
    r = rad('scene', 'generate', '--grid', '4', '--sides', '2', '--seed', '3', '-o', str(scene))
    assert r.returncode == 0, r.stderr
    r = rad('allocate', str(scene))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out['format'] == 'rad-allocation/1' and out['status'] == 'OPTIMAL'
    assert set(out) == {'format', 'status', 'objective', 'bound', 'solve_time_s', 'placements'}
    assert out['objective'] == len([c for t in json.loads(scene.read_text())['targets'] for c in t['filled']])
    for p in out['placements']:
        assert set(p) == {'type', 'target', 'yaw', 'cells'}
    r = rad('allocate', str(scene), '--solver', 'highs')
    assert json.loads(r.stdout)['objective'] == out['objective']


def test_allocate_reads_stdin_and_check_summarises():
    r = rad('allocate', '-', stdin=json.dumps(doc()))
    assert r.returncode == 0 and json.loads(r.stdout)['objective'] == 4
    r = rad('scene', 'check', '-', stdin=json.dumps(doc()))
    assert r.returncode == 0 and '4 target cells' in r.stdout


@pytest.mark.parametrize('text,expected', [
    ('{"format": "rad-scene/1", ', 'not valid JSON'),
    (json.dumps(doc(targets=[])), 'targets: expected a non-empty list'),
    (json.dumps(doc()).replace('"yaw": 90', '"yaw": 45'), 'blocks[2].yaw: 45 is not a multiple of 90'),
    (json.dumps(doc()).replace('0.6,', 'NaN,'), 'must be finite'),
])
def test_bad_input_exits_2_with_one_line(text, expected):
    r = rad('allocate', '-', stdin=text)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('rad: error:') and expected in lines[0]
    assert r.stdout == ''


def test_missing_file_and_bad_time_limit(tmp_path):
    r = rad('allocate', str(tmp_path / 'nope.json'))
    assert r.returncode == 2 and 'cannot read scene file' in r.stderr
    scene = tmp_path / 's.json'
    scene.write_text(json.dumps(doc()))
    r = rad('allocate', str(scene), '--time-limit', '0')
    assert r.returncode == 2 and 'time_limit_s must be a positive' in r.stderr


def test_rad_eval_accepts_every_allocation_support_the_agents_use():
    from rad_core.cli import build_parser
    parser = build_parser('eval')
    for support in ('none', 'stable', 'arm'):
        args = parser.parse_args(['eval', '--agent', 'greedy', '--support', support])
        assert args.support == support
    with pytest.raises(SystemExit):
        parser.parse_args(['eval', '--support', 'everywhere'])


def test_rad_ceiling_says_how_each_search_ended_and_refuses_bad_options(tmp_path):
    from rad_core.domain.generator import GeneratorConfig, generate_scene

    from scenes import flush_square
    square = tmp_path / 'square.json'
    square.write_text(flush_square().dumps())
    # GAMP's drop closes the flush square (tests/core/test_drop.py): the first line reaches the bound.
    r = rad('ceiling', str(square), '--time-limit', '60')
    assert r.returncode == 0 and 'square: ceiling 1.000, the ceiling over every allocation (it reached the bound)' \
        in r.stdout
    # No top-down hand that sets blocks down closes it: the bound, which asks for an order that hand can
    # keep, is three of four cells, and the first line reaches it.
    r = rad('ceiling', str(square), '--time-limit', '60', env=SET_DOWN)
    assert r.returncode == 0 and 'square: ceiling 0.750, the ceiling over every allocation (it reached the bound)' \
        in r.stdout
    # The vacuum gripper needs nothing beside the block: it closes the square.
    r = rad('ceiling', str(square), '--time-limit', '60', '--effector', 'suction')
    assert r.returncode == 0 and 'square: ceiling 1.000' in r.stdout, r.stdout + r.stderr
    # Generated g = 5 seed 23: five of six cells, below a bound of every cell. The allocations
    # searched to the end below it, which proves nothing about allocations never taken...
    g5 = tmp_path / 'g5.json'
    g5.write_text(generate_scene(GeneratorConfig(grid=5, sides=2), 23).dumps())
    r = rad('ceiling', str(g5), '--time-limit', '60', '--allocations-only', '--json', str(tmp_path / 'c.json'),
            env=SET_DOWN)
    assert r.returncode == 0, r.stderr
    assert ('g5: ceiling 0.833, the best found; the allocations searched do no better, any allocation '
            'covers at most 1.000' in r.stdout)
    found = json.loads((tmp_path / 'c.json').read_text())
    row = found['scenes'][0]
    assert found['support'] == ['arm', 'hand'] and row['proof'] == 'exhausted' and row['complete']
    assert row['ceiling'] == pytest.approx(5 / 6) and len(row['line']) == 3
    assert {step['block'] for step in row['line']} <= {b.id for b in generate_scene(GeneratorConfig(grid=5, sides=2),
                                                                                     23).blocks}
    # ... and every sequence of every pose searched as well: the true ceiling.
    r = rad('ceiling', str(g5), '--time-limit', '120', env=SET_DOWN)
    assert r.returncode == 0 and 'ceiling 0.833, the ceiling over every allocation (every sequence' in r.stdout
    r = rad('ceiling', str(square), '--time-limit', '1e-6', env=SET_DOWN)
    assert r.returncode == 0 and 'a lower bound (time limit' in r.stdout
    assert 'any build covers at most 0.750' in r.stdout
    r = rad('ceiling', str(square), '--support', 'arm,anywhere')
    assert r.returncode == 2 and "unknown rule 'anywhere'" in r.stderr
    r = rad('ceiling', str(square), '--time-limit', '0')
    assert r.returncode == 2 and '--time-limit must be a positive' in r.stderr


def test_rad_eval_takes_the_vacuum_gripper_serially_and_refuses_it_on_workers():
    r = rad('eval', '--agent', 'default', '--robot', '--effector', 'suction', '--workers', '2', '--scenes', '1')
    assert r.returncode == 2 and '--effector suction runs serially' in r.stderr
    r = rad('eval', '--agent', 'default', '--robot', '--effector', 'magnet', '--scenes', '1')
    assert r.returncode == 2 and "invalid choice: 'magnet'" in r.stderr

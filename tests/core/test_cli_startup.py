"""`rad` starts quickly: a command imports the heavy libraries it uses, and no others.

Building the parser used to import the agent registry (for --agent's choices) and the trainer
(for `rad train`'s config flags), and with them torch, OR-Tools and the rest, so every command
paid for all of them. Wall time, median of 5, with the background benchmark running on the
2 cores (`/tmp/cli_t/timeit.sh`: date before and after, the installed `rad`, a g = 4 scene):

    command                      before   after
    rad --help                   2.31 s   0.09 s
    rad scene check g4.json      2.44 s   0.36 s   (numpy, for the scene)
    rad allocate g4.json         3.22 s   0.73 s   (importing OR-Tools' cp_model alone: 0.69 s)

Each test runs `rad_core.cli.main` in a fresh interpreter and reads `sys.modules` after it.
"""

import json
import shutil
import subprocess
import sys

import pytest

from scenes import doc

HEAVY = ('torch', 'pybullet', 'dask', 'distributed', 'rerun')


def run_main(argv: list[str]) -> tuple[int, set[str]]:
    """main(argv)'s exit code and the top-level packages loaded once it has returned."""
    code = ('import json, sys\n'
            'from rad_core.cli import main\n'
            'try:\n'
            f'    rc = main({argv!r})\n'
            'except SystemExit as e:\n'
            '    rc = e.code\n'
            "print(json.dumps({'rc': rc, 'loaded': sorted({m.split('.')[0] for m in sys.modules})}))\n")
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert r.stdout.strip(), r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    return out['rc'], set(out['loaded'])


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / 'scene.json'
    path.write_text(json.dumps(doc()))
    return str(path)


@pytest.mark.parametrize('argv', [
    ['--help'],
    ['scene', '--help'],
    ['scene', 'check', 'SCENE'],
    ['scene', 'generate', '--grid', '3', '--seed', '2', '-o', 'OUT'],
    ['allocate', '--help'],
    ['eval', '--help'],
    ['dataset', 'build', '--help'],
])
def test_help_and_scene_commands_import_no_heavy_library(argv, scene_file, tmp_path):
    argv = [scene_file if a == 'SCENE' else str(tmp_path / 'out.json') if a == 'OUT' else a for a in argv]
    rc, loaded = run_main(argv)
    assert rc == 0
    assert loaded.isdisjoint(HEAVY + ('ortools', 'scipy')), sorted(loaded & set(HEAVY + ('ortools', 'scipy')))


def test_help_does_not_even_import_numpy():
    rc, loaded = run_main(['--help'])
    assert rc == 0 and 'numpy' not in loaded


def test_allocate_imports_its_solver_and_not_torch(scene_file, tmp_path):
    rc, loaded = run_main(['allocate', scene_file, '-o', str(tmp_path / 'allocation.json')])
    assert rc == 0
    assert 'ortools' in loaded          # the check sees what a command imports
    assert loaded.isdisjoint(HEAVY), sorted(loaded & set(HEAVY))


def rad(*args):
    exe = shutil.which('rad')
    cmd = [exe] if exe else [sys.executable, '-m', 'rad_core.cli']
    return subprocess.run(cmd + list(args), capture_output=True, text=True, timeout=120)


def test_unknown_agent_is_one_line_naming_the_valid_ones():
    r = rad('eval', '--agent', 'no-such-agent', '--scenes', '1')
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('rad: error:'), r.stderr
    assert 'no-such-agent' in lines[0] and 'heur' in lines[0]
    assert r.stdout == ''


@pytest.mark.parametrize('argv', [['train', '--help'], ['--debug', 'train', '--help']])
def test_train_help_still_lists_the_config_flags(argv):
    r = rad(*argv)
    assert r.returncode == 0, r.stderr
    assert '--total-steps' in r.stdout and '--actors' in r.stdout


def test_expert_help_lists_its_config_flags():
    r = rad('expert', '--help')
    assert r.returncode == 0, r.stderr
    assert '--anchor-weight' in r.stdout and '--rounds' in r.stdout and '--resume' in r.stdout

"""The test tiers of tests/conftest.py hold: `make test-fast` leaves out exactly the slow
and DDS tests, and a renamed or moved test cannot drop silently into the fast tier."""

import ast
import subprocess
import sys
from pathlib import Path

import conftest
from ros_harness import REPO_ROOT

# Fixtures of tests/conftest.py that bring up rclpy or start nodes.
DDS_FIXTURES = {'rclpy_session', 'ros_node', 'node_process'}


def functions_of(path: Path) -> dict[str, ast.FunctionDef]:
    tree = ast.parse(path.read_text(), filename=str(path))
    return {node.name: node for node in tree.body
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith('test')}


def uses_dds(path: Path) -> bool:
    """Whether a test file imports rclpy or takes a fixture that starts ROS."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name.split('.')[0] == 'rclpy' for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or '').split('.')[0] == 'rclpy':
            return True
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and DDS_FIXTURES & {
                a.arg for a in node.args.args}:
            return True  # a test, or a fixture of the file, built on them
    return False


def test_every_slow_entry_names_a_test_that_exists_once_with_a_reason():
    entries = [entry for entry, _ in conftest.SLOW]
    assert len(entries) == len(set(entries)), 'an entry of SLOW is listed twice'
    problems = []
    for entry, reason in conftest.SLOW:
        file, _, function = entry.partition('::')
        path = REPO_ROOT / file
        if not reason.strip():
            problems.append(f'{entry}: no reason given')
        if not path.is_file():
            problems.append(f'{entry}: no file {file}')
        elif function and function not in functions_of(path):
            problems.append(f'{entry}: {file} has no test function {function}')
        if any(file.startswith(d + '/') for d in conftest.DDS_DIRS):
            problems.append(f'{entry}: already left out of the fast tier as a DDS test')
    assert not problems, '\n'.join(problems)


def test_every_test_file_that_uses_ros_is_in_the_dds_tier():
    files = sorted((REPO_ROOT / 'tests').rglob('test_*.py'))
    assert len(files) > 20
    outside = [str(f.relative_to(REPO_ROOT)) for f in files if uses_dds(f) and 'dds' not in conftest.tiers_of(f)]
    assert not outside, f'these use rclpy or ROS fixtures but are not under {conftest.DDS_DIRS}: {outside}'
    # The check sees what it must: every node test does use ROS.
    assert all(uses_dds(f) for f in (REPO_ROOT / 'tests' / 'nodes').glob('test_*.py'))


def test_tiers_of_reads_directories_and_the_slow_list():
    assert conftest.tiers_of('tests/nodes/test_x.py', 'test_y') == {'dds'}
    assert conftest.tiers_of(REPO_ROOT / 'tests/e2e/test_x.py', 'test_y[1]') == {'dds'}
    assert conftest.tiers_of('tests/core/test_x.py', 'test_y') == set()
    assert conftest.tiers_of('tests/core/test_nodes.py', 'test_y') == set()
    slow_file, _, slow_function = conftest.SLOW[0][0].partition('::')
    assert conftest.tiers_of(slow_file, f'{slow_function}[case]') == {'slow'}
    assert conftest.tiers_of(slow_file, f'{slow_function}_other') == set()


def test_the_fast_tier_collects_no_slow_or_dds_test():
    # Collect the DDS directories and every file named in SLOW as `make test-fast` does.
    files = sorted({entry.partition('::')[0] for entry, _ in conftest.SLOW})
    r = subprocess.run([sys.executable, '-m', 'pytest', '--collect-only', '-q', '-p', 'no:cacheprovider',
                        '-m', 'not slow and not dds', *conftest.DDS_DIRS, *files],
                       cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    collected = [line for line in r.stdout.splitlines() if '::' in line]
    assert any(line.startswith('tests/core/') for line in collected), r.stdout[-3000:]
    wrong = [nodeid for nodeid in collected if conftest.tiers_of(*nodeid.split('::', 1))]
    assert not wrong, f'the fast tier holds slow or DDS tests: {wrong[:10]}'
    assert 'deselected' in r.stdout.splitlines()[-1]

"""The launch files, read as source: launch and launch_ros are not installable here (ENVIRONMENT.md),
so what can be checked without them is that each compiles and takes the shared arguments
(`rad_ros.launching`: params_file, namespace, use_sim_time, log_level) for every rad node it starts."""

import ast

import pytest
from ros_harness import REPO_ROOT

LAUNCH_FILES = sorted((REPO_ROOT / 'ros_ws' / 'src').glob('*/launch/*.launch.py'))


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_a_launch_file_compiles_and_starts_rad_nodes_with_the_shared_arguments(path):
    tree = ast.parse(path.read_text(), str(path))
    calls = [n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    assert 'arguments' in calls, f'{path.name} does not declare rad_ros.launching.arguments'
    raw = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == 'Node'
           and any(k.arg == 'package' and isinstance(k.value, ast.Constant) and str(k.value.value).startswith('rad_')
                   for k in n.keywords)]
    assert not raw, f'{path.name} starts a rad node without rad_ros.launching.node'


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_a_launch_file_of_the_graph_starts_its_managed_nodes_unconfigured_under_a_lifecycle_manager(path):
    """A graph (one with the assembly node) is brought up in order by a lifecycle manager; a launch
    file of one node (twin.launch.py) leaves that node to start itself (autostart)."""
    text = path.read_text()
    if "'assembly_node'" not in text:
        pytest.skip(f'{path.name} starts no graph')
    assert "'lifecycle_manager'" in text, f'{path.name} starts managed nodes without rad_planner lifecycle_manager'
    assert "'autostart'" in text and 'False' in text, \
        f'{path.name} leaves autostart on where a lifecycle manager brings nodes up'

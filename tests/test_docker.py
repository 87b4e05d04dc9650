"""scripts/check_docker.py passes on the repository's docker/ files and catches each fault it is
for: on a copy of the files it reads, one thing broken at a time, it fails naming it."""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
import sys

import pytest
from ros_harness import REPO_ROOT

SCRIPT = REPO_ROOT / 'scripts' / 'check_docker.py'
_spec = importlib.util.spec_from_file_location('check_docker', SCRIPT)
check_docker = importlib.util.module_from_spec(_spec)
sys.modules.setdefault('check_docker', check_docker)   # dataclasses look their module up there
_spec.loader.exec_module(check_docker)

ROS_PIN = re.compile(r'(ros-jazzy-[a-z0-9-]+)=(\S+)')


def test_the_repository_passes():
    r = subprocess.run([sys.executable, str(SCRIPT)], cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) >= 10 and all(line.startswith('ok') for line in lines[:-1]), r.stdout
    assert 'all' in lines[-1] and 'passed' in lines[-1]


@pytest.fixture
def repo(tmp_path):
    """A copy of every file the checker reads."""
    for name in ('docker', 'requirements', 'config', 'docs/examples'):
        shutil.copytree(REPO_ROOT / name, tmp_path / name)
    (tmp_path / 'scripts').mkdir()
    shutil.copy(REPO_ROOT / 'scripts' / 'setup.sh', tmp_path / 'scripts' / 'setup.sh')
    for setup in (REPO_ROOT / 'ros_ws' / 'src').glob('*/setup.py'):
        package = tmp_path / 'ros_ws' / 'src' / setup.parent.name
        package.mkdir(parents=True)
        shutil.copy(setup, package / 'setup.py')
        if (setup.parent / 'config').is_dir():
            shutil.copytree(setup.parent / 'config', package / 'config')
    return tmp_path


def run(root, capsys) -> tuple[int, str]:
    code = check_docker.main(['--root', str(root)])
    return code, capsys.readouterr().out


def edit(path, old, new, count=1):
    text = path.read_text()
    assert text.count(old) >= count, f'{old!r} not in {path.name}'
    path.write_text(text.replace(old, new, count))


def test_the_copy_passes(repo, capsys):
    code, out = run(repo, capsys)
    assert code == 0, out


def failed(out: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith('FAIL')]


def test_a_floating_base_tag_fails(repo, capsys):
    dockerfile = repo / 'docker' / 'Dockerfile'
    dockerfile.write_text(re.sub(r'^FROM \S+@sha256:[0-9a-f]{64}', 'FROM ros:jazzy', dockerfile.read_text(),
                                 count=1, flags=re.M))
    code, out = run(repo, capsys)
    assert code == 1
    assert 'FROM ros:jazzy is a floating tag' in out
    assert len(failed(out)) == 1, out


def test_an_unpinned_apt_package_fails(repo, capsys):
    dockerfile = repo / 'docker' / 'Dockerfile'
    pin = ROS_PIN.search(dockerfile.read_text())
    edit(dockerfile, pin.group(0), pin.group(1))
    code, out = run(repo, capsys)
    assert code == 1
    assert f'apt package {pin.group(1)} has no version' in out


def test_an_apt_pin_other_than_the_list_fails(repo, capsys):
    dockerfile = repo / 'docker' / 'Dockerfile'
    pin = ROS_PIN.search(dockerfile.read_text())
    edit(dockerfile, pin.group(0), f'{pin.group(1)}=0.0.1-1*')
    code, out = run(repo, capsys)
    assert code == 1
    assert f'{pin.group(1)}: the Dockerfile pins 0.0.1-1*, docker/apt-versions.txt says {pin.group(2)}' in out


def test_a_pip_version_other_than_constraints_fails(repo, capsys):
    edit(repo / 'docker' / 'Dockerfile', '-r /tmp/requirements-image.txt',
         '-r /tmp/requirements-image.txt numpy==1.26.4')
    numpy = check_docker.pins(repo / 'requirements' / 'constraints.txt')['numpy']
    code, out = run(repo, capsys)
    assert code == 1
    assert f'numpy==1.26.4: requirements/constraints.txt pins numpy=={numpy}' in out


def test_host_networking_without_ipc_host_fails(repo, capsys):
    compose = repo / 'docker' / 'compose.yaml'
    text = compose.read_text()
    mocap = text.index('  mocap:\n')
    compose.write_text(text[:mocap] + text[mocap:].replace('    ipc: host\n', '', 1))
    code, out = run(repo, capsys)
    assert code == 1
    assert 'mocap: network_mode host without ipc: host' in out
    assert len(failed(out)) == 1, out


def test_loopback_dds_on_the_cell_fails(repo, capsys):
    edit(repo / 'docker' / 'compose.yaml', 'ROS_AUTOMATIC_DISCOVERY_RANGE: SUBNET',
         'ROS_AUTOMATIC_DISCOVERY_RANGE: LOCALHOST')
    edit(repo / 'docker' / 'compose.yaml', '${RAD_DDS_PROFILE:-../docs/examples/fastdds_lan.xml}',
         '${RAD_DDS_PROFILE:-../config/fastdds_loopback.xml}', count=4)
    code, out = run(repo, capsys)
    assert code == 1
    assert 'cell-assembly: ROS_AUTOMATIC_DISCOVERY_RANGE is LOCALHOST, not SUBNET' in out
    assert 'cell-assembly: config/fastdds_loopback.xml is not a LAN profile' in out


# One edit of one file, and the line the checker must print: (file, old, new, how many, expected).
EDITS = {
    'pip without constraints': ('docker/Dockerfile', ' -c requirements/constraints.txt', '', 1,
                                'pip install without -c requirements/constraints.txt'),
    'unknown executable': ('docker/compose.yaml', 'ros2 run rad_gamp gamp_node', 'ros2 run rad_gamp gamp_nod', 1,
                           'gamp: rad_gamp has no executable gamp_nod'),
    'missing params file': ('docker/compose.yaml', 'config/graph.yaml -p', 'config/graf.yaml -p', 1,
                            'viz: params file /rad/ros_ws/install/rad_planner/share/rad_planner/config/graf.yaml'),
    'missing profile': ('docker/compose.yaml', 'profiles: [mocap]', 'profiles: [tracking]', 1,
                        'no service in profile mocap'),
    'fixed domain id': ('docker/compose.yaml', 'ROS_DOMAIN_ID: ${ROS_DOMAIN_ID:-42}', 'ROS_DOMAIN_ID: "42"', 2,
                        'cell-gamp: ROS_DOMAIN_ID is not taken from the environment'),
}


@pytest.mark.parametrize('fault', sorted(EDITS))
def test_each_edit_fails_naming_it(repo, capsys, fault):
    path, old, new, count, expected = EDITS[fault]
    edit(repo / path, old, new, count)
    code, out = run(repo, capsys)
    assert code == 1
    assert expected in out, out

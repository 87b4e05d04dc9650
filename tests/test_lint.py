"""Static checks on all Python of the project: pyflakes and pycodestyle (ruff.toml)."""

import shutil
import subprocess

from ros_harness import REPO_ROOT


def test_ruff_finds_nothing():
    ruff = shutil.which('ruff')
    assert ruff, 'ruff is not installed: run scripts/setup.sh'
    r = subprocess.run([ruff, 'check', '--output-format', 'concise', 'ros_ws/src', 'tests', 'benchmarks'],
                       cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:]

"""The core never imports rclpy: nodes wrap it, not the other way round."""

import pkgutil
import subprocess
import sys

import rad_core


def test_importing_every_core_module_does_not_load_rclpy():
    names = [m.name for m in pkgutil.walk_packages(rad_core.__path__, 'rad_core.')]
    assert 'rad_core.env.mdp' in names and 'rad_core.allocation.cpsat' in names
    code = ('import importlib, sys\n'
            f'for n in {names!r}: importlib.import_module(n)\n'
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rad_msgs', 'rclpy_message'))\n"
            'print(bad)\n')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == '[]'

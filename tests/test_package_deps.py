"""Every package.xml names what its package's Python imports (rosdep keys for the Python libraries)."""

import ast
import re
import sys

import pytest
from ros_harness import REPO_ROOT

SRC = REPO_ROOT / 'ros_ws' / 'src'

# Python libraries and the rosdep keys package.xml names them by.
ROSDEP = {'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml', 'torch': 'python3-torch',
          'pybullet': 'python3-pybullet', 'pybullet_data': 'python3-pybullet', 'ortools': 'python3-ortools',
          'ruckig': 'python3-ruckig', 'trimesh': 'python3-trimesh', 'rerun': 'python3-rerun-sdk',
          'matplotlib': 'python3-matplotlib', 'dask': 'python3-dask', 'distributed': 'python3-dask',
          'tensorboardX': 'python3-tensorboardx', 'pytest': 'python3-pytest',
          'mcap': 'python3-mcap', 'networkx': 'python3-networkx'}
BUILD_ONLY = {'setuptools'}        # setup.py's


def imports(package) -> set[str]:
    names = set()
    for path in package.rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(a.name.split('.')[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - BUILD_ONLY - {'__future__'}


PYTHON_PACKAGES = sorted(p.parent.name for p in SRC.glob('*/package.xml') if (p.parent / 'setup.py').exists())


@pytest.mark.parametrize('name', PYTHON_PACKAGES)
def test_package_xml_names_every_import(name):
    xml = (SRC / name / 'package.xml').read_text()
    declared = set(re.findall(r'<(?:exec_|build_|test_)?depend>\s*([^<\s]+)\s*</', xml))
    missing = sorted(f'{m} ({ROSDEP.get(m, m)})' for m in imports(SRC / name) - {name}
                     if ROSDEP.get(m, m) not in declared)
    assert not missing, f'{name}/package.xml lacks: {", ".join(missing)}'

"""The ladder of rad_core: each sub-package imports only those below it, and no module imports
itself back through others. Every import counts, at the top of a file or inside a function."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[2] / 'ros_ws' / 'src' / 'rad_core' / 'rad_core'

# Bottom to top. A module's layer is the longest of these prefixes of its dotted path.
LAYERS = (
    'domain',                   # blocks, grid, scenes, shapes and targets
    'cell',                     # robot model, limits, trajectories, motions, calibration, motion capture
    'sim',                      # physics and the twin
    'gamp',                     # grasp and motion planning
    'env',                      # the assembly MDP, with and without the robot
    'allocation',               # CP-SAT allocation, the hand's order model, supply
    'learning',                 # the graph observation, the Q-network, the Q-policy
    'sequencing.decide',        # scoring and search
    'sequencing.planning',      # a plan from an allocation
    'sequencing.bounds',        # ceilings
    'sequencing.agent',         # an agent's planning as stages under one deadline
    'sequencing.execution',     # running a plan
    'experiment',               # evaluation and scale-out
    'training',                 # DQN, expert iteration, actors
    'view',                     # renders, Rerun views, progress
    'cli',                      # the command line
)
# A package's __init__ that re-exports from one of its own sub-packages sits with it.
PACKAGE_LAYER = {'sequencing': 'sequencing.decide'}


def module_name(path: Path) -> str:
    rel = path.relative_to(CORE).with_suffix('')
    parts = list(rel.parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(CORE.rglob('*.py'))}


def layer(name: str) -> int | None:
    name = PACKAGE_LAYER.get(name, name)
    best = None
    for i, prefix in enumerate(LAYERS):
        if name == prefix or name.startswith(prefix + '.'):
            if best is None or len(prefix) > len(LAYERS[best]):
                best = i
    return best


def imports(path: Path, known: dict[str, Path]) -> list[tuple[int, str]]:
    """(line, module of rad_core) for every import statement in the file: `from a import b` is
    an import of a.b where that is a module, of a otherwise."""
    me = module_name(path)
    package = me if path.name == '__init__.py' else me.rpartition('.')[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.') if package else []
                base = base[:len(base) - node.level + 1]
                mod = '.'.join(base + ([node.module] if node.module else []))
                base_name = 'rad_core.' + mod if mod else 'rad_core'
            else:
                base_name = node.module or ''
            names = [f'{base_name}.{a.name}' if f'{base_name}.{a.name}'[9:] in known else base_name
                     for a in node.names]
        else:
            continue
        for n in names:
            if n.startswith('rad_core.') and n[9:] in known:
                out.append((node.lineno, n[9:]))
    return out


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: {n for _, n in imports(path, known) if n != name} for name, path in known.items()}


def test_every_module_has_a_layer():
    loose = [n for n in modules() if n and layer(n) is None]
    assert not loose, f'modules outside every layer of {LAYERS}: {loose}'


def test_no_module_imports_a_layer_above_its_own():
    known = modules()
    bad = []
    for name, path in known.items():
        if not name:
            continue
        mine = layer(name)
        for line, other in imports(path, known):
            theirs = layer(other)
            if theirs is not None and mine is not None and theirs > mine:
                bad.append(f'{path.relative_to(CORE)}:{line} ({LAYERS[mine]}) imports {other} ({LAYERS[theirs]})')
    assert not bad, 'imports up the ladder:\n' + '\n'.join(bad)


def strongly_connected(g: dict[str, set[str]]) -> list[list[str]]:
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def test_no_import_circle():
    g = graph()
    # A package's __init__ re-exporting its modules is not a circle through the package.
    for name in list(g):
        g[name] = {n for n in g[name] if not (modules()[n].name == '__init__.py' and name.startswith(n + '.'))}
    circles = strongly_connected(g)
    assert not circles, f'import circles: {circles}'


def test_checker_sees_an_upward_import(tmp_path, monkeypatch):
    """The checks above are not blind: an upward import in a copy of the tree is found."""
    fake = tmp_path / 'rad_core'
    (fake / 'domain').mkdir(parents=True)
    (fake / 'cli.py').write_text('')
    (fake / '__init__.py').write_text('')
    (fake / 'domain' / '__init__.py').write_text('')
    (fake / 'domain' / 'scene.py').write_text('def f():\n    from rad_core.cli import main\n')
    monkeypatch.setattr(__import__(__name__), 'CORE', fake)
    with pytest.raises(AssertionError, match='imports cli'):
        test_no_module_imports_a_layer_above_its_own()
    (fake / 'cli.py').write_text('from rad_core.domain import scene\n')
    with pytest.raises(AssertionError, match='import circles'):
        test_no_import_circle()

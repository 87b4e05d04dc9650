"""Small hand-made scenes for core tests."""

from __future__ import annotations

import copy

from rad_core.domain.scene import Scene

U = 0.05


def doc(blocks=None, targets=None, types=None, unit=U) -> dict:
    """A valid rad-scene/1 document; pass parts to override."""
    return {
        'format': 'rad-scene/1',
        'unit': unit,
        'block_types': types if types is not None else {
            'cube': [[0, 0, 0]], 'I2': [[0, 0, 0], [1, 0, 0]], 'L3_up': [[0, 0, 0], [1, 0, 0], [0, 0, 1]]},
        'blocks': blocks if blocks is not None else [
            {'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0},
            {'id': 'c1', 'type': 'cube', 'position': [0.5, -0.2, U / 2], 'yaw': 0},
            {'id': 'i0', 'type': 'I2', 'position': [0.6, -0.2, U / 2], 'yaw': 90},
        ],
        'targets': targets if targets is not None else [
            {'name': 'front', 'origin': [0.45, 0.1, U / 2], 'size': [3, 1, 2],
             'filled': [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 1]]},
        ],
    }


def scene(**kw) -> Scene:
    return Scene.from_dict(doc(**kw))


def packed() -> Scene:
    """A cube b4 with neighbours 1 cm off along x (b1) and 1.5 cm off along y (b2): too close for the
    fingers' tips on both closing axes, so every grasp of b4 is blocked until b1 (the nearest, which
    the hand can take itself) moves aside."""
    cubes = {'b4': (0.45, -0.25), 'b1': (0.45 + U + 0.01, -0.25), 'b2': (0.45, -0.25 + U + 0.015)}
    return scene(types={'cube': [[0, 0, 0]]},
                 blocks=[{'id': b, 'type': 'cube', 'position': [x, y, U / 2], 'yaw': 0} for b, (x, y) in cubes.items()],
                 targets=[{'name': 't', 'origin': [0.4, 0.25, U / 2], 'size': [2, 1, 1],
                           'filled': [[0, 0, 0], [1, 0, 0]]}])


def flush_square():
    """A flush 2 x 2 square to fill from two I2s and three cubes."""
    bars = [{'id': f'i{k}', 'type': 'I2', 'position': [0.35 + 0.15 * k, -0.25, U / 2], 'yaw': 0} for k in range(2)]
    cubes = [{'id': f'c{k}', 'type': 'cube', 'position': [0.35 + 0.1 * k, -0.4, U / 2], 'yaw': 0} for k in range(3)]
    blocks = bars + cubes
    return scene(types={'cube': [[0, 0, 0]], 'I2': [[0, 0, 0], [1, 0, 0]]}, blocks=blocks,
                 targets=[{'name': 't', 'origin': [0.45, 0.15, U / 2], 'size': [2, 2, 1],
                           'filled': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}])


def mutated(path: str, value) -> dict:
    """A copy of the default doc with one field (dotted path, [n] for lists) replaced."""
    d = copy.deepcopy(doc())
    keys = path.replace('[', '.').replace(']', '').split('.')
    obj = d
    for k in keys[:-1]:
        obj = obj[int(k)] if isinstance(obj, list) else obj[k]
    last = keys[-1]
    if isinstance(obj, list):
        obj[int(last)] = value
    elif value is KeyError:
        del obj[last]
    else:
        obj[last] = value
    return d

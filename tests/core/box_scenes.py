"""Scenes of a solid box shared by the wide-grasp and the vacuum-gripper tests."""

from rad_core.domain.scene import Scene

BOX = (0.42, 0.10)
"""x, y of the box's first cell's centre (m)."""


def box_but_one(unit: float, clearance: float = 0.0) -> Scene:
    """A solid 4 x 2 x 2 box of flat I2s lying across it (yaw 90), one per column and layer, all built
    but the top one of column 1, which lies on the table: its place has built neighbours on both
    sides along x, where its unit grasps close; its ends are the box's outer faces."""
    blocks = [{'id': f'b{i}{k}', 'type': 'I2', 'position': [BOX[0] + i * unit, BOX[1], unit / 2 + k * unit], 'yaw': 90}
              for k in range(2) for i in range(4) if (i, k) != (1, 1)]
    blocks.append({'id': 'm', 'type': 'I2', 'position': [0.45, -0.25, unit / 2], 'yaw': 0})
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': unit, 'clearance': clearance, 'block_types': {'I2': [[0, 0, 0], [1, 0, 0]]},
        'blocks': blocks,
        'targets': [{'name': 't', 'origin': [BOX[0], BOX[1], unit / 2], 'size': [4, 2, 2],
                     'filled': [[i, j, k] for i in range(4) for j in range(2) for k in range(2)]}]})

"""The hand's own order of an allocation (`sequencing.hand_order`): order repair's second chain."""

from __future__ import annotations

import numpy as np
import pytest

from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.arm import HandBlocked
from rad_core.grid import Grid
from rad_core.scene import Scene
from rad_core.sequencing.hand_order import hand_order

from scenes import scene as make_scene

U = 0.05


def square(n_cubes: int = 4) -> Scene:
    """A flush 2 x 2 square of cube cells on the table, and cubes on the table for it."""
    blocks = [{'id': f'c{k}', 'type': 'cube', 'position': [0.35 + 0.1 * k, -0.3, U / 2], 'yaw': 0}
              for k in range(n_cubes)]
    return make_scene(blocks=blocks, unit=U, types={'cube': [[0, 0, 0]]},
                      targets=[{'name': 't', 'origin': [0.45, 0.1, U / 2], 'size': [2, 2, 1],
                                'filled': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}])


def replay(scene: Scene, found) -> None:
    """Every pose of the order, placed in turn, has a way of being held that no earlier pose blocks,
    and the order keeps to its precedences."""
    grid = Grid(scene)
    hand = HandBlocked(scene, grid)
    occupied = np.zeros(grid.num_cells, dtype=bool)
    where = {cells: k for k, cells in enumerate(found.order)}
    for p in found.precedences:
        assert where[p.first] < where[p.then]
    for cells in found.order:
        assert not hand.blocked('cube', 0, cells, occupied), cells
        occupied[list(cells)] = True


def test_a_flush_square_places_three_cubes_in_an_order_the_hand_can_keep():
    # Each cube is taken with the fingers across one of its two neighbours in the square: the last of
    # four would have both built. So three, each before the neighbour its fingers go past.
    scene = square()
    placements = solve(scene).placements
    assert len(placements) == 4
    found = hand_order(scene, placements)
    assert len(found.order) == 3
    replay(scene, found)
    assert found.precedences           # at least one cube goes before a neighbour its fingers pass
    assert all(p.reason == 'hand order' for p in found.precedences)


def test_poses_needing_no_order_give_no_precedences_and_built_cells_count():
    # Two cubes side by side in a one-cell-deep row: the fingers close across the row, both free.
    blocks = [{'id': f'c{k}', 'type': 'cube', 'position': [0.35 + 0.1 * k, -0.3, U / 2], 'yaw': 0}
              for k in range(2)]
    row = make_scene(blocks=blocks, unit=U, types={'cube': [[0, 0, 0]]},
                     targets=[{'name': 't', 'origin': [0.45, 0.1, U / 2], 'size': [2, 1, 1],
                               'filled': [[0, 0, 0], [1, 0, 0]]}])
    found = hand_order(row, solve(row).placements)
    assert len(found.order) == 2 and found.precedences == []
    # The square with one cube already built in a corner: three cells open, two of them beside it.
    scene = square()
    d = scene.to_dict()
    d['blocks'][0]['position'] = [0.45, 0.1, U / 2]          # c0 on cell (0, 0)
    built = Scene.from_dict(d)
    placements = solve(built).placements
    assert len(placements) == 3
    found = hand_order(built, placements)
    grid = Grid(built)
    corner = grid.index(0, (0, 0, 0))
    assert all(corner not in cells for cells in found.order)
    # The cell across from the built corner is hemmed in last: two of the three.
    assert len(found.order) == 2


@pytest.mark.slow
def test_order_repair_with_the_hands_order_builds_held_out_spire_cup_whole():
    # Refusals alone taught contradictory precedences here (two tall blocks back to back, each
    # placeable only while the other is not there yet): the default agent stopped at 0.917.
    from rad_core.agents import parse
    from rad_core.sequencing.agent_plan import AgentPlanner
    from rad_core.shapes import shape_scene
    scene = shape_scene('spire_cup')
    assert hand_order(scene, solve(scene, AllocationParams(support='arm')).placements).precedences
    plan = AgentPlanner('default', time_limit_s=120)(scene, None, 0)
    assert parse('default').repair
    assert plan.predicted_coverage == 1.0 and plan.success
    assert 'repair' in [a['plan'] for a in plan.anytime]

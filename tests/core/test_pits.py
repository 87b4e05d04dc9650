"""`sequencing.planning.plan.pits_last`: actions that would leave an open pose in a pit go last."""

from __future__ import annotations

from rad_core.allocation.cpsat import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.scene import Scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.sequencing.planning.plan import pits_last

from scenes import U, doc


def test_a_block_rising_above_an_open_pose_beside_it_is_tried_after_the_others():
    # A two-deep wall 2 x 2 per face (the generator's back-to-back faces), cubes only.
    cubes = [{'id': f'c{n}', 'type': 'cube', 'position': [0.3 + 0.07 * n, -0.25, U / 2], 'yaw': 0} for n in range(8)]
    faces = [{'name': name, 'origin': [0.45, y, U / 2], 'size': [2, 1, 2],
              'filled': [[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]]} for name, y in (('left', U / 2),
                                                                                       ('right', -U / 2))]
    scene = Scene.from_dict(doc(blocks=cubes, targets=faces, types={'cube': [[0, 0, 0]]}))
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    guide = AllocationGuide(scene, solve(scene).placements, env.grid)

    def action_at(region: str, ijk):
        cell = env.grid.index([t.name for t in scene.targets].index(region), ijk)
        return next(a for a in guide.allowed_actions(env.state) if a.cell == cell)

    env.step(action_at('right', (0, 0, 0)))
    up = action_at('right', (0, 0, 1))           # one layer above the open left (0, 0, 0) beside it
    beside = action_at('left', (1, 0, 0))
    assert pits_last(env, guide, [up, beside]) == [beside, up]
    assert pits_last(env, guide, [beside, up]) == [beside, up]
    # Once nothing lower is open beside it, the ranking stands.
    for region, ijk in (('left', (0, 0, 0)), ('left', (1, 0, 0)), ('right', (1, 0, 0))):
        assert not env.step(action_at(region, ijk)).outcome.is_invalid
    up, high = action_at('right', (0, 0, 1)), action_at('left', (1, 0, 1))
    assert pits_last(env, guide, [up, high]) == [up, high]

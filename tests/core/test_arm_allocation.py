"""support='arm': the allocation rules out what the arm can never do, at the level it fails."""

import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.domain.scene import Scene

from scenes import doc

U = 0.04
SQUARE = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]     # a flat 2x2: no unit free for both fingers


def square_scene(far_cube: bool = False, far_target: bool = False) -> Scene:
    """A 2x2 flat target at a 4 cm unit; one 2x2 square block and four cubes that could fill it."""
    blocks = [{'id': 'sq', 'type': 'O4', 'position': [0.35, -0.25, U / 2], 'yaw': 0}]
    blocks += [{'id': f'c{n}', 'type': 'cube', 'position': [0.35 + 0.08 * n, -0.4, U / 2], 'yaw': 0}
               for n in range(4)]
    if far_cube:
        blocks[-1]['position'] = [0.95, -0.6, U / 2]       # 1.1 m from the shoulder: beyond reach
    origin = [1.05, 0.0, U / 2] if far_target else [0.45, 0.1, U / 2]
    return Scene.from_dict(doc(blocks=blocks, unit=U, types={'O4': SQUARE, 'cube': [[0, 0, 0]]},
                               targets=[{'name': 't', 'origin': origin, 'size': [2, 2, 1],
                                         'filled': [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}]))


def test_a_type_the_hand_cannot_take_is_never_allocated_and_the_others_fill_in():
    scene = square_scene()
    blind = solve(scene, AllocationParams(support='stable'))
    assert [p.type for p in blind.placements] == ['O4']          # the fewest-poses fill the paper's MILP finds
    arm = solve(scene, AllocationParams(support='arm'))
    assert sorted(p.type for p in arm.placements) == ['cube'] * 4 and arm.objective == 4
    assert 'no top-down grasp' in arm.arm.types['O4'] and not arm.arm.blocks
    assert arm.to_dict()['arm']['types'] == {'O4': arm.arm.types['O4']}


def test_a_block_out_of_reach_is_not_counted_and_a_pose_out_of_reach_not_offered():
    arm = solve(square_scene(far_cube=True), AllocationParams(support='arm'))
    assert set(arm.arm.blocks) == {'c3'} and 'from the shoulder' in arm.arm.blocks['c3']
    assert arm.objective == 3            # three cubes within reach for four cells
    far = solve(square_scene(far_target=True), AllocationParams(support='arm'))
    assert far.placements == () and far.arm.poses > 0
    assert solve(square_scene(far_target=True), AllocationParams(support='stable')).objective == 4


def test_nothing_is_ruled_out_where_the_arm_can_do_everything():
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    for seed in (500, 501):
        scene = generate_scene(GeneratorConfig(grid=4), seed)
        stable = solve(scene, AllocationParams(support='stable'))
        arm = solve(scene, AllocationParams(support='arm'))
        assert arm.placements == stable.placements
        assert arm.arm.summary() == 'nothing ruled out'


def test_prefer_needs_a_support_rule():
    with pytest.raises(Exception, match="needs support='stable' or 'arm'"):
        solve(square_scene(), AllocationParams(prefer='fewer'))
    assert solve(square_scene(), AllocationParams(support='arm', prefer='fewer')).has_solution


def test_a_plan_whose_allocation_places_nothing_says_what_the_arm_cannot_do():
    from rad_core.sequencing.decide.policy import HeurPolicy
    from rad_core.sequencing.planning.plan import plan_assembly

    def never(*_):
        raise AssertionError('nothing to plan a motion for')
    plan = plan_assembly(square_scene(far_target=True), lambda s: solve(s, AllocationParams(support='arm')),
                         never, HeurPolicy())
    assert not plan.success and plan.steps == []
    assert plan.reason.startswith('the allocation places no block') and 'out of reach' in plan.reason
    assert 'no top-down grasp' in plan.reason                    # and the square type, too

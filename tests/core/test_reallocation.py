"""Re-allocation when sequencing stalls (rad_core.sequencing.planning.reallocation) and its CP-SAT parts."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.constraints import rests_now
from rad_core.allocation.cpsat import pose_key
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.experiment.evaluation import evaluate, get_agent
from rad_core.sequencing.decide.actions import AllocationActions
from rad_core.sequencing.decide.deciders import Check, policy_decider
from rad_core.sequencing.decide.episode import run_episode
from rad_core.sequencing.decide.policy import HeurPolicy
from rad_core.sequencing.planning.reallocation import ReallocationConfig, Reallocator, placed_scene, with_reallocation

from tests.scenes import U
from tests.scenes import scene as small_scene

STABLE = AllocationParams(support='stable')
ROW = [{'name': 'front', 'origin': [0.45, 0.1, U / 2], 'size': [2, 1, 1], 'filled': [[0, 0, 0], [1, 0, 0]]}]


def keys(result) -> set:
    return {pose_key(p.type, p.target, p.cells) for p in result.placements}


def test_excluded_poses_are_never_chosen_and_the_yaw_does_not_matter():
    scene = generate_scene(GeneratorConfig(grid=3), 3)
    first = solve(scene, STABLE)
    banned = [replace(p, yaw=(p.yaw + 180) % 360) for p in first.placements[:2]]
    again = solve(scene, STABLE, exclude=banned)
    assert again.status == 'OPTIMAL'
    assert not keys(again) & {pose_key(p.type, p.target, p.cells) for p in banned}
    assert again.objective <= first.objective


def test_fewer_keeps_objective_and_coverage_and_never_uses_more_poses():
    for seed in range(6):
        scene = generate_scene(GeneratorConfig(grid=4), seed)
        plain, fewer = solve(scene, STABLE), solve(scene, replace(STABLE, prefer='fewer'))
        assert fewer.status == plain.status == 'OPTIMAL'
        assert fewer.objective == plain.objective
        covered = [len({(p.target, c) for p in r.placements for c in p.cells}) for r in (plain, fewer)]
        assert covered[0] == covered[1]
        assert len(fewer.placements) <= len(plain.placements)


def test_fewer_prefers_one_big_block_over_two_cubes():
    blocks = [{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0},
              {'id': 'c1', 'type': 'cube', 'position': [0.5, -0.2, U / 2], 'yaw': 0},
              {'id': 'i0', 'type': 'I2', 'position': [0.6, -0.2, U / 2], 'yaw': 0}]
    scene = small_scene(blocks=blocks, targets=ROW)
    assert [p.type for p in solve(scene, replace(STABLE, prefer='fewer')).placements] == ['I2']


def test_flat_prefers_lying_blocks_over_standing_ones():
    types = {'I2': [[0, 0, 0], [1, 0, 0]], 'I2_up': [[0, 0, 0], [0, 0, 1]]}
    blocks = [{'id': f'{t}{n}', 'type': t, 'position': [0.3 + 0.1 * n + (0.25 if t == 'I2' else 0), -0.2, U / 2],
               'yaw': 0} for t in ('I2', 'I2_up') for n in range(2)]
    square = [{'name': 'front', 'origin': [0.45, 0.1, U / 2], 'size': [2, 1, 2],
               'filled': [[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]]}]
    scene = small_scene(blocks=blocks, targets=square, types=types)
    flat = solve(scene, replace(STABLE, prefer='flat'))
    assert flat.objective == 4 and [p.type for p in flat.placements] == ['I2', 'I2']
    tall = {'I2': [[0, 0, 0], [1, 0, 0]], 'I2_up': [[0, 0, 0], [0, 0, 1]]}
    assert solve(small_scene(blocks=blocks[2:], targets=square, types=tall), replace(STABLE, prefer='flat')) \
        .objective == 4    # standing blocks only: still the best coverage, the preference only breaks ties


def test_prefer_needs_the_stable_allocation():
    with pytest.raises(RadError, match="prefer='fewer' needs support='stable'"):
        AllocationParams(prefer='fewer').validate()
    with pytest.raises(RadError, match='prefer must be one of'):
        AllocationParams(support='stable', prefer='most').validate()


def test_placed_blocks_stay_fixed_in_a_reallocation():
    scene = generate_scene(GeneratorConfig(grid=3), 5)
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    space = AllocationActions(env, solve(scene, STABLE).placements)
    decide = policy_decider(HeurPolicy(), space)
    rng = np.random.default_rng(0)
    for _ in range(2):
        env.step(decide(env, rng).action)
    placed_cells = {int(c) for cells, _ in env.state.placed.values() for c in cells}
    again = solve(placed_scene(env), STABLE)
    names = [t.name for t in scene.targets]
    for p in again.placements:
        ids = {env.grid.index(names.index(p.target), c) for c in p.cells}
        assert not ids & placed_cells
    used = {}
    for p in again.placements:
        used[p.type] = used.get(p.type, 0) + 1
    for t, n in used.items():
        left = sum(1 for b, blk in enumerate(scene.blocks) if blk.type == t and b not in env.state.placed)
        assert n <= left


def test_rests_now_is_the_stable_rule_on_what_is_there():
    scene = small_scene()
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    occupied = np.zeros(env.grid.num_cells, dtype=bool)
    ground, upper = env.grid.index(0, (0, 0, 0)), env.grid.index(0, (0, 0, 1))
    assert rests_now(env.grid, [ground], occupied)
    assert not rests_now(env.grid, [upper], occupied)
    occupied[ground] = True
    assert rests_now(env.grid, [upper], occupied)


def failing_at(cells_of_failing: set[int], env: AssemblyEnv):
    """A check that fails every action whose block would cover one of the given cells
    (a mock fault: GAMP would have to fail on demand) and passes the rest."""
    def check(action) -> Check:
        cells, _ = env.resulting_cells(action)
        if set(int(c) for c in cells) & cells_of_failing:
            return Check(False, 'hand hits block x (made to fail)')
        return Check(True)
    return check


def test_a_failing_pose_becomes_a_no_good_and_the_sequencer_goes_on_with_a_new_allocation():
    blocks = [{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0},
              {'id': 'c1', 'type': 'cube', 'position': [0.5, -0.2, U / 2], 'yaw': 0},
              {'id': 'i0', 'type': 'I2', 'position': [0.6, -0.2, U / 2], 'yaw': 0}]
    scene = small_scene(blocks=blocks, targets=ROW)
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    first = solve(scene, replace(STABLE, prefer='fewer'))
    space = AllocationActions(env, first.placements)
    i2_block = [b.id for b in scene.blocks].index('i0')

    def check(action) -> Check:   # the I2 cannot be placed (a fault made to happen), cubes can
        return Check(action.block != i2_block, 'placement: hand hits block c1')

    from rad_core.sequencing.decide.policy import first_feasible

    def decide_verified(env_, rng):
        from rad_core.sequencing.decide.episode import Decision, stop
        from rad_core.sequencing.decide.policy import ranked_actions
        action, _, _ = first_feasible(env_, ranked_actions(HeurPolicy(), env_, space(env_), rng), check)
        return Decision(action) if action is not None else stop('no feasible next action')

    realloc = Reallocator(space, check)
    episode = run_episode(env, with_reallocation(decide_verified, realloc), np.random.default_rng(0))
    assert episode.coverage == 1.0
    assert len(realloc.events) == 1
    event = realloc.events[0]
    assert event.changed and event.step == 0 and event.status == 'OPTIMAL'
    assert event.no_goods == [{'type': 'I2', 'target': 'front', 'cells': [[0, 0, 0], [1, 0, 0]],
                               'reason': 'i0: placement: hand hits block c1'}]
    assert sorted(p.type for p in event.placements) == ['cube', 'cube']
    assert 'no feasible next action' in event.reason and 'excluded 1 poses' in event.summary()
    doc = event.to_dict()
    assert doc['placements'][0]['type'] == 'cube' and doc['changed'] is True


def grasp_fails_for(block_ids: set[int], env: AssemblyEnv):
    """A check whose GAMP cannot pick the given blocks where they lie (failure 'grasp', a mock
    fault: real GAMP fails only where the table is laid out so) and passes the rest."""
    def check(action) -> Check:
        if action.block in block_ids:
            return Check(False, 'grasp: all 2 grasps blocked: left finger hits block x', failure='grasp')
        return Check(True)
    return check


def test_a_block_that_cannot_be_picked_is_excluded_as_a_block_until_the_table_changes():
    blocks = [{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0},
              {'id': 'c1', 'type': 'cube', 'position': [0.5, -0.2, U / 2], 'yaw': 0},
              {'id': 'i0', 'type': 'I2', 'position': [0.6, -0.2, U / 2], 'yaw': 0},
              {'id': 'i1', 'type': 'I2', 'position': [0.6, -0.3, U / 2], 'yaw': 0}]
    scene = small_scene(blocks=blocks, targets=ROW)
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    ids = [b.id for b in scene.blocks]
    first = solve(scene, replace(STABLE, prefer='fewer'))
    assert [p.type for p in first.placements] == ['I2']
    space = AllocationActions(env, first.placements)
    realloc = Reallocator(space, grasp_fails_for({ids.index('i0'), ids.index('i1')}, env))
    event = realloc.stalled(env, 'stuck')
    # Every I2 failed to be picked: the pose is not blamed, both blocks are left out of the re-solve.
    assert event.no_goods == []
    assert sorted(d['block'] for d in event.blocks) == ['i0', 'i1'] and 'finger' in event.blocks[0]['reason']
    assert event.changed and sorted(p.type for p in event.placements) == ['cube', 'cube']
    assert 'and 2 blocks that cannot be picked' in event.summary()
    assert event.to_dict()['blocks'][0]['type'] == 'I2'
    # The same pose again later: the excluded blocks are not tried again, and stay excluded.
    again = realloc.stalled(env, 'stuck')
    assert again.blocks == [] and {d['block'] for d in realloc.blocked.values()} == {'i0', 'i1'}
    # A block leaves the table (it may have been what blocked the others): the exclusion is lifted,
    # the next re-solve may use the I2s again, and they are checked again where a pose asks for them.
    env.step([a for a in space(env) if not a.is_terminate and a.block == ids.index('c0')][0])
    realloc.stalled(env, 'stuck')
    assert realloc.blocked == {}
    assert {'i0', 'i1'} <= {b.id for b in realloc._without_blocked(placed_scene(env)).blocks}


def test_a_pose_waiting_for_its_support_is_not_a_no_good():
    scene = small_scene()
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    space = AllocationActions(env, solve(scene, STABLE).placements)
    everything = set(range(env.grid.num_cells))
    realloc = Reallocator(space, failing_at(everything, env))
    event = realloc.stalled(env, 'stuck')
    for d in event.no_goods:
        assert min(c[2] for c in d['cells']) == 0    # only poses resting on the table now


def test_nothing_new_ends_the_episode_and_the_limit_holds():
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    space = AllocationActions(env, solve(scene, STABLE).placements)
    realloc = Reallocator(space, lambda a: Check(True), ReallocationConfig(max_reallocations=3))
    event = realloc.stalled(env, 'the policy prefers to stop')
    assert not event.changed and event.no_goods == []       # every pose works: nothing to exclude
    zero = Reallocator(space, lambda a: Check(False, 'x'), ReallocationConfig(max_reallocations=0))
    assert not zero.can_retry(env)
    with pytest.raises(RadError, match='max_reallocations'):
        ReallocationConfig(max_reallocations=-1).validate()


def test_no_time_left_skips_the_solve_with_a_reason():
    scene = generate_scene(GeneratorConfig(grid=3), 1)
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    space = AllocationActions(env, solve(scene, STABLE).placements)
    realloc = Reallocator(space, lambda a: Check(False, 'x'), deadline=0.0)
    assert not realloc.can_retry(env)
    event = realloc.stalled(env, 'stuck')
    assert event.status == 'SKIPPED' and 'no time left' in event.reason and not event.changed


def test_rad_eval_reallocate_agent_names_and_refuses_other_action_spaces():
    agent = get_agent('heur-verified', reallocate=True)
    assert agent.reallocate and agent.name == 'heur+verify+realloc' and agent.robot is True
    assert get_agent('milp-dqn-mixed-lookahead', verify=True, reallocate=True).name == \
        'milp-dqn-mixed+lookahead:5+verify+realloc'
    with pytest.raises(RadError, match='realloc applies'):
        get_agent('dqn', reallocate=True)


def test_with_the_robot_an_unreachable_block_is_excluded_and_another_type_fills_its_pose():
    # Real GAMP, real physics: the I2 lies out of the arm's reach, two cubes within it.
    blocks = [{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.25, U / 2], 'yaw': 0},
              {'id': 'c1', 'type': 'cube', 'position': [0.5, -0.25, U / 2], 'yaw': 0},
              {'id': 'i0', 'type': 'I2', 'position': [0.95, -0.6, U / 2], 'yaw': 0}]
    scene = small_scene(blocks=blocks, targets=ROW)
    first = AllocationParams(support='stable', prefer='fewer')
    plain = evaluate(get_agent('heur-verified'), [('row', scene)], robot=True, seed=0, allocation=first)
    assert plain['coverage'] == 0.0
    again = evaluate(get_agent('heur-verified', reallocate=True), [('row', scene)], robot=True, seed=0,
                     allocation=first)
    row = again['scenes'][0]
    assert again['coverage'] == 1.0 and again['f'] == 0.0
    assert len(row['reallocations']) == 1
    event = row['reallocations'][0]
    # The I2 cannot be picked where it lies: the block is excluded, not the pose it was asked for.
    assert event['no_goods'] == []
    [blocked] = event['blocks']
    assert blocked['block'] == 'i0' and blocked['type'] == 'I2' and 'unreachable' in blocked['reason']
    assert row['reallocation_s'] > 0


def test_a_used_up_allocation_with_free_target_cells_is_solved_again():
    blocks = [{'id': f'c{n}', 'type': 'cube', 'position': [0.4 + 0.1 * n, -0.2, U / 2], 'yaw': 0} for n in range(2)]
    scene = small_scene(blocks=blocks, targets=ROW)
    env = AssemblyEnv(scene, EnvConfig(stability='support'))
    only_one = [p for p in solve(scene, STABLE).placements if p.cells == ((0, 0, 0),)]
    space = AllocationActions(env, only_one)
    realloc = Reallocator(space, lambda a: Check(True))
    episode = run_episode(env, with_reallocation(policy_decider(HeurPolicy(), space), realloc),
                          np.random.default_rng(0))
    assert episode.coverage == 1.0
    assert [e.reason for e in realloc.events][0] == 'the allocation is built and target cells are still free'
    assert realloc.events[0].changed and realloc.events[0].step == 1


def test_the_coverage_bound_counts_what_the_blocks_left_could_cover():
    from rad_core.allocation.cpsat import coverage_bound
    three = [{'name': 'front', 'origin': [0.45, 0.1, U / 2], 'size': [3, 1, 1],
              'filled': [[0, 0, 0], [1, 0, 0], [2, 0, 0]]}]
    two_cubes = [{'id': f'c{n}', 'type': 'cube', 'position': [0.4 + 0.1 * n, -0.2, U / 2], 'yaw': 0}
                 for n in range(2)]
    assert coverage_bound(small_scene(blocks=two_cubes, targets=three)) == pytest.approx(2 / 3)
    placed = [dict(two_cubes[0], position=[0.45, 0.1, U / 2]), two_cubes[1]]   # one cube already in a cell
    assert coverage_bound(small_scene(blocks=placed, targets=three)) == pytest.approx(2 / 3)
    bar = two_cubes + [{'id': 'i0', 'type': 'I2', 'position': [0.7, -0.2, U / 2], 'yaw': 0}]
    assert coverage_bound(small_scene(blocks=bar, targets=three)) == 1.0

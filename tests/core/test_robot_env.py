"""The MDP with the robot in the loop: success and each failure class, for the right reason."""

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.env.mdp import TERMINATE, Action, Outcome
from rad_core.env.robot_env import AtRest, RobotAssemblyEnv, RobotEnvConfig, outcome_class
from rad_core.sequencing import supported_actions

U = 0.05
SEED = 5   # a generated scene whose supported allocation poses are all reachable
TYPES = {'cube': [[0, 0, 0]], 'I3': [[0, 0, 0], [1, 0, 0], [2, 0, 0]]}


def scene_of(blocks, size=(3, 1, 3), filled=((0, 0, 0),)):
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': U, 'block_types': TYPES,
        'blocks': [{'id': bid, 'type': t, 'position': list(p), 'yaw': 0} for bid, t, p in blocks],
        'targets': [{'name': 't', 'origin': [0.45, 0.15, U / 2], 'size': list(size),
                     'filled': [list(c) for c in filled]}]})


def action(env, block_id, unit, ijk, rotation=0):
    b = [blk.id for blk in env.scene.blocks].index(block_id)
    return Action(b, unit, env.grid.index(0, ijk), rotation)


@pytest.mark.parametrize('execution', ['simulate', 'teleport'])
def test_guided_episode_builds_what_the_mdp_books(execution):
    scene = generate_scene(GeneratorConfig(grid=4), SEED)
    with RobotAssemblyEnv(scene, RobotEnvConfig(execution=execution)) as renv:
        env = renv.env
        guide = AllocationGuide(scene, solve(scene).placements)
        placed = 0
        while not env.state.done:
            acts = supported_actions(env, guide.allowed_actions(env.state))
            r = renv.step(acts[0] if acts else TERMINATE)
            placed += r.outcome in (Outcome.PLACED, Outcome.COMPLETED, Outcome.NO_BLOCKS) and r.cells is not None
        assert placed >= 2
        # The twin's world, registered like motion capture would, matches the booked cells.
        now = renv.current_scene()
        for b, (cells, yaw) in env.state.placed.items():
            block = now.blocks[b]
            assert np.allclose(block.position, env.grid.centres[cells[0]], atol=1e-4)
            assert block.yaw == yaw


def test_buried_block_is_a_grasp_failure():
    c = (0.5, -0.2, U / 2)
    around = [(f'n{i}', 'cube', (c[0] + dx * U, c[1] + dy * U, U / 2))
              for i, (dx, dy) in enumerate(((1, 0), (-1, 0), (0, 1), (0, -1)))]
    with RobotAssemblyEnv(scene_of([('buried', 'cube', c)] + around)) as renv:
        r = renv.step(action(renv.env, 'buried', 0, (0, 0, 0)))
    assert r.outcome == Outcome.INVALID_GRASP and outcome_class(r.outcome) == 'f_g'
    assert r.reward == -1.0 and r.done and 'hits block n' in r.reason


def test_placement_the_hand_cannot_reach_between_towers_is_a_placement_failure():
    # Three-cube towers on both sides of the destination cell [1,0,0] (all in the region).
    towers = [(f't{x}{k}', 'cube', (0.45 + x * U, 0.15, U / 2 + k * U)) for x in (0, 2) for k in range(3)]
    with RobotAssemblyEnv(scene_of([('free', 'cube', (0.45, -0.2, U / 2))] + towers,
                                   filled=((1, 0, 0),))) as renv:
        assert len(renv.env.state.placed) == 6   # the towers sit on the grid: already placed
        r = renv.step(action(renv.env, 'free', 0, (1, 0, 0)))
    assert r.outcome == Outcome.INVALID_PLACEMENT and outcome_class(r.outcome) == 'f_p'
    assert 'at the placement' in r.reason


@pytest.mark.parametrize('execution', ['simulate', 'teleport'])
def test_unstable_overhang_is_executed_and_seen_to_fall(execution):
    # A one-cube column at [0,0,0]; an I3 laid on top reaching two cells past it.
    blocks = [('col', 'cube', (0.45, 0.15, U / 2)), ('bar', 'I3', (0.40, -0.25, U / 2))]
    with RobotAssemblyEnv(scene_of(blocks, filled=((0, 0, 0), (0, 0, 1), (1, 0, 1), (2, 0, 1))),
                          RobotEnvConfig(execution=execution)) as renv:
        r = renv.step(action(renv.env, 'bar', 0, (0, 0, 1)))
        assert renv.last_plan is not None and renv.last_plan.success   # it was executed
    assert r.outcome == Outcome.INVALID_UNSTABLE and outcome_class(r.outcome) == 'unstable'
    assert 'did not stay' in r.reason or 'did not stand' in r.reason


def test_block_resting_on_nothing_fails_without_planning_or_physics():
    with RobotAssemblyEnv(scene_of([('c', 'cube', (0.45, -0.2, U / 2))])) as renv:
        r = renv.step(action(renv.env, 'c', 0, (1, 0, 2)))
        assert renv.last_plan is None
    assert r.outcome == Outcome.INVALID_UNSTABLE and 'rest on nothing' in r.reason


def test_a_block_moved_by_the_motion_counts_as_a_placement_failure():
    blocks = [('c', 'cube', (0.45, -0.2, U / 2)), ('other', 'cube', (0.6, -0.3, U / 2))]
    with RobotAssemblyEnv(scene_of(blocks)) as renv:
        before = {b: renv.world.block_pose(b) for b in renv.world.blocks}
        renv.world.set_block_pose('c', renv.env.grid.centres[0], [0, 0, 0, 1])
        p, q = before['other']
        renv.world.set_block_pose('other', p + np.array([0.02, 0, 0]), q)   # as if the arm had pushed it
        outcome, reason = renv._judge(before, 'c', renv.env.grid.centres[0], 0)
    assert outcome == Outcome.INVALID_DISTURBED and outcome_class(outcome) == 'f_p'
    assert 'moved block other by 20.0 mm' in reason


def test_geometric_failures_are_booked_as_in_the_mdp():
    blocks = [(name, 'cube', (x, -0.2, U / 2)) for name, x in (('c', 0.45), ('d', 0.55), ('e', 0.65))]
    with RobotAssemblyEnv(scene_of(blocks), RobotEnvConfig(execution='teleport')) as renv:
        assert renv.step(action(renv.env, 'c', 0, (0, 0, 0))).outcome == Outcome.COMPLETED
    with RobotAssemblyEnv(scene_of(blocks, filled=((0, 0, 0), (1, 0, 0))),
                          RobotEnvConfig(execution='teleport')) as renv:
        assert renv.step(action(renv.env, 'c', 0, (0, 0, 0))).outcome == Outcome.PLACED
        r = renv.step(action(renv.env, 'd', 0, (0, 0, 0)))
        assert renv.last_plan is not None and renv.last_plan.success   # only the first was planned
    assert r.outcome == Outcome.INVALID_OVERLAP and r.reward == -1.0 and "overlaps placed block 'c'" in r.reason


# ---- for training: the world as a function of the MDP state, and the step cache -------------
MARKOV = RobotEnvConfig(execution='teleport', markov=True)


def test_markov_puts_the_arm_home_and_unplaced_blocks_back_so_gamp_sees_only_the_state():
    """Two orders of the same two placements leave the same world, so GAMP's plan of a
    third action is the same (a pure function of scene, placed blocks and action)."""
    from rad_core.cell import panda
    blocks = [(name, 'cube', (x, -0.2, U / 2)) for name, x in (('c', 0.45), ('d', 0.55), ('e', 0.65))]
    scene = scene_of(blocks, filled=((0, 0, 0), (1, 0, 0), (2, 0, 0)))
    plans = []
    with RobotAssemblyEnv(scene, MARKOV) as renv:
        for order in (('c', 'd'), ('d', 'c')):
            renv.reset()
            for name in order:
                cell = (0, 0, 0) if name == 'c' else (1, 0, 0)
                assert renv.step(action(renv.env, name, 0, cell)).outcome == Outcome.PLACED
            assert np.allclose(renv.world.joint_positions(), panda.HOME, atol=1e-9)
            p, q = renv.world.block_pose('e')
            assert np.allclose(p, (0.65, -0.2, U / 2), atol=1e-9)
            plans.append(renv.plan(action(renv.env, 'e', 0, (2, 0, 0))))
    a, b = plans
    assert a.success and b.success
    assert a.motion.to_dict() == b.motion.to_dict()


def test_the_step_cache_replays_the_verdicts_of_a_fresh_env():
    scene = generate_scene(GeneratorConfig(grid=4), SEED)
    placements = solve(scene).placements
    with RobotAssemblyEnv(scene, MARKOV) as fresh, \
            RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport', markov=True, cache=True)) as cached:
        guide = AllocationGuide(scene, placements)
        walks = []
        for _ in range(3):
            walk, k = [], 0
            fresh.reset()
            cached.reset()
            while not fresh.env.state.done:
                acts = guide.allowed_actions(fresh.env.state)
                # The first two episodes take the same path (the second replays it), the third its own.
                a = acts[(k * 7 + len(walks) // 2) % len(acts)] if acts else TERMINATE
                k += 1
                r1, r2 = fresh.step(a), cached.step(a)
                assert (r1.outcome, r1.reward, r1.reason) == (r2.outcome, r2.reward, r2.reason)
                assert cached.env.state.placed.keys() == fresh.env.state.placed.keys()
                walk.append(r1.outcome)
            walks.append(walk)
        assert cached.cache.hits >= len(walks[1]) - 1 and cached.cache.misses > 0
    with pytest.raises(Exception, match='needs markov'):
        RobotEnvConfig(execution='teleport', cache=True)


@pytest.mark.parametrize('overhang', [False, True])
def test_settling_ended_at_rest_judges_as_the_full_settling(overhang):
    # A bar on a one-cube column: centred on it, it stands; reaching two cells past it, it falls.
    col = 0 if overhang else 1
    blocks = [('col', 'cube', (0.45 + col * U, 0.15, U / 2)), ('bar', 'I3', (0.40, -0.25, U / 2))]
    filled = ((col, 0, 0), (0, 0, 1), (1, 0, 1), (2, 0, 1))
    verdicts, settled = [], []
    for at_rest in (None, AtRest()):
        config = RobotEnvConfig(execution='teleport', at_rest=at_rest)
        with RobotAssemblyEnv(scene_of(blocks, filled=filled), config) as renv:
            t0 = renv.twin.time
            r = renv.step(action(renv.env, 'bar', 0, (0, 0, 1)))
            verdicts.append((r.outcome, r.reason.split(':')[0]))
            settled.append(renv.twin.time - t0)
    assert verdicts[0] == verdicts[1]
    assert verdicts[0][0] == (Outcome.INVALID_UNSTABLE if overhang else Outcome.COMPLETED)
    assert settled[0] == pytest.approx(0.5) and settled[1] < 0.5


def test_at_rest_refuses_bad_settings():
    with pytest.raises(RadError, match='AtRest'):
        AtRest(every_s=0.0)
    with pytest.raises(RadError, match='AtRest'):
        AtRest(speed=-1.0)

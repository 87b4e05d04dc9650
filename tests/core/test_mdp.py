import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.env.mdp import TERMINATE, Action, AssemblyEnv, EnvConfig, Outcome
from rad_core.sequencing.decide.episode import Decision, run_episode

from scenes import U, doc, scene

GEOM = EnvConfig(stability='none')
SUPPORT = EnvConfig(stability='support')


def cell(env, ijk, region=0):
    return env.grid.index(region, ijk)


def test_action_space_size_is_nu_times_cells_times_four_plus_one():
    env = AssemblyEnv(scene(), GEOM)
    # 4 units (2 cubes + an I2) x 6 cells x 4 rotations + terminate.
    assert env.num_actions() == 4 * 6 * 4 + 1
    env.step(Action(0, 0, cell(env, (0, 0, 0)), 0))
    assert env.num_actions() == 3 * 5 * 4 + 1


def test_encode_decode_round_trip_over_the_whole_space():
    env = AssemblyEnv(scene(), GEOM)
    for k in range(env.num_actions()):
        assert env.encode(env.decode(k)) == k
    assert env.decode(env.num_actions() - 1) == TERMINATE
    with pytest.raises(RadError):
        env.decode(env.num_actions())


def test_reward_is_point_two_per_target_minus_non_target():
    env = AssemblyEnv(scene(), GEOM)
    # I2 (yaw 90 on the table) turned by 270 deg -> yaw 0, along +x, on [1,0,0],[2,0,0]: +0.4.
    r = env.step(Action(2, 0, cell(env, (1, 0, 0)), 3))
    assert r.outcome == Outcome.PLACED and r.reward == pytest.approx(0.4)
    assert sorted(env.grid.ijk[r.cells].tolist()) == [[1, 0, 0], [2, 0, 0]]
    # A cube on non-target [1,0,1]: -0.2.
    r = env.step(Action(0, 0, cell(env, (1, 0, 1)), 0))
    assert r.reward == pytest.approx(-0.2)


def test_completion_gives_the_bonus_and_ends():
    env = AssemblyEnv(scene(), GEOM)
    env.step(Action(2, 1, cell(env, (2, 0, 0)), 3))          # I2 by its second unit
    env.step(Action(0, 0, cell(env, (0, 0, 0)), 0))
    r = env.step(Action(1, 0, cell(env, (0, 0, 1)), 2))
    assert r.outcome == Outcome.COMPLETED and r.done
    assert r.reward == pytest.approx(0.2 + 1.0)
    assert env.coverage() == 1.0
    with pytest.raises(RadError, match='episode is over'):
        env.step(TERMINATE)


@pytest.mark.parametrize('action,outcome', [
    (Action(2, 0, 2, 3), Outcome.INVALID_OFF_GRID),    # I2 from the last column sticks out
])
def test_invalid_actions_end_with_minus_one(action, outcome):
    env = AssemblyEnv(scene(), GEOM)
    r = env.step(action)
    assert r.outcome == outcome and r.reward == -1.0 and r.done and r.reason


def test_overlap_and_moving_a_placed_block_are_invalid():
    env = AssemblyEnv(scene(), GEOM)
    env.step(Action(0, 0, cell(env, (0, 0, 0)), 0))
    clone = env.clone()
    r = env.step(Action(1, 0, cell(env, (0, 0, 0)), 0))
    assert r.outcome == Outcome.INVALID_OVERLAP and "'c0'" in r.reason
    r = clone.step(Action(0, 0, cell(clone, (1, 0, 0)), 0))
    assert r.outcome == Outcome.INVALID_BLOCK


def test_support_rule_rejects_floating_blocks():
    env = AssemblyEnv(scene(), SUPPORT)
    r = env.step(Action(0, 0, cell(env, (1, 0, 1)), 0))
    assert r.outcome == Outcome.INVALID_UNSTABLE
    env = AssemblyEnv(scene(), SUPPORT)
    env.step(Action(0, 0, cell(env, (0, 0, 0)), 0))
    assert env.step(Action(1, 0, cell(env, (0, 0, 1)), 0)).outcome == Outcome.PLACED


def test_terminate_and_running_out_of_blocks():
    env = AssemblyEnv(scene(), GEOM)
    r = env.step(TERMINATE)
    assert (r.outcome, r.reward, r.done) == (Outcome.TERMINATED, 0.0, True)
    s = scene(blocks=[{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0}])
    env = AssemblyEnv(s, GEOM)
    r = env.step(Action(0, 0, cell(env, (0, 0, 0)), 0))
    assert r.outcome == Outcome.NO_BLOCKS and r.reward == pytest.approx(0.2)


def test_malformed_actions_raise_not_penalise():
    env = AssemblyEnv(scene(), GEOM)
    for bad in (Action(9, 0, 0, 0), Action(0, 1, 0, 0), Action(0, 0, 99, 0), Action(0, 0, 0, 4)):
        with pytest.raises(RadError):
            env.step(bad)


def test_clone_and_reset_are_independent():
    env = AssemblyEnv(scene(), GEOM)
    other = env.clone()
    env.step(Action(0, 0, cell(env, (0, 0, 0)), 0))
    assert other.free_cells().size == 6 and env.free_cells().size == 5
    env.reset()
    assert env.free_cells().size == 6 and not env.state.placed


def test_pre_placed_blocks_start_in_s_p():
    d = doc()
    d['blocks'][0]['position'] = [0.45, 0.1, U / 2]
    env = AssemblyEnv(Scene.from_dict(d), GEOM)
    assert 0 in env.state.placed and env.remaining_target_cells() == 3
    assert (0, 0) not in env.unplaced_units()


def test_guide_offers_exactly_the_allocated_poses_and_drops_filled_ones():
    s = scene()
    alloc = solve(s)
    env = AssemblyEnv(s, GEOM)
    guide = AllocationGuide(s, alloc.placements)
    actions = guide.allowed_actions(env.state)
    pose_sets = {frozenset(env.grid.index(0, c) for c in p.cells) for p in alloc.placements}
    for a in actions:
        cells, _ = env.resulting_cells(a)
        assert frozenset(int(c) for c in cells) in pose_sets
    # Cubes are symmetric: each of 2 cubes x 4 rotations reaches a cube pose.
    cube_poses = sum(p.type == 'cube' for p in alloc.placements)
    assert sum(a.block in (0, 1) for a in actions) == 2 * 4 * cube_poses
    # After placing into a pose, no action fills that pose again.
    first = actions[0]
    cells, _ = env.resulting_cells(first)
    env.step(first)
    for a in guide.allowed_actions(env.state):
        c, _ = env.resulting_cells(a)
        assert set(c.tolist()).isdisjoint(cells.tolist())
        assert a.block != first.block


def test_guide_turns_each_block_from_its_own_yaw_into_the_pose():
    # Three L3_up blocks, two at yaw 0 and one at yaw 90, and one allocated L3_up pose along +x:
    # the blocks at yaw 0 fill it unturned, the one at yaw 90 after three quarter turns (the
    # guide works the actions out once per type and yaw; the yaws must not be mixed up).
    from rad_core.allocation.placements import Placement
    blocks = [{'id': f'l{k}', 'type': 'L3_up', 'position': [0.4 + 0.1 * k, -0.2, U / 2], 'yaw': yaw}
              for k, yaw in enumerate((0, 90, 0))]
    s = scene(blocks=blocks)
    env = AssemblyEnv(s, GEOM)
    pose = Placement('L3_up', 'front', 0, ((0, 0, 0), (1, 0, 0), (0, 0, 1)))
    actions = AllocationGuide(s, [pose]).allowed_actions(env.state)
    assert {(a.block, a.rotation) for a in actions} == {(0, 0), (1, 3), (2, 0)}
    for a in actions:
        cells, _ = env.resulting_cells(a)
        assert sorted(int(c) for c in cells) == sorted(cell(env, c) for c in pose.cells)
    assert [a for a in actions if a.block == 0] == [Action(0, u, cell(env, c), 0) for u, c in enumerate(pose.cells)]


def test_guided_episode_with_allocation_reaches_completion():
    s = scene()
    env = AssemblyEnv(s, SUPPORT)
    guide = AllocationGuide(s, solve(s).placements)

    def heur(e, rng):
        ok = [a for a in guide.allowed_actions(e.state) if e.evaluate(a)[0] is None]
        return Decision(ok[int(rng.integers(len(ok)))] if ok else TERMINATE)

    ep = run_episode(env, heur, np.random.default_rng(0))
    assert ep.outcome == Outcome.COMPLETED and ep.coverage == 1.0
    assert ep.ret == pytest.approx(0.2 * 4 + 1.0, abs=0.01)

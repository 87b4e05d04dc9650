"""gamp.ik: checked top-down IK over the workspace, and clear failures outside it."""

import math

import numpy as np
import pytest
from rad_core.cell import panda
from rad_core.gamp.ik import hand_yaw_options, solve_pose, solve_top_down
from rad_core.sim.world import World


@pytest.fixture(scope='module')
def world():
    with World() as w:
        yield w


def _closing_axis(world, q):
    """World direction the fingers close along (the hand's y axis) at joints q."""
    import pybullet as p
    with world.preserved():
        world.set_joint_positions(q)
        pos, orn = world.link_pose()
    rot = np.array(p.getMatrixFromQuaternion(orn.tolist())).reshape(3, 3)
    return pos, rot


def test_random_reachable_top_down_targets_are_solved_accurately_within_limits(world):
    rng = np.random.default_rng(7)
    errors, failures = [], []
    for _ in range(300):
        target = np.array([rng.uniform(0.3, 0.7), rng.uniform(-0.4, 0.4), rng.uniform(0.02, 0.35)])
        closing = rng.uniform(-math.pi, math.pi)
        r = solve_top_down(world, target, closing, rng=rng)
        if not r.ok:
            failures.append((target, r.reason))
            continue
        assert panda.within_limits(r.q)
        # Check independently of the solver: forward kinematics of the answer.
        pos, rot = _closing_axis(world, r.q)
        pos_err = np.linalg.norm(pos - target)
        down = math.degrees(math.acos(min(1.0, -rot[2, 2])))
        # Fingers close along the hand's y axis; the hand is symmetric, so +-y both do.
        axis_err = math.degrees(math.acos(min(1.0, abs(rot[0, 1] * math.cos(closing)
                                                       + rot[1, 1] * math.sin(closing)))))
        errors.append((pos_err, down, axis_err))
    e = np.array(errors)
    print(f'\nIK over 300 targets: {len(failures)} failures; position error mm median '
          f'{np.median(e[:, 0]) * 1000:.4f} p95 {np.percentile(e[:, 0], 95) * 1000:.4f} '
          f'max {e[:, 0].max() * 1000:.3f}; '
          f'tilt deg max {e[:, 1].max():.3f}; closing-axis deg max {e[:, 2].max():.3f}')
    assert len(failures) <= 3, failures
    assert e[:, 0].max() < 0.002
    assert e[:, 1].max() < 2.0 and e[:, 2].max() < 2.0
    assert np.percentile(e[:, 0], 95) < 0.0005


def test_ik_leaves_the_world_unchanged(world):
    before = world.joint_positions()
    solve_top_down(world, [0.5, 0.2, 0.1], 0.3)
    assert np.array_equal(world.joint_positions(), before)


@pytest.mark.parametrize('target, words', [
    ([2.0, 0.0, 0.1], 'from the shoulder'),
    ([0.5, 0.0, -0.3], 'below the table'),
    ([0.0, 0.95, 0.05], 'best residual'),
])
def test_unreachable_targets_fail_with_a_reason(world, target, words):
    r = solve_top_down(world, target, 0.0)
    assert not r.ok and r.q is None
    assert r.reason.startswith('unreachable') and words in r.reason, r.reason


def test_best_residual_names_millimetres(world):
    r = solve_pose(world, [0.0, 0.95, 0.05], panda.top_down_quaternion(0.0))
    assert not r.ok and 'mm' in r.reason and r.position_error > 0.01


def test_hand_yaw_options_are_the_two_symmetric_hand_yaws_best_wrist_first(world):
    a, b = hand_yaw_options([0.5, 0.0, 0.1], 0.4)
    assert abs(abs(a - b) - math.pi) < 1e-9
    for closing in np.linspace(-math.pi, math.pi, 13):
        r = solve_top_down(world, [0.45, -0.1, 0.05], closing)
        assert r.ok and abs(r.q[6]) < panda.UPPER[6]



def test_numpy_forward_kinematics_is_pybullets(world):
    """gamp.kinematics reads the chain off the loaded robot: the grasp target where pybullet puts it."""
    from rad_core.domain.transforms import matrix_from_quaternion
    from rad_core.gamp.kinematics import kinematics
    kin = kinematics(world)
    rng = np.random.default_rng(11)
    with world.preserved():
        for _ in range(100):
            q = rng.uniform(panda.LOWER, panda.UPPER)
            world.set_joint_positions(q, hold=False)
            pos, orn = world.link_pose()
            tip, _, _ = kin.forward(q)
            assert np.abs(tip[:3, 3] - pos).max() < 1e-6
            assert np.abs(tip[:3, :3] - matrix_from_quaternion(orn)).max() < 1e-5


def test_a_vertical_path_stays_on_its_branch(world):
    """Each waypoint seeded from the one below (4 cm) moves the joints a little, as a straight move should."""
    rng = np.random.default_rng(2)
    below = solve_top_down(world, [0.5, 0.1, 0.03], 0.4, rng=rng)
    assert below.ok
    q = below.q
    for k in range(1, 5):
        r = solve_top_down(world, [0.5, 0.1, 0.03 + 0.04 * k], 0.0, seeds=[q], rng=rng, hand_yaw=below.hand_yaw)
        assert r.ok and np.abs(r.q[:7] - q[:7]).max() < 0.2, (k, r.q - q)
        q = r.q

"""gamp.trajectory.retime against Franka's limits, checked independently of rad_core.cell.trajectory.

The motion a joint_trajectory_controller makes of retime's points (quintic Hermite
through each point's position, velocity and acceleration, from rest at the start)
is rebuilt here from its definition, sampled at Franka's 1 kHz and compared with
the robot models' velocity, acceleration and jerk limits x speed_scale; each
segment between two waypoints must stay on the straight joint-space line GAMP
checked for collisions. `limit_violation` must flag the same path run faster.
"""

import re

import numpy as np
import pytest
from rad_core.cell.robot_model import FR3, PANDA, PLANNING_LOWER, PLANNING_UPPER
from rad_core.cell.trajectory import Trajectory, TrajectoryPoint, limit_ratios, limit_violation
from rad_core.gamp.trajectory import retime

DT = 1e-3                       # Franka's control period
MOVES = 20
ROUNDING = 1e-6                 # relative: what is left of a limit after floating point


def random_moves(seed: int, count: int = MOVES) -> list[list[np.ndarray]]:
    """count paths of 2 to 4 (7,) configurations, uniform within the planning limits."""
    rng = np.random.default_rng(seed)
    return [[rng.uniform(PLANNING_LOWER, PLANNING_UPPER) for _ in range(rng.integers(2, 5))] for _ in range(count)]


# ---- the controller's interpolation, from its definition ------------------------

def _quintic(p0, v0, a0, p1, v1, a1, h):
    """(6, k) coefficients in s = (t - t0) / h of the quintic with these end states."""
    s_rows = np.array([[1, 0, 0, 0, 0, 0],         # p(0)
                       [0, 1, 0, 0, 0, 0],         # p'(0)
                       [0, 0, 2, 0, 0, 0],         # p''(0)
                       [1, 1, 1, 1, 1, 1],         # p(1)
                       [0, 1, 2, 3, 4, 5],         # p'(1)
                       [0, 0, 2, 6, 12, 20]], dtype=float)
    rhs = np.vstack([p0, v0 * h, a0 * h * h, p1, v1 * h, a1 * h * h])
    return np.linalg.solve(s_rows, rhs)


def sample(traj: Trajectory, start, dt: float = DT):
    """Times and (n, 7) position, velocity, acceleration and jerk of the motion at 1 kHz."""
    times = np.array([p.time_from_start for p in traj.points])
    pos = np.array([p.positions for p in traj.points])
    vel = np.array([p.velocities for p in traj.points])
    acc = np.array([p.accelerations for p in traj.points])
    assert vel.shape == acc.shape == pos.shape, 'retime gives velocities and accelerations at every point'
    if times[0] > 0:                                  # from where the arm is, at rest
        times = np.concatenate([[0.0], times])
        pos = np.vstack([start, pos])
        vel = np.vstack([np.zeros(7), vel])
        acc = np.vstack([np.zeros(7), acc])
    ts = np.arange(0.0, times[-1] + dt / 2, dt)
    out = [np.zeros((len(ts), 7)) for _ in range(4)]
    powers = np.arange(6)
    for k in range(len(times) - 1):
        h = times[k + 1] - times[k]
        inside = (ts >= times[k]) & ((ts < times[k + 1]) if k < len(times) - 2 else (ts <= times[k + 1]))
        c = _quintic(pos[k], vel[k], acc[k], pos[k + 1], vel[k + 1], acc[k + 1], h)
        s = np.clip((ts[inside] - times[k]) / h, 0.0, 1.0)[:, None]
        for d in range(4):                              # d-th derivative in t
            coef = np.array([np.prod(np.arange(n - d + 1, n + 1)) if n >= d else 0.0 for n in powers])
            basis = np.where(powers >= d, s ** np.maximum(powers - d, 0), 0.0) * coef
            out[d][inside] = basis @ c / h ** d
    return ts, out


def scaled(traj: Trajectory, k: float) -> Trajectory:
    """The same path with every time multiplied by k (k < 1: faster)."""
    return Trajectory(traj.joint_names, [
        TrajectoryPoint(p.positions, [v / k for v in p.velocities], p.time_from_start * k,
                        [a / k / k for a in p.accelerations]) for p in traj.points])


def test_the_sampler_reproduces_a_known_quintic():
    # Rest to rest over 2 s, 1 rad: the minimum-jerk polynomial 10s^3 - 15s^4 + 6s^5.
    traj = Trajectory(tuple(PANDA.arm_joint_names), [TrajectoryPoint([1.0] * 7, [0.0] * 7, 2.0, [0.0] * 7)])
    ts, (q, v, a, j) = sample(traj, np.zeros(7))
    s = ts / 2.0
    assert np.allclose(q[:, 0], 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5, atol=1e-12)
    assert np.allclose(v[:, 0], (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / 2, atol=1e-12)
    assert np.allclose(a[:, 0], (60 * s - 180 * s ** 2 + 120 * s ** 3) / 4, atol=1e-12)
    assert np.allclose(j[:, 0], (60 - 360 * s + 360 * s ** 2) / 8, atol=1e-12)


# ---- retime's output -------------------------------------------------------------------

@pytest.mark.parametrize('speed', [0.5, 1.0])
@pytest.mark.parametrize('model', [PANDA, FR3], ids=['panda', 'fr3'])
def test_retimed_moves_stay_within_the_limits_at_1khz(model, speed):
    v_max, a_max, j_max = model.limits(speed)
    worst = {'velocity': 0.0, 'acceleration': 0.0, 'jerk': 0.0}
    for path in random_moves(seed=11):
        traj = retime(path, model, speed)
        _, (q, v, a, j) = sample(traj, path[0])
        jerk_1khz = np.diff(a, axis=0) / DT             # as the robot's loop sees it
        # Velocity against the bound where the joint is: the FR3's shrinks near the ends of its range.
        lower, upper = model.velocity_bounds(q)
        bound = np.minimum(np.where(v >= 0, upper, -lower), v_max)
        ratios = {'velocity': np.where(np.abs(v) < 1e-9, 0.0, np.abs(v) / np.maximum(bound, 1e-12)).max(),
                  'acceleration': (np.abs(a) / a_max).max(), 'jerk': (np.abs(j) / j_max).max()}
        assert max(ratios.values()) <= 1 + ROUNDING, ratios
        assert (np.abs(jerk_1khz) / j_max).max() <= 1 + ROUNDING
        for key in worst:
            worst[key] = max(worst[key], float(ratios[key]))
        # The twin's own measure of the same motion agrees with this one.
        theirs = limit_ratios(traj, path[0], model)
        full = np.where(v >= 0, upper, -lower)
        assert theirs['velocity'] == pytest.approx(
            np.where(np.abs(v) < 1e-9, 0.0, np.abs(v) / np.maximum(full, 1e-12)).max(), rel=2e-3)
        assert theirs['acceleration'] == pytest.approx((np.abs(a) / model.limits()[1]).max(), rel=1e-6)
        assert theirs['jerk'] == pytest.approx((np.abs(jerk_1khz) / model.limits()[2]).max(), rel=1e-6)
        assert limit_violation(traj, path[0], model) == ''
    # Time-optimal: every quantity reaches its limit somewhere (not a timid timing).
    assert min(worst.values()) > 0.99, worst


@pytest.mark.parametrize('model', [PANDA, FR3], ids=['panda', 'fr3'])
def test_each_retimed_segment_lies_on_the_line_between_its_waypoints(model):
    for path in random_moves(seed=12):
        traj = retime(path, model, 0.5)
        ts, (q, v, a, _) = sample(traj, path[0])
        # Where each waypoint is reached: a point exactly there, at rest.
        ends = [0.0]
        for w in path[1:]:
            at = [p.time_from_start for p in traj.points
                  if np.allclose(p.positions, w, rtol=0, atol=1e-12) and p.time_from_start > ends[-1]]
            assert at, 'every waypoint is a point of the trajectory'
            point = next(p for p in traj.points if p.time_from_start == at[0])
            assert np.abs(point.velocities).max() == 0 and np.abs(point.accelerations).max() == 0
            ends.append(at[0])
        assert ends[-1] == traj.points[-1].time_from_start
        for k, (a_, b_) in enumerate(zip(path[:-1], path[1:])):
            inside = (ts >= ends[k]) & (ts <= ends[k + 1])
            d = b_ - a_
            s = (q[inside] - a_) @ d / (d @ d)
            off_line = np.abs(q[inside] - a_ - s[:, None] * d).max()
            assert off_line < 1e-9, f'segment {k} leaves its line by {off_line:.2e} rad'
            assert s.min() > -1e-9 and s.max() < 1 + 1e-9
            assert np.diff(s).min() > -1e-12                 # forward only: no overshoot and back
            # The velocity points along the line too.
            assert np.abs(v[inside] - (v[inside] @ d / (d @ d))[:, None] * d).max() < 1e-9


@pytest.mark.parametrize('model', [PANDA, FR3], ids=['panda', 'fr3'])
def test_retimed_points_start_after_zero_increase_and_end_at_rest(model):
    for path in random_moves(seed=13):
        traj = retime(path, model, 1.0)
        times = traj.times()
        assert times[0] > 0                                   # the first point is not where the arm is
        assert np.diff(times).min() > 0
        assert traj.joint_names == model.arm_joint_names
        last = traj.points[-1]
        assert last.positions == pytest.approx(list(path[-1]), abs=1e-12)
        assert np.abs(last.velocities).max() == 0 and np.abs(last.accelerations).max() == 0
        assert all(len(p.positions) == len(p.velocities) == len(p.accelerations) == 7 for p in traj.points)


@pytest.mark.parametrize('model', [PANDA, FR3], ids=['panda', 'fr3'])
def test_limit_violation_flags_the_same_path_run_twice_as_fast(model):
    v_max, a_max, j_max = model.limits()
    for path in random_moves(seed=14, count=10):
        traj = retime(path, model, 0.5)
        assert limit_violation(traj, path[0], model) == ''
        fast = scaled(traj, 0.5)                               # v x2, a x4, jerk x8: at most the velocity fits
        _, (_, v, a, j) = sample(fast, path[0])
        mine = max((np.abs(a) / a_max).max(), (np.abs(j) / j_max).max())
        assert mine > 1.9
        why = limit_violation(fast, path[0], model)
        # The FR3's velocity limit shrinks near the ends of a range: doubled, a velocity may break it first.
        kinds = '(velocity|acceleration|jerk)' if model.braking is not None else '(acceleration|jerk)'
        match = re.fullmatch(rf'{model.prefix}_joint[1-7]: {kinds} [\d.]+ exceeds the {model.name} '
                             r'limit [\d.]+ \((\d+\.\d+)x.*\) at t = [\d.]+ s', why)
        assert match, why
        assert float(match.group(2)) > (1.0 if match.group(1) == 'velocity' else 1.9)


def test_retime_refuses_what_it_cannot_time():
    from rad_core.domain.errors import RadError
    with pytest.raises(RadError, match='start and at least one waypoint'):
        retime([np.zeros(7)], PANDA, 0.5)
    with pytest.raises(RadError, match='does not move'):
        retime([np.zeros(7), np.zeros(7)], PANDA, 0.5)
    with pytest.raises(RadError, match='speed_scale'):
        retime([np.zeros(7), np.ones(7) * 0.1], PANDA, 1.5)


@pytest.mark.parametrize('grid, seed', [(3, 2), (4, 1003)])
def test_planned_scenes_stay_within_both_robots_limits_at_1khz(grid, seed):
    """Whole plans as GAMP times them by default (limits='both'): every arm trajectory, each from where
    the previous one ended, within the Panda's and the FR3's velocity, acceleration and jerk limits
    as this test's own 1 kHz sampler sees them; and within the FR3's when timed for the FR3 alone."""
    from rad_core.allocation import solve
    from rad_core.cell.motion import Motion
    from rad_core.cell.panda import HOME
    from rad_core.cell.robot_model import robot_model
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.gamp.action import MotionPlanner
    from rad_core.gamp.planner import GampConfig
    from rad_core.gamp.trajectory import TimingConfig
    from rad_core.sequencing import HeurPolicy
    from rad_core.sequencing.planning.plan import local_motion_planner, plan_assembly
    scene = generate_scene(GeneratorConfig(grid=grid), seed)
    for timing, models in ((TimingConfig(), (PANDA, robot_model('fr3', 'panda'))),
                           (TimingConfig(robot='fr3', limits='robot', speed_scale=1.0), (FR3,))):
        planner = MotionPlanner(GampConfig(timing=timing))
        try:
            plan = plan_assembly(scene, solve, local_motion_planner(planner), HeurPolicy(), seed=1)
        finally:
            planner.close()
        assert len(plan.steps) >= 2, plan.reason
        q, count = HOME[:7], 0
        for step in plan.steps:
            for traj in Motion.from_dict(step.motion).trajectories:
                assert list(traj.joint_names) == list(models[0].arm_joint_names)
                for model in models:
                    v_max, a_max, j_max = model.limits()
                    _, (_, v, a, j) = sample(traj, q)
                    assert (np.abs(v) / v_max).max() <= 1 + ROUNDING
                    assert (np.abs(a) / a_max).max() <= 1 + ROUNDING
                    assert (np.abs(j) / j_max).max() <= 1 + ROUNDING
                    assert limit_violation(traj, q, model) == ''
                q = np.asarray(traj.points[-1].positions)
                count += 1
        assert count == 3 * len(plan.steps)

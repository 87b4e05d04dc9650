"""Inverse kinematics of the Panda's grasp target for top-down hand poses.

pybullet's calculateInverseKinematics is damped least squares: with null-space
terms (joint limits, rest pose) it lands millimetres off because the rest-pose
pull fights the target; without them it needs a hundred iterations a call and
up to six calls to come within 0.2 mm. So each attempt, from a seed
(measured, see docs/results/planning_step.md):

1. where the seed (a caller's, or HOME turned towards the target; not a
   random one) already puts the target within `near_seed_m` / `near_seed_deg`
   of the pose (the waypoint below on a vertical path), Newton steps from it,
   which keep its branch; where their answer passes step 3 it is the answer;
2. otherwise one null-space call of `solver_iterations` from the seed, with
   limits and a rest pose whose joint 1 points at the target and whose joint 7
   is the one the requested hand yaw needs (this picks the arm's elbow-up,
   wrist-centred branch), then up to `newton_steps` Newton steps on the exact
   Jacobian (`gamp.kinematics`: the Panda's forward kinematics in numpy, read
   off the loaded robot), which reach 1e-6 m in two or three;
3. the answer is accepted only when the residual (position and orientation)
   is within tolerance and every joint is within the URDF limits.

Why Newton finishes: pybullet's calls alone of a hundred iterations each cost
three times as much a solve for the same accuracy; the answers of the two differ
by milliradians (Newton keeps the branch of the waypoint below on a vertical
path), and every planning step `benchmarks/bench_planning_step.py --compare`
replays decides the same (docs/results/planning_step.md).

Attempts are seeded in turn from the caller's seeds (e.g. the previous
waypoint, so a path stays on one branch), from HOME turned towards the target,
and from random configurations within the limits drawn from the caller's
generator. Every call puts the robot's joints back (``world.joints_kept()``):
the world is unchanged.

The Panda hand is symmetric under a 180 deg turn about its axis, so a grasp
with closing direction phi can be taken with hand yaw phi + 90 or phi + 270 deg;
`solve_top_down` tries first the one that keeps joint 7 near the middle of its
range (+-166 deg), and the other if that fails.
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from rad_core.cell import panda
from rad_core.domain.transforms import matrix_from_quaternion
from rad_core.gamp.kinematics import kinematics, newton
from rad_core.sim.world import World

SHOULDER = np.array([0.0, 0.0, 0.333])

# World -> {inputs of solve_pose, generator state -> (IkResult, generator state after)}.
_IK_MEMO: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_IK_MEMO_MAX = 20_000


@dataclass(frozen=True)
class IkConfig:
    """Tolerances and effort of one IK solve."""

    position_tol: float = 0.002
    """Accepted FK position residual of the grasp target (m)."""
    orientation_tol_deg: float = 2.0
    """Accepted FK orientation residual (deg, angle of the relative rotation)."""
    solver_iterations: int = 20
    """maxNumIterations of the null-space pybullet call that picks an attempt's branch; Newton
    steps finish it."""
    newton_steps: int = 8
    """Newton steps after the null-space call, per attempt (two or three reach 1e-6 m)."""
    near_seed_m: float = 0.05
    near_seed_deg: float = 5.0
    """A seed (not a random one) that already puts the grasp target this near the pose (the waypoint
    below on a vertical path, 4 cm) is finished by Newton steps alone, on its own branch; where that
    answer leaves the limits or the tolerance, the attempt goes on as from any other seed."""
    random_seeds: int = 4
    """Random restarts after the caller's seeds and HOME."""
    min_height: float = 0.005
    """Targets lower than this (m above the table top) are refused at once: the
    fingertips reach 11 mm below the grasp target, so lower means into the table."""
    max_reach: float = 1.0
    """Targets farther than this from the shoulder (joint 2, 0.333 m above the base)
    are refused at once (the arm spans 0.86 m shoulder to flange, 1.07 m to the grasp
    target; a top-down hand reaches about 0.8 m out)."""


@dataclass
class IkResult:
    """A joint solution (9,) with the fingers as seeded, or why there is none."""

    ok: bool
    q: np.ndarray | None
    position_error: float           # m, of the best attempt (accepted or not)
    orientation_error_deg: float
    reason: str = ''
    calls: int = 0
    seconds: float = 0.0
    hand_yaw: float = 0.0            # rad, the hand yaw that was solved for


def predicted_joint7(position, hand_yaw: float) -> float:
    """Joint 7 (rad, wrapped to +-pi) of a top-down pose, from the base yaw to the target."""
    j1 = math.atan2(position[1], position[0])
    return _wrap(j1 + panda.HAND_YAW_AT_HOME_OFFSET - hand_yaw)


def hand_yaw_options(position, closing_yaw: float) -> list[float]:
    """The two hand yaws that close the fingers along closing_yaw, best wrist first."""
    base = panda.closing_yaw_to_hand_yaw(closing_yaw)
    options = [_wrap(base), _wrap(base + math.pi)]
    return sorted(options, key=lambda y: abs(predicted_joint7(position, y)))


def solve_pose(world: World, position, quaternion, seeds: Sequence[np.ndarray] = (),
               config: IkConfig = IkConfig(), rng: np.random.Generator | None = None,
               rest_joint7: float | None = None) -> IkResult:
    """Joint positions putting the grasp target at (position, quaternion), or a failure.

    seeds: (9,) or (7,) configurations tried first, in order. The fingers of the
    answer are those of the first seed (HOME's when there is none).
    """
    start = time.perf_counter()
    position = np.asarray(position, dtype=float)
    quaternion = np.asarray(quaternion, dtype=float)
    rng = rng if rng is not None else np.random.default_rng(0)
    fingers = panda.HOME[7:]
    if len(seeds):
        s0 = np.asarray(seeds[0], dtype=float)
        fingers = s0[7:9] if len(s0) == 9 else fingers
    rest = panda.HOME.copy()
    rest[0] = math.atan2(position[1], position[0])
    if rest_joint7 is not None:
        rest[6] = rest_joint7
    rest[7:] = fingers
    candidates = [_full(s, fingers) for s in seeds] + [rest]
    # The answer is a function of the robot model and these inputs (calculateInverseKinematics reads
    # only the joints it is seeded with; no block enters), and of the generator's state where the
    # random restarts are reached: remembered per world with the state it leaves the generator in.
    memo = _IK_MEMO.setdefault(world, {})
    if len(memo) >= _IK_MEMO_MAX:
        memo.clear()
    key = (position.tobytes(), quaternion.tobytes(), np.stack(candidates).tobytes(), config,
           repr(rng.bit_generator.state))
    found = memo.get(key)
    if found is not None:
        result, rng_after = found
        rng.bit_generator.state = rng_after
        return replace(result, q=None if result.q is None else result.q.copy(), calls=0,
                       seconds=time.perf_counter() - start)
    result = _solve_pose(world, position, quaternion, candidates, fingers, rest, config, rng)
    result.seconds = time.perf_counter() - start
    memo[key] = (replace(result, q=None if result.q is None else result.q.copy()), rng.bit_generator.state)
    return result


def _solve_pose(world: World, position: np.ndarray, quaternion: np.ndarray, candidates: list[np.ndarray],
                fingers: np.ndarray, rest: np.ndarray, config: IkConfig, rng: np.random.Generator) -> IkResult:
    """The attempts of `solve_pose` (seconds left 0 for the caller to fill in)."""
    p, cid, robot = world.pybullet, world.client, world.robot
    lo, hi = panda.LOWER, panda.UPPER
    limits = dict(lowerLimits=lo.tolist(), upperLimits=hi.tolist(), jointRanges=(hi - lo).tolist(),
                  restPoses=rest.tolist())
    kin = kinematics(world)
    rotation = matrix_from_quaternion(quaternion)
    near = (config.near_seed_m, config.near_seed_deg)
    best = (math.inf, math.inf, None)
    calls = 0
    n_attempts = len(candidates) + config.random_seeds
    with world.joints_kept():
        for attempt in range(n_attempts):
            seed = candidates[attempt] if attempt < len(candidates) else _random_q(rng, fingers)
            found = None
            if attempt < len(candidates):
                # A seed near the pose already (the waypoint below, on a vertical path): Newton from it,
                # the branch it is on; where that fails the checks, as from any other seed.
                found = newton(kin, position, rotation, seed, config.newton_steps, start_within=near)
                if found is not None and not (panda.within_limits(found[0]) and found[1] <= config.position_tol
                                              and found[2] <= config.orientation_tol_deg):
                    found = None
            if found is None:
                world.set_joint_positions(seed, hold=False)
                q = np.array(p.calculateInverseKinematics(
                    robot, world.ee_link, position.tolist(), quaternion.tolist(),
                    maxNumIterations=config.solver_iterations, residualThreshold=1e-6,
                    physicsClientId=cid, **limits))
                calls += 1
                found = newton(kin, position, rotation, q, config.newton_steps)
            q, pos_err, orn_err = found
            q[7:] = fingers
            within = panda.within_limits(q)
            if within and pos_err <= config.position_tol and orn_err <= config.orientation_tol_deg:
                return IkResult(True, q, pos_err, orn_err, '', calls)
            score = pos_err + 0.001 * orn_err + (0.0 if within else 1.0)
            if score < best[0] + 0.001 * best[1] + (0.0 if best[2] is None or best[2] else 1.0):
                best = (pos_err, orn_err, within)
    pos_err, orn_err, within = best
    if within is False:
        reason = (f'unreachable: every solution leaves the joint limits (best residual '
                  f'{pos_err * 1000:.0f} mm, {orn_err:.1f} deg)')
    else:
        reason = f'unreachable: best residual {pos_err * 1000:.0f} mm, {orn_err:.1f} deg'
    return IkResult(False, None, pos_err, orn_err, reason, calls)


def solve_top_down(world: World, position, closing_yaw: float, seeds: Sequence[np.ndarray] = (),
                   config: IkConfig = IkConfig(), rng: np.random.Generator | None = None,
                   hand_yaw: float | None = None) -> IkResult:
    """IK for the hand pointing straight down with its fingers closing along closing_yaw (rad).

    Both hand yaws of the symmetric hand are tried, the one with joint 7 nearer
    the middle first, unless hand_yaw (rad) fixes one (e.g. a placement must keep
    the hand yaw the grasp implied).
    """
    position = np.asarray(position, dtype=float)
    refused = out_of_workspace(position, config)
    if refused:
        return IkResult(False, None, math.inf, math.inf, refused)
    options = [hand_yaw] if hand_yaw is not None else hand_yaw_options(position, closing_yaw)
    first, total_calls, total_s = None, 0, 0.0
    for yaw in options:
        result = solve_pose(world, position, panda.top_down_quaternion(yaw), seeds, config, rng,
                            rest_joint7=predicted_joint7(position, yaw))
        total_calls += result.calls
        total_s += result.seconds
        result.hand_yaw = yaw
        if result.ok:
            result.calls, result.seconds = total_calls, total_s
            return result
        if first is None or result.position_error < first.position_error:
            first = result
    first.calls, first.seconds = total_calls, total_s
    return first


def out_of_workspace(position: np.ndarray, config: IkConfig = IkConfig()) -> str:
    """Why a grasp-target position cannot be reached whatever the joints, or ''."""
    if not np.all(np.isfinite(position)):
        return 'unreachable: target position is not finite'
    if position[2] < config.min_height:
        return f'unreachable: target z = {position[2]:.3f} m is below the table top'
    reach = float(np.linalg.norm(position - SHOULDER))
    if reach > config.max_reach:
        return f'unreachable: target is {reach:.2f} m from the shoulder (reach < {config.max_reach:.2f} m)'
    return ''


def _full(q, fingers) -> np.ndarray:
    """A (7,) or (9,) seed as (9,) with the given fingers."""
    return np.concatenate([np.asarray(q, dtype=float)[:7], fingers])


def _random_q(rng: np.random.Generator, fingers) -> np.ndarray:
    q = rng.uniform(panda.LOWER, panda.UPPER)
    q[7:] = fingers
    return q


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi

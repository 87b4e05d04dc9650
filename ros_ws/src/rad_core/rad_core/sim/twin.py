"""The twin's execution core: a World driven like the real cell's controllers.

`Twin` is the plant the rad_sim node wraps. It accepts joint trajectories the
way a ros2_control joint_trajectory_controller does (joint names in any order,
a subset allowed, points at ``time_from_start``; a new trajectory replaces the
running one; joints not named hold their last command) and steps physics with
position control, so the arm moves with the Panda's torque limits and blocks
react to it.

Two ways to drive it, both on the same state:
- ``start(trajectory)`` then ``advance(seconds)`` in slices: a node calls
  advance from its timer with wall time x a real-time factor, publishing joint
  states and motion capture between slices, so ROS callbacks interleave.
- ``execute(trajectory, callback=..., real_time_factor=...)``: runs to the end
  in one call (tests, benchmarks, the MDP), optionally paced to wall time.

A trajectory is a `rad_core.trajectory.Trajectory` (as GAMP plans it) or its
dict form (as rad_ros.motion converts a JointTrajectory message). Each is
validated in full (`parse_trajectory`) before anything moves; a bad one raises
RadError and leaves the world as it was.

Grasping is a contact-checked attachment, as in the predecessor. When the
gripper is commanded to close (the finger targets fall below the open width and
below where the fingers are) and both finger links touch the same block, that
block is fixed to the hand with a JOINT_FIXED constraint at its current relative
pose; when the fingers are commanded open past the width they held it at, the
constraint is removed. The fingers still close physically (20 N each) and the
block still collides with everything, so a grasp of a block that is not between
the fingers, or a carried block that hits something, behaves as it would. Why
not pure friction: friction grasps in Bullet slip and rotate slowly under
transport (and differently from run to run as contact sets change), which
would make a placement's outcome depend on solver noise rather than on the
plan; the attachment makes transport stable and reproducible.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from rad_core.errors import RadError
from rad_core.scene import Scene
from rad_core.sim import panda
from rad_core.sim.mocap import RegistrationConfig, RigidBodyPose, register_scene
from rad_core.sim.panda import JOINT_NAMES
from rad_core.sim.world import World
from rad_core.trajectory import Trajectory, parse_trajectory

@dataclass(frozen=True)
class TwinConfig:
    """Controller and gripper settings (SI units; fingers in metres per finger)."""

    arm_forces: tuple[float, ...] = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
    """Motor torque limits (N m) of joints 1-7: the Panda's rated maxima."""
    finger_force: float = 20.0
    """Force of each finger motor (N); a Panda hand squeezes with up to 70 N continuous."""
    position_gain: float = 0.3
    """Bullet position-control gain kp (fraction of the position error removed per step)."""
    velocity_gain: float = 1.0
    """Bullet position-control gain kd on the velocity error (the trajectory feeds velocity forward)."""
    limit_tol: float = 1e-3
    """Positions this far (rad or m) beyond a joint limit are still accepted (rounding in planners)."""
    goal_time: float = 0.5
    """After the last point, hold at most this long (s) for the arm to reach it."""
    goal_tol: float = 1e-3
    """The arm counts as arrived when every named arm joint is this close (rad) to the last point."""
    close_margin: float = 5e-4
    """Closing = finger target this far (m) below both the open width and the finger position."""
    release_margin: float = 2e-3
    """Opening = finger target this far (m) above the width the block was grasped at."""
    attach_max_force: float = 500.0
    """Strength (N) of the attachment constraint; far above any load a block puts on it."""

    def __post_init__(self):
        values = list(self.arm_forces) + [self.finger_force, self.position_gain, self.velocity_gain,
                                          self.limit_tol, self.goal_time, self.goal_tol, self.close_margin,
                                          self.release_margin, self.attach_max_force]
        if len(self.arm_forces) != 7 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0
                                                 for v in values):
            raise RadError('twin config: expected 7 arm forces and finite, non-negative settings')


@dataclass
class ExecutionReport:
    """How a trajectory went. Errors are max |actual - commanded| over the named arm joints (rad)."""

    joint_names: tuple[str, ...]
    final_positions: np.ndarray           # (9,) JOINT_NAMES order, when it finished
    final_error: float                    # against the last point, after the goal hold
    max_tracking_error: float             # against the interpolated command, while it ran
    grasp_events: list[dict] = field(default_factory=list)   # {'t', 'action': attach|detach, 'block'}
    duration: float = 0.0                 # the trajectory's own length (s)
    sim_time: float = 0.0                 # simulated, including the goal hold (s)
    wall_time: float = 0.0                # from start to finish (s)
    compute_time: float = 0.0             # of which stepping and control (s)
    steps: int = 0
    preempted: bool = False

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second achieved (pacing and callbacks included)."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else math.inf

    @property
    def compute_factor(self) -> float:
        """Simulated seconds per second of stepping: how fast it could run unpaced."""
        return self.sim_time / self.compute_time if self.compute_time > 0 else math.inf

    def as_dict(self) -> dict:
        return {'joint_names': list(self.joint_names), 'final_positions': [float(v) for v in self.final_positions],
                'final_error': self.final_error, 'max_tracking_error': self.max_tracking_error,
                'grasp_events': list(self.grasp_events), 'duration': self.duration, 'sim_time': self.sim_time,
                'wall_time': self.wall_time, 'real_time_factor': self.real_time_factor,
                'compute_factor': self.compute_factor, 'steps': self.steps, 'preempted': self.preempted}


class _Run:
    """One trajectory being executed: its interpolant and its running figures."""

    def __init__(self, traj: Trajectory, start_q: np.ndarray):
        """traj: validated (`parse_trajectory`)."""
        self.joints = np.array([JOINT_NAMES.index(n) for n in traj.joint_names])
        k = len(self.joints)
        times, pos = traj.times(), traj.positions()
        vel = np.array([pt.velocities for pt in traj.points]) if traj.points[0].velocities else None
        if times[0] > 0:               # the controller starts from where the joints are
            times = np.concatenate([[0.0], times])
            pos = np.vstack([start_q[self.joints], pos])
            vel = None if vel is None else np.vstack([np.zeros(k), vel])
        self.times, self.pos, self.vel = times, pos, vel
        self.t = 0.0
        self.max_error = 0.0
        self.arm = self.joints < 7
        self.report = ExecutionReport(traj.joint_names, start_q, math.nan, 0.0, duration=traj.duration)
        self.wall_start = time.perf_counter()

    def command(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded positions and velocities of the named joints at time t."""
        times = self.times
        if t >= times[-1] or len(times) == 1:
            return self.pos[-1], np.zeros(len(self.joints))
        i = max(int(np.searchsorted(times, t, side='right')) - 1, 0)
        h = times[i + 1] - times[i]
        s = (t - times[i]) / h
        p0, p1 = self.pos[i], self.pos[i + 1]
        if self.vel is None:
            return p0 + s * (p1 - p0), (p1 - p0) / h
        m0, m1 = self.vel[i] * h, self.vel[i + 1] * h      # cubic Hermite on [0, 1]
        s2, s3 = s * s, s * s * s
        q = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1
        dq = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0 + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * m1) / h
        return q, dq


class Twin:
    """A World with joint-trajectory control and contact-checked grasping.

    Not thread-safe; the node calls it from one thread. If the World is moved
    behind the twin's back (``world.set_joint_positions``, ``world.load_scene``),
    call `sync` (or use `load_scene` here) so the held command matches it.
    """

    def __init__(self, world: World, config: TwinConfig = TwinConfig()):
        import pybullet as p  # here, not at module top: importing it prints a banner
        self._p = p
        self.world = world
        self.config = config
        self.dt = float(world.config.physics.time_step)
        self._forces = [*config.arm_forces, config.finger_force, config.finger_force]
        self._target = world.joint_positions()
        self._target_vel = np.zeros(9)
        self._run: _Run | None = None
        self._carry = 0.0             # simulated time owed to advance() (less than one step)
        self.time = 0.0               # simulated seconds since the twin was made
        self.attached: tuple[str, int] | None = None   # (block id, constraint id)
        self._grip_width = 0.0
        self._events: list[dict] = []
        self._apply()

    # ---- state -----------------------------------------------------------
    def sync(self) -> None:
        """Hold the joints where they are now and forget a grasp whose block is gone."""
        self._target = self.world.joint_positions()
        self._target_vel = np.zeros(9)
        if self.attached is not None and self.attached[0] not in self.world.blocks:
            self.attached = None
        self._apply()

    def load_scene(self, scene: Scene) -> None:
        """Replace the blocks (robot back at HOME); a running trajectory is dropped."""
        self._release()
        self._run = None
        self.world.load_scene(scene)
        self.sync()

    @property
    def busy(self) -> bool:
        return self._run is not None

    def joint_state(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        return JOINT_NAMES, self.world.joint_positions(), self.world.joint_velocities()

    def block_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {bid: self.world.block_pose(bid) for bid in self.world.blocks}

    def bodies(self, names: dict[str, str] | None = None) -> list[RigidBodyPose]:
        """Every block as a motion-capture rigid body (name = block id unless renamed)."""
        names = names or {}
        return [RigidBodyPose(names.get(bid, bid), tuple(float(v) for v in pos), tuple(float(v) for v in q))
                for bid, (pos, q) in self.block_poses().items()]

    def current_scene(self, template: Scene | None = None, config: RegistrationConfig | None = None) -> Scene:
        """The blocks where they are now, snapped as motion-capture registration snaps them.

        Raises RadError when a block is somewhere a scene cannot express (carried,
        tilted, fallen over), exactly as registering real poses would.
        """
        template = template or self.world.scene
        if template is None:
            raise RadError('no scene loaded')
        if config is None:
            types = {b.id: b.type for b in self.world.scene.blocks}
            config = RegistrationConfig(body_map={bid: (bid, types[bid]) for bid in self.world.blocks})
        return register_scene(self.bodies(), template, config)

    # ---- commands ----------------------------------------------------------
    def start(self, trajectory: Trajectory | dict) -> dict:
        """Validate and begin a trajectory, replacing any running one; returns a summary.

        Raises RadError (nothing changes) when the trajectory is invalid.
        """
        traj = parse_trajectory(trajectory, self.config.limit_tol)
        if self._run is not None:
            self._finish(preempted=True)
        self._run = _Run(traj, self._target.copy())
        self._events = []
        return {'joints': list(traj.joint_names), 'points': len(traj.points), 'duration': traj.duration}

    def cancel(self) -> ExecutionReport | None:
        """Stop the running trajectory and hold where the joints are."""
        if self._run is None:
            return None
        report = self._finish(preempted=True)
        q = self.world.joint_positions()
        self._target[:7] = q[:7]
        self._target_vel[:] = 0.0
        self._apply()
        return report

    def advance(self, seconds: float) -> dict | None:
        """Simulate `seconds` more (whole steps; the remainder carries over).

        Returns the finished trajectory's report as a dict when one completes
        within this slice, else None. Without a trajectory the robot holds.
        """
        if not (math.isfinite(seconds) and seconds >= 0):
            raise RadError(f'advance: seconds must be finite and >= 0, got {seconds!r}')
        self._carry += seconds
        n = int(self._carry / self.dt + 1e-9)
        self._carry -= n * self.dt
        report = self._steps(n)
        return None if report is None else report.as_dict()

    def settle(self, seconds: float) -> None:
        """Let physics run for `seconds`: the robot holds its command (a running trajectory goes on)."""
        self.advance(seconds)

    def execute(self, trajectory: Trajectory | dict, callback=None, callback_period: float = 0.02,
                real_time_factor: float | None = None) -> ExecutionReport:
        """Run a trajectory to its end (goal hold included) and report.

        callback(twin) is called every `callback_period` simulated seconds (to
        publish state); real_time_factor paces the run to that many simulated
        seconds per wall second (1.0 = real time, None = as fast as possible).
        """
        self.start(trajectory)
        slice_steps = max(1, round(callback_period / self.dt))
        wall0, sim0 = time.perf_counter(), self.time
        while True:
            report = self._steps(slice_steps)
            if callback is not None:
                callback(self)
            if real_time_factor:
                ahead = (self.time - sim0) / real_time_factor - (time.perf_counter() - wall0)
                if ahead > 0:
                    time.sleep(ahead)
            if report is not None:
                report.wall_time = time.perf_counter() - wall0
                return report

    # ---- stepping ------------------------------------------------------------
    def _apply(self) -> None:
        p, w = self._p, self.world
        p.setJointMotorControlArray(w.robot, w.joints, p.POSITION_CONTROL, targetPositions=self._target.tolist(),
                                    targetVelocities=self._target_vel.tolist(), forces=self._forces,
                                    positionGains=[self.config.position_gain] * 9,
                                    velocityGains=[self.config.velocity_gain] * 9, physicsClientId=w.client)

    def _steps(self, n: int) -> ExecutionReport | None:
        finished = None
        t0 = time.perf_counter()
        for _ in range(n):
            run = self._run
            if run is not None:
                q_cmd, dq_cmd = run.command(run.t + self.dt)
                self._target[run.joints] = q_cmd
                self._target_vel[:] = 0.0
                self._target_vel[run.joints] = dq_cmd
            self._apply()
            self.world.step()
            self.time += self.dt
            self._grasp_update()
            if run is not None:
                run.t += self.dt
                if self._progress(run):
                    run.report.compute_time += time.perf_counter() - t0
                    finished = self._finish(preempted=False)
                    t0 = time.perf_counter()
        if self._run is not None:
            self._run.report.compute_time += time.perf_counter() - t0
        return finished

    def _progress(self, run: _Run) -> bool:
        """Track the error; True once the trajectory is over and the arm has arrived."""
        q = self.world.joint_positions()[run.joints]
        arm = run.arm
        if not arm.any():
            err = 0.0
        else:
            q_cmd, _ = run.command(run.t)
            err = float(np.abs(q - q_cmd)[arm].max())
        duration = run.times[-1]
        if run.t < duration - 1e-9:
            run.max_error = max(run.max_error, err)
            return False
        run.report.final_error = err
        fingers_still = np.all(np.abs(self.world.joint_velocities()[7:]) < 1e-3)
        return (err <= self.config.goal_tol and fingers_still) or run.t >= duration + self.config.goal_time - 1e-9

    def _finish(self, preempted: bool) -> ExecutionReport:
        run, self._run = self._run, None
        r = run.report
        r.final_positions = self.world.joint_positions()
        if math.isnan(r.final_error):
            q_cmd = run.pos[-1]
            q = r.final_positions[run.joints]
            r.final_error = float(np.abs(q - q_cmd)[run.arm].max()) if run.arm.any() else 0.0
        r.max_tracking_error = run.max_error
        r.grasp_events = list(self._events)
        r.sim_time = run.t
        r.steps = round(run.t / self.dt)
        r.wall_time = time.perf_counter() - run.wall_start
        r.preempted = preempted
        # Hold exactly the last command (zero velocity), as the controller does at the end.
        self._target_vel[:] = 0.0
        self._apply()
        return r

    # ---- grasping --------------------------------------------------------------
    def _grasp_update(self) -> None:
        cfg, w = self.config, self.world
        target = float(self._target[7:].mean())
        if self.attached is not None:
            if target > self._grip_width + cfg.release_margin:
                self._release()
            return
        fingers = w.joint_positions()[7:]
        closing = target < panda.FINGER_OPEN - cfg.close_margin and target < float(fingers.mean()) - cfg.close_margin
        if not closing:
            return
        touched = [self._touching(link) for link in w.finger_links]
        common = sorted(touched[0] & touched[1])
        if common:
            self._attach(common[0], float(fingers.mean()))

    def _touching(self, link: int) -> set[str]:
        p, w = self._p, self.world
        by_body = {body: bid for bid, body in w.blocks.items()}
        contacts = p.getContactPoints(bodyA=w.robot, linkIndexA=link, physicsClientId=w.client)
        return {by_body[c[2]] for c in contacts if c[2] in by_body and c[8] < 1e-3}

    def _attach(self, block_id: str, width: float) -> None:
        p, w = self._p, self.world
        body = w.blocks[block_id]
        hand = p.getLinkState(w.robot, w.hand_link, computeForwardKinematics=True, physicsClientId=w.client)
        block = p.getBasePositionAndOrientation(body, physicsClientId=w.client)
        inv_pos, inv_orn = p.invertTransform(hand[0], hand[1])
        rel_pos, rel_orn = p.multiplyTransforms(inv_pos, inv_orn, block[0], block[1])
        c = p.createConstraint(w.robot, w.hand_link, body, -1, p.JOINT_FIXED, [0, 0, 0],
                               parentFramePosition=rel_pos, childFramePosition=[0, 0, 0],
                               parentFrameOrientation=rel_orn, childFrameOrientation=[0, 0, 0, 1],
                               physicsClientId=w.client)
        p.changeConstraint(c, maxForce=self.config.attach_max_force, physicsClientId=w.client)
        self.attached = (block_id, c)
        self._grip_width = width
        self._events.append({'t': round(self._run_time(), 6), 'action': 'attach', 'block': block_id})

    def _release(self) -> None:
        if self.attached is None:
            return
        block_id, c = self.attached
        self.attached = None
        if c in self._constraint_ids():   # gone already when its block was removed with a scene
            self._p.removeConstraint(c, physicsClientId=self.world.client)
        self._events.append({'t': round(self._run_time(), 6), 'action': 'detach', 'block': block_id})

    def _constraint_ids(self) -> set[int]:
        p, cid = self._p, self.world.client
        count = p.getNumConstraints(physicsClientId=cid)
        return {p.getConstraintUniqueId(i, physicsClientId=cid) for i in range(count)}

    def _run_time(self) -> float:
        return self._run.t + self.dt if self._run is not None else self.time

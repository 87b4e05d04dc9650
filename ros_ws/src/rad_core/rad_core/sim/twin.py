"""The twin's execution core: a World driven like a real Franka cell's controllers.

`Twin` is the plant the rad_sim node wraps, as strict as the real robot. The arm
takes trajectories the way a franka_ros2 joint_trajectory_controller does: the
robot model's 7 arm joints only (any order; finger joints are refused, they
belong to the gripper), checked before anything moves (`parse_trajectory`), and
the interpolated motion from where the arm is, sampled at 1 kHz, within the
model's velocity, acceleration and jerk limits (`limit_violation`): a trajectory
a real Franka would stop on is refused with the controller's error code
(`TrajectoryRejected`). It is followed by the controller's interpolation
(`rad_core.cell.trajectory.Spline`: quintic with accelerations), with path and goal
tolerances; the report carries the FollowJointTrajectory error code. A new
trajectory replaces the running one; `cancel` stops the arm where it is.

The hand takes GripperCommand goals as franka_gripper's gripper_action does:
`position` per finger (m), opening is a move at the gripper's speed, closing is a
grasp with `max_effort` (N) that succeeds when the fingers stop within
`grasp_epsilon` (of the width) of the commanded width; the result reports where
the fingers stopped.

Two ways to drive it, both on the same state:
- ``start(trajectory)`` / ``grip(position, effort)`` then ``advance(seconds)`` in
  slices: a node calls advance from its timer with wall time x a real-time factor,
  publishing joint states and motion capture between slices.
- ``execute(trajectory)``, ``execute_gripper(command)``, ``execute_motion(motion)``:
  run to the end in one call (tests, benchmarks, the MDP), optionally paced.

Grasping is a contact-checked attachment, as in the predecessor. When the
fingers are closing and both finger links touch the same block, that block is
fixed to the hand with a JOINT_FIXED constraint at its current relative pose;
when the fingers open past the width they held it at, the constraint is removed.
The fingers still close physically (with the grasp's force) and the block still
collides with everything, so a grasp of a block that is not between the fingers,
or a carried block that hits something, behaves as it would. Why not pure
friction: friction grasps in Bullet slip and rotate slowly under transport (and
differently from run to run as contact sets change), which would make a
placement's outcome depend on solver noise rather than on the plan; the
attachment makes transport stable and reproducible.

The faults of a real cell (`rad_core.sim.faults.FaultConfig`, off by default),
each drawn from its own seeded stream and recorded as an event (in `fault_events`
for the twin's life, and in the running trajectory's report with the grasp events):
- motion capture: `bodies` adds Gaussian noise to each reported position (per
  axis) and yaw, and drops bodies (tracking_valid false, the last reported pose,
  as a tracker does); `current_scene` / `registration` register what motion
  capture reports, waiting a few frames for a dropped body and else holding it at
  its last pose (a body missing for a frame is "not seen", not "removed"). Dropped frames are the node's business
  (`drop_frame` says whether to skip one);
- placement error: a released block is shifted in x/y by the error once the
  fingers are clear of it, no farther than its neighbours allow (blocks do not
  interpenetrate), and settles physically;
- slip: the attachment is let go at a random moment of the carry (the next arm
  trajectory after the grasp) and the fingers stop touching the block, so it falls;
- miss: at the moment of grasping the fingers pass through the block, so the
  hand closes on nothing (no attachment; the gripper reports the closed width);
- nudge: when a block is released, a block touching or next to it is pushed
  away from it by `nudge_distance` (as far as its own neighbours allow);
- unpressed: a studded brick the arm pressed home is let go without joining it to the
  studs under it; like every brick resting on studs unjoined, `bodies` reports it a
  stud's height above where it rests (the twin's bricks have no studs);
- knock: when a brick is released, a joined brick of the structure lets go of its studs
  and is pushed sideways at `knock_speed`.
A block the fingers pass through (slip, miss) collides with them again once it is
clear of them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from rad_core.cell import panda
from rad_core.cell.mocap import Registration, RegistrationConfig, RigidBodyPose, register_scene, register_world
from rad_core.cell.motion import VACUUM_ACTIONS, GripperCommand, GripperFailed, GripperResult, Motion, run_motion
from rad_core.cell.robot_model import RobotModel, robot_model
from rad_core.cell.trajectory import (
    GOAL_TOLERANCE_VIOLATED,
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    Spline,
    Trajectory,
    TrajectoryAborted,
    TrajectoryRejected,
    limit_violation,
    parse_trajectory,
)
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion
from rad_core.sim.faults import KINDS, FaultConfig
from rad_core.sim.physics import BLOCK_PLAY
from rad_core.sim.world import World, WorldConfig

SEAL_GAP = 0.007
"""The cup seals on a top face its lip is at most this far (m) above (its bellows close the gap), or 2 mm
pressed into."""
SEAL_TILT_DEG = 3.0
"""A face tilted more than this (deg) leaks: no seal."""
VACUUM_BUILD_UP_S = 0.05
"""Simulated seconds a vacuum takes to reach its level on a sealed face."""

# BLOCK_PLAY (`sim.physics`): the play real blocks have between their neighbours. With the planning
# worlds' 0.1 mm hairline a block lowered into a pocket between neighbours jammed on an edge at the
# twin's own tracking error (its joints lag the command by one 4 ms physics step, up to 7.6 mrad), so
# with the whole arm motion simulated, packed targets lost blocks a real cell (chamfered, slightly
# compliant blocks, a 0.1 mm repeatable arm) would place: measured on the held-out cube3, 0.26
# coverage with 0.1 mm and 0.81 (as teleporting) with 0.5 mm.


AVERAGE_FRAMES = 10
"""Motion-capture frames a registration averages body positions over when the tracker is noisy
(`Twin.registration`): the blocks are at rest, so 10 frames (a tenth of a second at 100 Hz) cut the
noise of a measured offset by sqrt(10)."""


def twin_world_config(base: WorldConfig = WorldConfig(), play: float = BLOCK_PLAY) -> WorldConfig:
    """The world a twin simulates: `base` with `play` per side face (see BLOCK_PLAY)."""
    return replace(base, physics=replace(base.physics, side_gap=play))


@dataclass(frozen=True)
class Tolerances:
    """A FollowJointTrajectory goal's tolerances (one value for every arm joint; 0 = the twin's default)."""

    path: float = 0.0
    """Largest |actual - desired| (rad) of any arm joint while the trajectory runs."""
    goal: float = 0.0
    """Largest |actual - last point| (rad) at the end."""
    goal_time: float = 0.0
    """How long (s) after the last point's time the arm may take to come within `goal`."""


@dataclass(frozen=True)
class TwinConfig:
    """Controller and gripper settings (SI units; fingers in metres per finger)."""

    robot: str = 'panda'
    """Robot model whose joint names and limits the twin enforces ('panda' | 'fr3'); the simulated
    arm is the Panda URDF (the FR3 shares its kinematics)."""
    joint_prefix: str = ''
    """Joint names `<prefix>_joint1..7` ('' = the model's)."""

    arm_forces: tuple[float, ...] = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
    """Motor torque limits (N m) of joints 1-7: the Panda's rated maxima."""
    finger_force: float = 20.0
    """Force of each finger motor (N) when moving (not grasping)."""
    gripper_speed: float = 0.05
    """Finger speed (m/s per finger; franka_gripper's default 0.1 m/s of width)."""
    grasp_epsilon: float = 0.005
    """A grasp succeeds when the width stops this close (m) to the commanded width (franka_gripper's default)."""
    position_gain: float = 0.3
    """Bullet position-control gain kp (fraction of the position error removed per step)."""
    velocity_gain: float = 1.0
    """Bullet position-control gain kd on the velocity error (the trajectory feeds velocity forward)."""
    limit_tol: float = 1e-3
    """Positions this far (rad or m) beyond a joint limit are still accepted (rounding in planners)."""
    goal_time: float = 0.5
    """After the last point, hold at most this long (s) for the arm to reach it (unless a goal says)."""
    goal_tol: float = 1e-3
    """The arm counts as arrived when every arm joint is this close (rad) to the last point (unless a goal
    says); only a goal tolerance given with the trajectory is enforced (GOAL_TOLERANCE_VIOLATED)."""
    path_tol: float = 0.0
    """Largest tracking error (rad) while moving before the run aborts (0: not enforced, unless a goal says)."""
    close_margin: float = 5e-4
    """Closing = finger target this far (m) below both the open width and the finger position."""
    release_margin: float = 2e-3
    """Opening = finger target this far (m) above the width the block was grasped at."""
    attach_max_force: float = 500.0
    """Strength (N) of the attachment constraint; far above any load a block puts on it."""
    press_travel: float = 5e-4
    """A studded brick is pressed home when the hand holding it goes on down this far (m) after the brick
    touched what is under it (the studs' engagement: a real arm's stiffness turns it into force): let go
    then, it is joined to the bricks under it (`sim.clutch`); set down and let go, it only rests."""
    faults: FaultConfig = field(default_factory=FaultConfig)
    """The faults of a real cell to inject (none by default)."""

    def __post_init__(self):
        if not isinstance(self.faults, FaultConfig):
            raise RadError(f'twin config: faults must be a FaultConfig, got {type(self.faults).__name__}')
        robot_model(self.robot, self.joint_prefix)
        values = list(self.arm_forces) + [self.finger_force, self.position_gain, self.velocity_gain,
                                          self.limit_tol, self.goal_time, self.goal_tol, self.close_margin,
                                          self.release_margin, self.attach_max_force, self.gripper_speed,
                                          self.grasp_epsilon, self.path_tol, self.press_travel]
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
    # and the faults injected while it ran: {'t', 'action': 'fault', 'fault': slip|miss|placement|nudge, ...}
    duration: float = 0.0                 # the trajectory's own length (s)
    sim_time: float = 0.0                 # simulated, including the goal hold (s)
    wall_time: float = 0.0                # from start to finish (s)
    compute_time: float = 0.0             # of which stepping and control (s)
    steps: int = 0
    preempted: bool = False
    error_code: int = SUCCESSFUL          # control_msgs/FollowJointTrajectory result code
    error_string: str = ''

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
                'compute_factor': self.compute_factor, 'steps': self.steps, 'preempted': self.preempted,
                'error_code': self.error_code, 'error_string': self.error_string}


class _Run:
    """One arm trajectory being executed: the controller's interpolant and the running figures."""

    def __init__(self, traj: Trajectory, start_q: np.ndarray, tolerances: Tolerances, config: TwinConfig):
        """traj: parsed (`parse_trajectory`), in the model's joint order."""
        self.spline = Spline(traj, start_q[:7])
        self.path_tol = tolerances.path or config.path_tol
        self.goal_tol = tolerances.goal or config.goal_tol
        self.goal_enforced = tolerances.goal > 0      # as in joint_trajectory_controller: 0 = not enforced
        self.goal_time = tolerances.goal_time or config.goal_time
        self.t = 0.0
        self.max_error = 0.0
        self.abort_at = math.inf       # an injected arm_abort: the controller stops the run at this time
        self.report = ExecutionReport(traj.joint_names, start_q, math.nan, 0.0, duration=traj.duration)
        self.wall_start = time.perf_counter()

    def command(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded arm positions and velocities at time t."""
        q, dq, _ = self.spline(t)
        return q, dq


class _Grip:
    """One gripper command being executed: a move to `goal`, or (closing) a grasp that squeezes
    with the force until the fingers stop, judged against `goal` (franka_gripper's grasp)."""

    def __init__(self, position: float, max_effort: float, start: float, closing: bool):
        self.goal, self.effort, self.closing = position, max_effort, closing
        self.drive = 0.0 if closing else position     # a grasp closes until something stops the fingers
        self.target = start            # the finger command, moving to `drive` at the gripper's speed
        self.t = 0.0
        self.still = 0.0               # s the fingers have not moved


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
        self.model: RobotModel = robot_model(config.robot, config.joint_prefix)
        self._forces = [*config.arm_forces, config.finger_force, config.finger_force]
        self._target = world.joint_positions()
        self._target_vel = np.zeros(9)
        self._run: _Run | None = None
        self._grip: _Grip | None = None
        self.gripper_result: GripperResult | None = None   # of the last gripper command that finished
        self._carry = 0.0             # simulated time owed to advance() (less than one step)
        self.time = 0.0               # simulated seconds since the twin was made
        self.attached: tuple[str, int] | None = None   # (block id, constraint id)
        self._grip_width = 0.0
        self._events: list[dict] = []
        faults = config.faults
        self._rng = {kind: np.random.default_rng([faults.seed, i]) for i, kind in enumerate(KINDS)}
        self.fault_events: list[dict] = []     # every fault injected since the twin was made
        self.fault_counts: dict[str, int] = dict.fromkeys(KINDS, 0)
        self._reported: dict[str, RigidBodyPose] = {}   # body name -> the pose motion capture last reported
        self._slip: float | None = None        # fraction of the next carry at which the held block slips
        self._slip_at: float | None = None     # simulated time at which it does
        self._ghosts: dict[int, str] = {}      # block bodies the fingers pass through (slip, miss) until clear
        self._miss_next = False                # the grasp under way will miss
        self._released: tuple[str, float] | None = None   # block just let go, width it was held at
        self._pressed: str | None = None        # the held brick, once pressed home onto studs
        self._touched_at: dict[str, float] = {}  # held brick -> the hand's height when it first touched below
        self._apply()

    # ---- state -----------------------------------------------------------
    def sync(self) -> None:
        """Hold the joints where they are now and forget a grasp whose block is gone."""
        self._target = self.world.joint_positions()
        self._target_vel = np.zeros(9)
        self._grip = None
        self._forces[7:] = [self.config.finger_force] * 2
        if self.attached is not None and self.attached[0] not in self.world.blocks:
            self.attached = None
        self._apply()

    def present(self, block_id: str) -> bool:
        """The scene's feeder presents a block at its station (`World.present`); whether it moved one.
        RadError for an unknown block, one not in the feeder (or taken from it already) or one the hand holds."""
        scene = self.world.scene
        if scene is None or scene.feeder is None:
            raise RadError('this scene has no feeder')
        if block_id not in self.world.blocks:
            raise RadError(f'unknown block id {block_id!r}')
        if self.attached is not None and self.attached[0] == block_id:
            raise RadError(f'block {block_id} is in the hand')
        if block_id not in self.world.parked and not self.world.at_station(block_id):
            raise RadError(f'block {block_id} is not in the feeder (left in it: '
                           f'{", ".join(sorted(self.world.parked)) or "none"})')
        return self.world.present(block_id)

    def load_scene(self, scene: Scene) -> None:
        """Replace the blocks (robot back at HOME); a running trajectory is dropped."""
        self._release()
        self._run = self._grip = None
        self._ghosts.clear()
        self._reported.clear()
        self._released = self._slip = self._slip_at = None
        self._miss_next = False
        self.world.load_scene(scene)
        self.sync()

    @property
    def busy(self) -> bool:
        return self._run is not None or self._grip is not None

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The model's 7 arm and 2 finger joints, in world order; the arm's only with the vacuum gripper
        (it has no joints: a cell with one publishes none for it)."""
        if self.world.effector == 'suction':
            return self.model.arm_joint_names
        return self.model.arm_joint_names + self.model.finger_joint_names

    def joint_state(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        n = len(self.joint_names)
        return self.joint_names, self.world.joint_positions()[:n], self.world.joint_velocities()[:n]

    def block_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {bid: self.world.block_pose(bid) for bid in self.world.blocks}

    def bodies(self, names: dict[str, str] | None = None, exact: bool = False) -> list[RigidBodyPose]:
        """Every block as a motion-capture rigid body (name = block id unless renamed), as the
        tracker reports it: with the configured noise, and a dropped body as tracking_valid false at
        its last reported pose. exact=True: the true poses, no faults."""
        names = names or {}
        f = self.config.faults
        out = []
        studs = self.world.studs if self.world.scene is not None and self.world.scene.studs is not None else None
        held = self.attached[0] if self.attached is not None else None
        for bid, (pos, q) in self.block_poses().items():
            if bid in self.world.parked:
                continue        # inside the feeder: no camera sees it
            if studs is not None and bid != held and studs.unpressed(self.world, bid):
                # The twin's bricks have no studs: one not pressed home rests at its seat in the physics,
                # where a real one stands on the studs under it, a stud's height higher.
                pos = pos + (0.0, 0.0, self.world.scene.stud_height)
            name = names.get(bid, bid)
            if not exact and self._happens('drop_body') \
                    and name in self._reported:
                last = self._reported[name]
                out.append(replace(last, tracking_valid=False))
                self.fault_counts['drop_body'] += 1
                continue
            if not exact and (f.mocap_position_noise > 0 or f.mocap_yaw_noise_deg > 0):
                rng = self._rng['noise']
                pos = pos + rng.normal(0.0, f.mocap_position_noise, 3)
                turn = yaw_quaternion(float(rng.normal(0.0, f.mocap_yaw_noise_deg)))
                q = np.array(self._p.multiplyTransforms([0, 0, 0], turn, [0, 0, 0], q.tolist())[1])
                self.fault_counts['noise'] += 1
            body = RigidBodyPose(name, tuple(float(v) for v in pos), tuple(float(v) for v in q))
            if not exact:
                self._reported[name] = body
            out.append(body)
        return out

    def drop_frame(self) -> bool:
        """Whether motion capture skips this frame (draw once per frame; counted when it does)."""
        dropped = self._happens('drop_frame')
        self.fault_counts['drop_frame'] += dropped
        return dropped

    def registration_config(self, template: Scene) -> RegistrationConfig:
        """Registration of every block by its id, with tolerances that follow the motion-capture noise."""
        types = {b.id: b.type for b in self.world.scene.blocks}
        f = self.config.faults
        return RegistrationConfig.for_noise(f.mocap_position_noise / math.sqrt(self._frames()), f.mocap_yaw_noise_deg,
                                            template.unit,
                                            body_map={bid: (bid, types[bid]) for bid in self.world.blocks})

    def _frames(self) -> int:
        """How many motion-capture frames a registration averages positions over: AVERAGE_FRAMES with
        position noise (blocks at rest: the mean of n frames has 1/sqrt(n) of the noise), else 1."""
        return AVERAGE_FRAMES if self.config.faults.mocap_position_noise > 0 else 1

    def _seen(self, frames: int = 10) -> list[RigidBodyPose]:
        """What registration gets: each body's latest tracked pose over up to `frames` motion-capture frames
        (stopping at the first frame by which every body was tracked), as a registration that waits out a
        dropped body does; a body dropped in all of them is held at its last reported pose (not seen for a
        moment is not gone). With position noise, at least `_frames()` frames, and each body's position
        is the mean of its tracked ones (the blocks are at rest)."""
        latest: dict[str, RigidBodyPose] = {}
        sums: dict[str, list] = {}
        average = self._frames()
        for k in range(max(frames, average)):
            now = self.bodies()
            latest.update({b.name: b for b in now if b.tracking_valid})
            for b in now:
                if b.tracking_valid:
                    total = sums.setdefault(b.name, [np.zeros(3), 0])
                    total[0] += b.position
                    total[1] += 1
            if len(latest) == len(now) and k + 1 >= average:
                break
        out = []
        for b in now:
            seen = latest.get(b.name)
            if seen is None:
                out.append(replace(b, tracking_valid=True))
                continue
            total, n = sums[b.name]
            out.append(replace(seen, position=tuple(float(v) for v in total / n)) if n > 1 else seen)
        return out

    def current_scene(self, template: Scene | None = None, config: RegistrationConfig | None = None) -> Scene:
        """The blocks where motion capture sees them now, snapped as registration snaps them.

        Raises RadError when a block is somewhere a scene cannot express (carried,
        tilted, fallen over), exactly as registering real poses would.
        """
        template = template or self.world.scene
        if template is None:
            raise RadError('no scene loaded')
        return register_scene(self._seen(), template, config or self.registration_config(template))

    def registration(self, template: Scene | None = None, config: RegistrationConfig | None = None) -> Registration:
        """As `current_scene`, but blocks a scene cannot express are set aside with the reason
        (`rad_core.cell.mocap.register_world`)."""
        template = template or self.world.scene
        if template is None:
            raise RadError('no scene loaded')
        return register_world(self._seen(), template, config or self.registration_config(template))

    # ---- commands ----------------------------------------------------------
    def start(self, trajectory: Trajectory | dict, tolerances: Tolerances = Tolerances()) -> dict:
        """Check and begin an arm trajectory, replacing any running one; returns a summary.

        Raises `TrajectoryRejected` (nothing changes) when the controller would
        refuse it: joint names (INVALID_JOINTS), or points, positions, or the
        interpolated motion from where the arm is over the model's limits (INVALID_GOAL).
        """
        traj = parse_trajectory(trajectory, self.model, self.config.limit_tol)
        if not all(math.isfinite(x) and x >= 0 for x in (tolerances.path, tolerances.goal, tolerances.goal_time)):
            raise TrajectoryRejected(INVALID_GOAL, 'tolerances must be finite and >= 0')
        start_q = self._target[:7].copy()
        why = limit_violation(traj, start_q, self.model)
        if why:
            raise TrajectoryRejected(INVALID_GOAL, f'over the {self.model.name}\'s limits: {why}')
        if self._happens('arm_reject'):
            self._fault('arm_reject')
            raise TrajectoryRejected(INVALID_GOAL, 'the controller refused the trajectory (an injected arm_reject '
                                     'fault): the arm did not move')
        if self._run is not None:
            self._finish(preempted=True)
        self._run = _Run(traj, start_q, tolerances, self.config)
        if self._happens('arm_abort'):
            self._run.abort_at = float(self._rng['arm_abort'].uniform(0.2, 0.8)) * traj.duration
            self._fault('arm_abort', at=round(self._run.abort_at, 4))
        self._events = []
        if self._slip is not None and self.attached is not None:
            # The carry after a grasp that will slip: it slips at that fraction of this trajectory.
            self._slip_at = self.time + self._slip * traj.duration
            self._slip = None
        return {'joints': list(traj.joint_names), 'points': len(traj.points), 'duration': traj.duration}

    def cancel(self) -> ExecutionReport | None:
        """Stop the running arm trajectory and hold where the joints are."""
        if self._run is None:
            return None
        report = self._finish(preempted=True)
        self._hold_here()
        return report

    def grip(self, position: float, max_effort: float) -> None:
        """Begin a gripper command (per-finger position, m; grasp force, N), replacing a running one."""
        if not (math.isfinite(position) and 0.0 <= position <= panda.FINGER_OPEN + 1e-6):
            raise RadError(f'gripper: position {position} is outside the hand\'s range '
                           f'[0, {panda.FINGER_OPEN}] m per finger')
        if not (math.isfinite(max_effort) and max_effort >= 0):
            raise RadError(f'gripper: max_effort must be finite and >= 0, got {max_effort}')
        if self._happens('gripper_reject'):
            self._fault('gripper_reject')
            raise GripperFailed('the gripper refused the command (an injected gripper_reject fault): the fingers '
                                'did not move')
        now = float(self.world.joint_positions()[7:].mean())
        closing = position < now - 1e-4
        self._grip = _Grip(min(position, panda.FINGER_OPEN), max_effort, float(self._target[7:].mean()), closing)
        if not closing and position > now + 1e-3 and self._happens('gripper_abort'):
            # The fingers stop partway (something in their way): the move ends short, reached_goal false.
            grip = self._grip
            grip.drive = now + float(self._rng['gripper_abort'].uniform(0.2, 0.7)) * (grip.goal - now)
            self._fault('gripper_abort', stopped_at=round(grip.drive, 5))
        if closing:
            self._miss_next = self._happens('miss')
        force = max_effort if closing and max_effort > 0 else self.config.finger_force
        self._forces[7:] = [force, force]

    def cancel_gripper(self) -> GripperResult | None:
        """Stop the hand where it is."""
        if self._grip is None:
            return None
        return self._finish_grip(stop=True)

    def advance(self, seconds: float) -> dict | None:
        """Simulate `seconds` more (whole steps; the remainder carries over).

        Returns the finished arm trajectory's report as a dict when one completes
        within this slice, else None (a finished gripper command leaves its result
        in `gripper_result`). Without commands the robot holds.
        """
        if not (math.isfinite(seconds) and seconds >= 0):
            raise RadError(f'advance: seconds must be finite and >= 0, got {seconds!r}')
        self._carry += seconds
        n = int(self._carry / self.dt + 1e-9)
        self._carry -= n * self.dt
        report = self._steps(n)
        return None if report is None else report.as_dict()

    def settle(self, seconds: float) -> None:
        """Let physics run for `seconds`: the robot holds its command (a running one goes on)."""
        self.advance(seconds)

    def settle_until_rest(self, seconds: float, min_s: float, every_s: float, speed: float, spin: float) -> float:
        """Let physics run at most `seconds`, and stop once the blocks are at rest; returns the seconds run.

        From `min_s` on, every `every_s`, every block's linear speed (m/s) and angular speed (rad/s)
        are read; when both are under `speed` and `spin` at two checks in a row, the settling ends
        there. A block that tips or slides keeps speeding up, so it never passes two checks in a row
        (`RobotEnvConfig.at_rest` says what that bounds). Whole time steps, as `settle`.
        """
        if not all(math.isfinite(x) and x >= 0 for x in (seconds, min_s, speed, spin)) or not every_s > 0:
            raise RadError(f'settle_until_rest: bad arguments {(seconds, min_s, every_s, speed, spin)!r}')
        p, cid, bodies = self._p, self.world.client, list(self.world.blocks.values())
        total = int(seconds / self.dt + 1e-9)
        first, every = min(total, int(min_s / self.dt + 1e-9)), max(1, round(every_s / self.dt))
        self._steps(first)
        done, calm = first, 0
        while done < total:
            n = min(every, total - done)
            self._steps(n)
            done += n
            still = True
            for body in bodies:
                v, w = p.getBaseVelocity(body, physicsClientId=cid)
                if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] >= speed * speed or \
                        w[0] * w[0] + w[1] * w[1] + w[2] * w[2] >= spin * spin:
                    still = False
                    break
            calm = calm + 1 if still else 0
            if calm >= 2:
                break
        return done * self.dt

    def execute(self, trajectory: Trajectory | dict, callback=None, callback_period: float = 0.02,
                real_time_factor: float | None = None, tolerances: Tolerances = Tolerances()) -> ExecutionReport:
        """Run an arm trajectory to its end (goal hold included) and report (its error_code says how it ended).

        callback(twin) is called every `callback_period` simulated seconds (to
        publish state); real_time_factor paces the run to that many simulated
        seconds per wall second (1.0 = real time, None = as fast as possible).
        Raises `TrajectoryRejected` when the trajectory is refused.
        """
        self.start(trajectory, tolerances)
        wall0 = time.perf_counter()
        report = self._run_until(lambda: self._run is None, callback, callback_period, real_time_factor)
        report.wall_time = time.perf_counter() - wall0
        return report

    def execute_gripper(self, command: GripperCommand, callback=None, callback_period: float = 0.02,
                        real_time_factor: float | None = None) -> GripperResult:
        """Run a gripper command to its end and return what the gripper action would answer: the hand's
        GripperCommand, or the vacuum gripper's Vacuum / DropOff ('vacuum', 'drop_off')."""
        if command.action in VACUUM_ACTIONS:
            return self.execute_vacuum(command, callback, callback_period, real_time_factor)
        if self.world.effector != 'hand':
            raise RadError(f'gripper: this robot carries the {self.world.effector} gripper, not a hand: '
                           f'a {command.action!r} command has no action to go to')
        self.grip(command.position, command.max_effort)
        self._run_until(lambda: self._grip is None, callback, callback_period, real_time_factor)
        return self.gripper_result

    def execute_vacuum(self, command: GripperCommand, callback=None, callback_period: float = 0.02,
                       real_time_factor: float | None = None) -> GripperResult:
        """The vacuum gripper's Vacuum or DropOff goal run to its end: `VACUUM_BUILD_UP_S` of simulated
        time (at most its `timeout_ms`), then `vacuum_now`."""
        self._check_vacuum_gripper(command)
        self._run_for(min(command.timeout_ms / 1000.0, VACUUM_BUILD_UP_S), callback, callback_period,
                      real_time_factor)
        return self.vacuum_now(command)

    def vacuum_now(self, command: GripperCommand) -> GripperResult:
        """The end of a Vacuum or DropOff goal, as the real pump answers it (reached_goal is the action's
        success, error its text): a vacuum holds the block whose flat top face the cup sits on (`seal`),
        else fails as the pump does when its level is not reached; a drop-off lets the held block go (and
        succeeds with nothing held, as libfranka's dropOff does)."""
        self._check_vacuum_gripper(command)
        if not (1 <= command.timeout_ms <= 127):
            return self._vacuum_answer(False, f'timeout must be 1..127 ms, got {command.timeout_ms}')
        if command.action == 'drop_off':
            self._release()
            return self._vacuum_answer(True, '')
        if not (1 <= command.vacuum <= 127):
            return self._vacuum_answer(False, f'vacuum must be 1..127 (x 10 mbar), got {command.vacuum}')
        if self.attached is not None:
            return self._vacuum_answer(True, '')
        block_id, why = self.seal()
        if block_id and self._happens('miss'):
            self._fault('miss', block=block_id)
            block_id, why = '', 'the vacuum was not reached: the seal leaks'
        if not block_id:
            return self._vacuum_answer(False, why)
        self._attach(block_id, float('nan'))
        return self._vacuum_answer(True, '')

    def _check_vacuum_gripper(self, command: GripperCommand) -> None:
        if self.world.effector != 'suction':
            raise RadError(f'gripper: this robot carries the {self.world.effector}, not a vacuum gripper: '
                           f'a {command.action!r} command has no action to go to')
        if command.action not in VACUUM_ACTIONS:
            raise RadError(f'gripper: {command.action!r} is not a vacuum gripper command ({", ".join(VACUUM_ACTIONS)})')

    def seal(self) -> tuple[str, str]:
        """(the block the cup seals on, '') or ('', why none): the cup's lip within `SEAL_GAP` above a
        unit's top face (no unit of the same block above it), its whole rim on that face (the face's
        edges, set back by the scene's clearance, at least `CUP_RADIUS` from the cup's centre) and the
        face level within `SEAL_TILT_DEG`."""
        p, w = self._p, self.world
        lip = np.asarray(p.getLinkState(w.robot, w.ee_link, computeForwardKinematics=True,
                                        physicsClientId=w.client)[4])
        scene, nearest = w.scene, (math.inf, 'the cup touches no block\'s top face')
        half = scene.unit * (1.0 - scene.clearance) / 2
        for block_id in w.blocks:
            btype = scene.block_types[scene.block(block_id).type]
            position, quaternion = w.block_pose(block_id)
            rot = matrix_from_quaternion(np.asarray(quaternion))
            tilt = math.degrees(math.acos(min(1.0, abs(float(rot[2, 2])))))
            cells = {tuple(o) for o in btype.offsets}
            for x, y, z in btype.offsets:
                if (x, y, z + 1) in cells:
                    continue
                top = np.asarray(position) + rot @ (np.array([x, y, z + 0.5]) * scene.pitch)
                local = rot.T @ (lip - top)
                gap, off = float(local[2]), float(max(abs(local[0]), abs(local[1])))
                if not (-0.002 <= gap <= SEAL_GAP) or off > half:
                    continue
                if tilt > SEAL_TILT_DEG:
                    why = f'block {block_id} is tilted {tilt:.1f} deg: the cup finds no level face'
                    nearest = min(nearest, (0.0, why))
                elif off + panda.CUP_RADIUS > half:
                    why = (f'the cup is {off * 1000:.1f} mm off the centre of block {block_id}\'s top face: '
                           'its rim passes the edge')
                    nearest = min(nearest, (off, why))
                else:
                    return block_id, ''
        return '', nearest[1]

    def _vacuum_answer(self, success: bool, error: str) -> GripperResult:
        self.gripper_result = GripperResult(panda.FINGER_OPEN, 0.0, False, success, error)
        return self.gripper_result

    def _run_for(self, seconds: float, callback, callback_period, real_time_factor) -> None:
        end = self.time + seconds
        self._run_until(lambda: self.time >= end - 1e-9, callback, callback_period, real_time_factor)

    def execute_motion(self, motion: Motion, callback=None, real_time_factor: float | None = None) -> str:
        """Run a step's commands in order (`rad_core.cell.motion.run_motion`); '' when all went through, else
        why the step stopped: a refused or aborted trajectory, or a grasp that holds nothing."""
        def move_arm(trajectory):
            report = self.execute(trajectory, callback, real_time_factor=real_time_factor)
            if report.error_code != SUCCESSFUL:
                raise TrajectoryAborted(report.error_code, f'trajectory aborted (error code {report.error_code}): '
                                                           f'{report.error_string}')

        start = self.world.joint_positions()[:7]
        try:
            return run_motion(motion, move_arm, lambda c: self.execute_gripper(c, callback,
                                                                               real_time_factor=real_time_factor),
                              start=start)
        except TrajectoryRejected as e:
            return f'trajectory refused (error code {e.code}): {e}'
        except RadError as e:
            return str(e)

    def _run_until(self, done, callback, callback_period, real_time_factor) -> ExecutionReport | None:
        slice_steps = max(1, round(callback_period / self.dt))
        wall0, sim0 = time.perf_counter(), self.time
        last = None
        while True:
            report = self._steps(slice_steps)
            last = report or last
            if callback is not None:
                callback(self)
            if real_time_factor:
                ahead = (self.time - sim0) / real_time_factor - (time.perf_counter() - wall0)
                if ahead > 0:
                    time.sleep(ahead)
            if done():
                return last

    # ---- stepping ------------------------------------------------------------
    def _apply(self) -> None:
        p, w = self._p, self.world
        p.setJointMotorControlArray(w.robot, w.joints, p.POSITION_CONTROL, targetPositions=self._target.tolist(),
                                    targetVelocities=self._target_vel.tolist(), forces=self._forces,
                                    positionGains=[self.config.position_gain] * 9,
                                    velocityGains=[self.config.velocity_gain] * 9, physicsClientId=w.client)

    def _hold_here(self) -> None:
        self._target[:7] = self.world.joint_positions()[:7]
        self._target_vel[:] = 0.0
        self._apply()

    def _steps(self, n: int) -> ExecutionReport | None:
        finished = None
        t0 = time.perf_counter()
        for _ in range(n):
            run = self._run
            if run is not None:
                q_cmd, dq_cmd = run.command(run.t + self.dt)
                self._target[:7] = q_cmd
                self._target_vel[:7] = dq_cmd
            grip = self._grip
            if grip is not None:
                step = self.config.gripper_speed * self.dt
                grip.target += float(np.clip(grip.drive - grip.target, -step, step))
                self._target[7:] = grip.target
            self._apply()
            self.world.step()
            self.time += self.dt
            if self.attached is not None and self.world.scene.studs is not None:
                self._press_check()
            if self._slip_at is not None and self.time >= self._slip_at:
                self._slip_out()
            self._grasp_update()
            if self._ghosts and round(self.time / self.dt) % 10 == 0:
                self._unghost()
            if grip is not None:
                self._grip_progress(grip)
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
        """Track the error; True once the run is over: arrived, or a tolerance violated (report says)."""
        q = self.world.joint_positions()[:7]
        q_cmd, _ = run.command(run.t)
        err = float(np.abs(q - q_cmd).max())
        duration = run.spline.duration
        if run.t >= run.abort_at:
            j = int(np.abs(q - q_cmd).argmax())
            run.report.error_code = PATH_TOLERANCE_VIOLATED
            run.report.error_string = (f'path tolerance violated: the arm was held back (an injected arm_abort '
                                       f'fault) at t = {run.t:.3f} s; {run.report.joint_names[j]} is {err:.4f} rad '
                                       f'from the command')
            run.report.final_error = err
            return True
        if run.t < duration - 1e-9:
            run.max_error = max(run.max_error, err)
            if run.path_tol > 0 and err > run.path_tol:
                j = int(np.abs(q - q_cmd).argmax())
                run.report.error_code = PATH_TOLERANCE_VIOLATED
                run.report.error_string = (f'path tolerance violated: {run.report.joint_names[j]} is {err:.4f} rad '
                                           f'from the command (tolerance {run.path_tol:.4f}) at t = {run.t:.3f} s'
                                           + self._contact_note())
                run.report.final_error = err
                return True
            return False
        run.report.final_error = err
        if err <= run.goal_tol:
            return True
        if run.t >= duration + run.goal_time - 1e-9:
            if not run.goal_enforced:      # no goal tolerance asked for: done, as the controller is
                return True
            run.report.error_code = GOAL_TOLERANCE_VIOLATED
            run.report.error_string = (f'goal tolerance violated: {err:.4f} rad from the last point after '
                                       f'{run.goal_time:.2f} s (tolerance {run.goal_tol:.4f})')
            return True
        return False

    def _finish(self, preempted: bool) -> ExecutionReport:
        run, self._run = self._run, None
        r = run.report
        r.final_positions = self.world.joint_positions()
        if math.isnan(r.final_error):
            r.final_error = float(np.abs(r.final_positions[:7] - run.spline.pos[-1]).max())
        r.max_tracking_error = run.max_error
        r.grasp_events = list(self._events)
        r.sim_time = run.t
        r.steps = round(run.t / self.dt)
        r.wall_time = time.perf_counter() - run.wall_start
        r.preempted = preempted
        if r.error_code != SUCCESSFUL:
            self._hold_here()           # an aborted run holds where the arm is, as the controller does
        else:
            # Hold exactly the last command (zero velocity), as the controller does at the end.
            self._target_vel[:] = 0.0
            self._apply()
        return r

    def _grip_progress(self, grip: _Grip) -> None:
        grip.t += self.dt
        fingers = self.world.joint_positions()[7:]
        moving = np.abs(self.world.joint_velocities()[7:]).max() > 1e-3
        grip.still = 0.0 if moving else grip.still + self.dt
        commanded = abs(grip.target - grip.drive) < 1e-9
        arrived = commanded and np.abs(fingers - grip.drive).max() < 2e-4
        stalled = grip.still >= 0.05 and (commanded or grip.closing)
        if stalled and not grip.closing and self._wedged():
            grip.still = 0.0
            return
        timeout = grip.t > abs(grip.drive - fingers.mean()) / self.config.gripper_speed + 2.0
        if arrived or stalled or timeout:
            self._finish_grip(stop=False)

    def _finish_grip(self, stop: bool) -> GripperResult:
        grip, self._grip = self._grip, None
        position = float(self.world.joint_positions()[7:].mean())
        if grip.closing:
            reached = abs(2 * position - 2 * grip.goal) <= self.config.grasp_epsilon
        else:
            reached = abs(position - grip.goal) < 5e-4
        if stop or not grip.closing:
            # A move that stopped (cancelled, blocked) holds where the fingers are; a grasp keeps squeezing.
            self._target[7:] = position if (stop or not reached) else grip.drive
        self._apply()
        self.gripper_result = GripperResult(position, grip.effort if grip.closing else 0.0,
                                            stalled=abs(position - grip.goal) >= 2e-4, reached_goal=bool(reached))
        return self.gripper_result

    # ---- grasping --------------------------------------------------------------
    def _grasp_update(self) -> None:
        cfg, w = self.config, self.world
        target = float(self._target[7:].mean())
        fingers = w.joint_positions()[7:]
        if self.attached is not None:
            if target > self._grip_width + cfg.release_margin:
                released = (self.attached[0], self._grip_width)
                self._release()
                self._released = released
            return
        if self._released is not None:
            block_id, width = self._released
            if block_id not in w.blocks:
                self._released = None
            elif float(fingers.min()) > width + 0.003 and w.blocks[block_id] not in self._ghosts:
                # the fingers are clear of the block's sides (and collide with it again)
                self._released = None
                self._after_release(block_id)
        closing = target < panda.FINGER_OPEN - cfg.close_margin and target < float(fingers.mean()) - cfg.close_margin
        if not closing:
            return
        touched = [self._touching(link) for link in w.finger_links]
        common = sorted(touched[0] & touched[1])
        if common and self._miss_next:
            self._miss_next = False
            self._ghost(common[0])
            self._fault('miss', block=common[0])
        elif common:
            self._attach(common[0], float(fingers.mean()))

    def _wedged(self) -> bool:
        """Opening fingers stopped by the block they just let go: let them pass through it (until
        clear, `_unghost`). In PyBullet the squeezed pads' penetration recovery can twist a block as
        they open, and a twisted block wedges between them and comes up with the hand; a parallel
        gripper's coupled fingers open symmetrically off a block standing on its support."""
        if self._released is None:
            return False
        block_id = self._released[0]
        body = self.world.blocks.get(block_id)
        if body is None or body in self._ghosts:
            return False
        if not all(block_id in self._touching(link) for link in self.world.finger_links):
            return False
        self._ghost(block_id)
        self._events.append({'t': round(self._run_time(), 6), 'action': 'unwedge', 'block': block_id})
        return True

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
        self._released = None
        self._events.append({'t': round(self._run_time(), 6), 'action': 'attach', 'block': block_id})
        if self._happens('slip'):
            # It will slip out during the carry: at this fraction of the next arm trajectory.
            self._slip = float(self._rng['slip'].uniform(0.1, 0.6))

    def _release(self) -> None:
        if self.attached is None:
            return
        block_id, c = self.attached
        self.attached = None
        self._slip = self._slip_at = None
        if c in self._constraint_ids():   # gone already when its block was removed with a scene
            self._p.removeConstraint(c, physicsClientId=self.world.client)
        self._events.append({'t': round(self._run_time(), 6), 'action': 'detach', 'block': block_id})
        if self._pressed == block_id and block_id in self.world.blocks:
            if self._happens('unpressed'):
                self._fault('unpressed', block=block_id)
            else:
                joined = self.world.studs.join(self.world, block_id)
                self._events.append({'t': round(self._run_time(), 6), 'action': 'join', 'block': block_id,
                                     'to': joined})
        self._pressed = None
        self._touched_at.pop(block_id, None)
        if self.world.studs.studs and self._happens('knock'):
            self._knock()

    def _knock(self) -> None:
        """A brick of the structure knocked off its studs (`FaultConfig.knock`): one joined brick, drawn
        at random, lets go of the bricks under it and is pushed sideways."""
        w, rng = self.world, self._rng['knock']
        joined = sorted({s.upper for s in w.studs.studs.values() if not s.broken})
        if not joined:
            return
        block_id = joined[int(rng.integers(len(joined)))]
        w.studs.let_go(w, block_id)
        angle = float(rng.uniform(0.0, 2 * math.pi))
        speed = self.config.faults.knock_speed
        self._p.resetBaseVelocity(w.blocks[block_id], [speed * math.cos(angle), speed * math.sin(angle), 0.0],
                                  [0.0, 0.0, 0.0], physicsClientId=w.client)
        w.wake(block_id)
        self._fault('knock', block=block_id)

    def _over_target(self, block_id: str) -> bool:
        """Whether the brick's units are all over a target region's footprint (not where it was picked)."""
        w = self.world
        xy = w.unit_centres(block_id)[:, :2]
        for region in w.scene.targets:
            lo = np.asarray(region.origin[:2]) - w.scene.unit / 2
            hi = lo + w.scene.unit * np.asarray(region.size[:2])
            if np.all((xy > lo) & (xy < hi)):
                return True
        return False

    def _press_check(self) -> None:
        """Whether the held brick has been pushed onto the blocks under it `press_travel` past where it
        first touched them (the hand's travel while in contact): then it is pressed home onto their
        studs, and joined when let go (`sim.clutch`)."""
        p, w = self._p, self.world
        block_id = self.attached[0]
        body = w.blocks.get(block_id)
        if body is None or self._pressed == block_id:
            return
        others = set(w.blocks.values()) - {body}
        if w.scene.studs is not None and w.scene.studs.baseplate and self._over_target(block_id):
            others.add(w.table)         # the baseplate's studs take a press where the design stands
        if not any(c[2] in others and c[7][2] > 0.9       # the normal on B points up at the held brick
                   for c in p.getContactPoints(bodyA=body, physicsClientId=w.client)):
            return
        hand_z = float(p.getLinkState(w.robot, w.ee_link, computeForwardKinematics=True,
                                      physicsClientId=w.client)[4][2])
        touched = self._touched_at.setdefault(block_id, hand_z)
        if touched - hand_z >= self.config.press_travel:
            self._pressed = block_id
            self._events.append({'t': round(self._run_time(), 6), 'action': 'pressed', 'block': block_id,
                                 'travel': round(touched - hand_z, 5)})

    # ---- faults ------------------------------------------------------------------
    def _happens(self, kind: str) -> bool:
        """Whether a fault of `kind` (its FaultConfig probability) happens now: one draw from its own stream,
        none while it is off, so turning one kind on does not shift when another happens."""
        p = getattr(self.config.faults, kind)
        return p > 0 and bool(self._rng[kind].random() < p)

    def _fault(self, kind: str, **fields) -> None:
        event = {'t': round(self._run_time(), 6), 'action': 'fault', 'fault': kind, **fields}
        self._events.append(event)
        self.fault_events.append({**event, 'time': round(self.time, 6)})
        self.fault_counts[kind] += 1

    def _slip_out(self) -> None:
        """The held block slips out of the hand: let go, and the fingers no longer hold it up."""
        self._slip_at = None
        if self.attached is None:
            return
        block_id = self.attached[0]
        self._release()
        self._ghost(block_id)
        self._fault('slip', block=block_id)

    def _ghost(self, block_id: str) -> None:
        """Let the fingers pass through a block (until it is clear of them, `_unghost`)."""
        p, w = self._p, self.world
        body = w.blocks[block_id]
        for link in w.finger_links:
            p.setCollisionFilterPair(w.robot, body, link, -1, 0, physicsClientId=w.client)
        self._ghosts[body] = block_id

    def _unghost(self) -> None:
        p, w = self._p, self.world
        for body, block_id in list(self._ghosts.items()):
            if w.blocks.get(block_id) != body:
                del self._ghosts[body]
                continue
            # Bounding boxes, not closest points: those honour the collision filter and find nothing.
            lo, hi = (np.asarray(v) for v in p.getAABB(body, physicsClientId=w.client))
            near = False
            for link in w.finger_links:
                flo, fhi = (np.asarray(v) for v in p.getAABB(w.robot, link, physicsClientId=w.client))
                near |= bool(np.all(flo < hi + 0.002) and np.all(lo - 0.002 < fhi))
            if not near:
                for link in w.finger_links:
                    p.setCollisionFilterPair(w.robot, body, link, -1, 1, physicsClientId=w.client)
                del self._ghosts[body]

    def _after_release(self, block_id: str) -> None:
        """The fingers are clear of a block they placed: the placement error, and a nudged neighbour."""
        f, w = self.config.faults, self.world
        if f.placement_error > 0:
            offset = self._rng['placement'].normal(0.0, f.placement_error, 2)
            moved = self._shift(block_id, offset)
            self._fault('placement', block=block_id, offset=[round(float(v), 6) for v in offset * moved])
        if self._happens('nudge'):
            p = self._p
            body = w.blocks[block_id]
            near = sorted(bid for bid, other in w.blocks.items() if other != body
                          and p.getClosestPoints(body, other, 0.005, physicsClientId=w.client))
            if near:
                other = near[int(self._rng['nudge'].integers(len(near)))]
                a = np.array(p.getBasePositionAndOrientation(body, physicsClientId=w.client)[0])
                b = np.array(p.getBasePositionAndOrientation(w.blocks[other], physicsClientId=w.client)[0])
                d = (b - a)[:2]
                axis = int(abs(d[1]) > abs(d[0]))     # pushed along the grid axis it mostly lies on
                direction = np.zeros(2)
                direction[axis] = 1.0 if d[axis] >= 0 else -1.0
                moved = self._shift(other, direction * f.nudge_distance)
                self._fault('nudge', block=other, by=block_id, distance=round(moved * f.nudge_distance, 6))

    def _shift(self, block_id: str, dxy: np.ndarray) -> float:
        """Move a block by dxy (m) in x/y, or as far along it as it goes without pushing into anything
        (to within 1/64 of it: a block shifted at a neighbour ends against it); returns the fraction moved."""
        w = self.world
        pos, q = w.block_pose(block_id)
        body = w.blocks[block_id]
        before = self._penetration(body)

        def fits(frac: float) -> bool:
            w.set_block_pose(block_id, [pos[0] + frac * dxy[0], pos[1] + frac * dxy[1], pos[2]], q)
            return self._penetration(body) >= before - 2e-4

        if fits(1.0):
            return 1.0
        lo, hi = 0.0, 1.0
        for _ in range(6):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if fits(mid) else (lo, mid)
        fits(lo)
        return lo

    def _penetration(self, body: int) -> float:
        """The deepest contact (m, <= 0) of a body with anything now."""
        p, cid = self._p, self.world.client
        p.performCollisionDetection(physicsClientId=cid)
        return min([0.0] + [c[8] for c in p.getContactPoints(bodyA=body, physicsClientId=cid)])

    def _contact_note(self) -> str:
        """What the arm touches now, for a tracking error's report (a real controller cannot say; the twin can)."""
        p, w = self._p, self.world
        names = {body: f'block {bid}' for bid, body in w.blocks.items()}
        names[w.table] = 'the table'
        links = {i: n for n, i in w.link_index.items()}
        touched = sorted({f'{links.get(c[3], c[3])} touches {names.get(c[2], f"body {c[2]}")}'
                          for c in p.getContactPoints(bodyA=w.robot, physicsClientId=w.client)
                          if c[2] != w.robot and c[8] < 1e-3})
        held = ''
        if self.attached is not None:
            # What the held block touches pushes the hand too (the attachment is rigid).
            body = w.blocks.get(self.attached[0])
            hits = sorted({names.get(c[2], f'body {c[2]}') for c in
                           (p.getContactPoints(bodyA=body, physicsClientId=w.client) if body is not None else [])
                           if c[2] not in (w.robot, body) and c[8] < 1e-3})
            held = f'; holding block {self.attached[0]}' + (f', which touches {", ".join(hits)}' if hits else '')
        return (f' ({", ".join(touched)}{held})' if touched else f' (no contact{held})')

    def _constraint_ids(self) -> set[int]:
        p, cid = self._p, self.world.client
        count = p.getNumConstraints(physicsClientId=cid)
        return {p.getConstraintUniqueId(i, physicsClientId=cid) for i in range(count)}

    def _run_time(self) -> float:
        return self._run.t + self.dt if self._run is not None else self.time

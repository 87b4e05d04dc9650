"""The assembly MDP with the robot in the loop (the paper's Sec. V-B setting).

An action succeeds only if (1) the geometry allows it (on the grid, no overlap),
(2) GAMP finds a feasible grasp and placement, (3) the twin executes the motion,
and (4) afterwards the new block sits at its pose, the structure still stands and
no other block was moved. Failures are classed as the paper's Table II needs:
f_g (no feasible grasp), f_p (no feasible placement, or the motion knocked
another block), and instability (the new block or the structure did not stay).

Speed: one physics client for everything (GAMP probes the same World the twin
steps, inside a restoring context); blocks that would rest on nothing fail by
geometry without any physics; and `execution='teleport'` skips simulating the
arm (the block is put in place and physics only settles the structure), the
predecessor's shortcut, for training; 'simulate' runs the whole trajectory.

For training (`rad_core.training.dqn` with the robot), two more (measured in
benchmarks/bench_robot_training.py and docs/results/robot_training.md):
- ``markov=True``: after each successful step the world is put where the MDP
  state says (placed blocks on their grid poses, as always; the other blocks back
  at their start poses, the arm at HOME), so what the next step sees is a function
  of (scene, placed blocks) alone, as the learner's observation assumes;
- ``cache=True`` (needs markov and teleport): the verdict of GAMP + execution +
  physics for an action, keyed on the scene, the placed blocks and the action, is
  remembered (`StepCache`) and replayed when the same question comes again (the
  validation scenes every evaluation, repeated training scenes), skipping GAMP and
  the settling. One env serves many scenes with `load`, so the PyBullet world (and
  its robot model) is built once.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace

import numpy as np

from rad_core.cell import panda
from rad_core.domain import support
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_of_quaternion, yaw_quaternion
from rad_core.env.mdp import Action, AssemblyEnv, EnvConfig, Outcome, StepResult
from rad_core.gamp.planner import GampConfig, placement_pose, plan_action
from rad_core.sim.twin import Twin, TwinConfig
from rad_core.sim.world import World, WorldConfig

# How each outcome counts in the paper's Table II.
OUTCOME_CLASS = {
    Outcome.INVALID_GRASP: 'f_g',
    Outcome.INVALID_PLACEMENT: 'f_p',
    Outcome.INVALID_DISTURBED: 'f_p',
    Outcome.INVALID_UNSTABLE: 'unstable',
    Outcome.INVALID_OVERLAP: 'invalid',
    Outcome.INVALID_OFF_GRID: 'invalid',
    Outcome.INVALID_BLOCK: 'invalid',
}


def outcome_class(outcome: Outcome) -> str:
    """'success' for every non-failure outcome, else f_g / f_p / unstable / invalid."""
    return OUTCOME_CLASS.get(outcome, 'success')


@dataclass(frozen=True)
class AtRest:
    """When a teleporting step's settling may end before `RobotEnvConfig.settle_s`.

    From `min_s` on, every `every_s`, the twin reads every block's speed; when all are under
    `speed` (m/s) and `spin` (rad/s) at two checks in a row, the blocks are judged there
    (`Twin.settle_until_rest`). Why that decides as the full settling does: a block that will fall
    or tip is pulled by an unbalanced force and speeds up, so it does not pass two checks in a
    row. One that tips so slowly that it passes (angular acceleration under spin / min_s, 0.5
    rad/s^2 by default) would turn less than 4 degrees by 0.5 s, and `tilt_tol_deg` is 5.
    Measured: the same verdicts as the full 0.5 s on 1,152 steps of 47 scenes
    (benchmarks/bench_at_rest.py) and on every step of the planning-step benchmark
    (docs/results/planning_step.md).
    """

    min_s: float = 0.1
    every_s: float = 0.025
    speed: float = 0.002
    spin: float = 0.05

    def __post_init__(self):
        if not (self.min_s >= 0 and self.every_s > 0 and self.speed >= 0 and self.spin >= 0):
            raise RadError(f'AtRest: min_s, speed and spin must be >= 0 and every_s > 0, got {self}')


@dataclass(frozen=True)
class RobotEnvConfig:
    """How the robot environment executes and judges an action.

    execution: 'simulate' (the twin runs the whole trajectory with the arm) or
        'teleport' (the block is put at its pose, only the settling is simulated).
    settle_s: simulated seconds after the motion before poses are judged.
    new_block_tol: the new block may end this far (fraction of a unit) from its pose.
    structure_tol: a placed block moving this far (fraction of a unit; 0.2 = 1 cm
        at 5 cm, the predecessor's "destroyed the structure") fails the action.
    disturbed_tol: a block on the table moving this far fails it (f_p).
    tilt_tol_deg: any block tilting more than this fails it.
    markov: after each successful step, blocks not placed go back to their start
        poses and the arm to HOME (placed ones are always snapped to the grid), so
        the world before a step is a function of the MDP state.
    cache: replay the verdict of an action already judged from the same state
        (scene, placed blocks); needs markov and teleport execution.
    at_rest: with teleport execution, end the settling once the blocks are at rest
        (`AtRest`), at most settle_s; None settles the full settle_s. Simulated
        execution always settles settle_s.
    """

    env: EnvConfig = field(default_factory=lambda: EnvConfig(stability='none'))
    execution: str = 'simulate'
    settle_s: float = 0.5
    new_block_tol: float = 0.1
    structure_tol: float = 0.2
    disturbed_tol: float = 0.1
    tilt_tol_deg: float = 5.0
    gamp: GampConfig = field(default_factory=GampConfig)
    twin: TwinConfig = field(default_factory=TwinConfig)
    markov: bool = False
    cache: bool = False
    at_rest: AtRest | None = field(default_factory=AtRest)

    def __post_init__(self):
        if self.execution not in ('simulate', 'teleport'):
            raise RadError(f"execution must be 'simulate' or 'teleport', got {self.execution!r}")
        if self.cache and not (self.markov and self.execution == 'teleport'):
            raise RadError('the step cache needs markov=True and teleport execution (otherwise the world '
                           'before a step is not a function of the MDP state)')
        if self.env.stability != 'none':
            # Stability is what the twin shows after executing; no second opinion.
            object.__setattr__(self, 'env', replace(self.env, stability='none'))


@dataclass
class RobotSnapshot:
    """What `RobotAssemblyEnv.snapshot` returns (opaque to callers)."""

    state: object        # the AssemblyEnv state
    world: object        # a sim.world.WorldState
    last_plan: object = None


class StepCache:
    """Verdicts of robot steps: (scene key, placed blocks, action) -> (outcome, reason).

    Valid because with `RobotEnvConfig.markov` the world before a step is a function
    of the scene and the placed blocks (poses and arm; GAMP seeds its IK from a
    fixed seed), so GAMP's answer and the teleport-and-settle verdict are too (up to
    Bullet's contact cache, whose history the cache ignores: measured to change no
    verdict, benchmarks/bench_robot_training.py). Plain data: a training checkpoint
    stores it, so a resumed run replays exactly what the uninterrupted one would.
    """

    def __init__(self, max_entries: int = 200_000):
        self.max_entries = max_entries
        self.table: dict[tuple, tuple[str, str]] = {}
        self.hits = self.misses = 0

    def get(self, key: tuple) -> tuple[str, str] | None:
        found = self.table.get(key)
        if found is None:
            self.misses += 1
        else:
            self.hits += 1
        return found

    def put(self, key: tuple, outcome: Outcome, reason: str) -> None:
        if len(self.table) >= self.max_entries:
            self.table.clear()   # rare (a long run on many scenes); simple and deterministic
        self.table[key] = (outcome.value, reason)

    def state_dict(self) -> dict:
        return {'table': dict(self.table), 'hits': self.hits, 'misses': self.misses}

    def load_state_dict(self, d: dict) -> None:
        self.table, self.hits, self.misses = dict(d['table']), int(d['hits']), int(d['misses'])


def scene_key(scene: Scene) -> str:
    """A short digest of everything in a scene (blocks, poses, types, targets)."""
    text = json.dumps(scene.to_dict(), sort_keys=True, separators=(',', ':'))
    return hashlib.sha1(text.encode()).hexdigest()[:20]


class RobotAssemblyEnv:
    """The MDP of `AssemblyEnv` (same actions, rewards, termination) with the robot.

    `env` is the bookkeeping AssemblyEnv (use it for the grid, state views, the
    flat action index and an AllocationGuide); `world` and `twin` the simulation.
    """

    def __init__(self, scene: Scene, config: RobotEnvConfig = RobotEnvConfig(), cache: StepCache | None = None):
        self.config = config
        self.world = World(scene, WorldConfig(effector=config.gamp.effector))
        self.twin = Twin(self.world, config.twin)
        self.cache = (cache if cache is not None else StepCache()) if config.cache else None
        self.load(scene)

    def load(self, scene: Scene) -> None:
        """Switch to another scene in the same PyBullet world (no new robot model);
        call `reset` before stepping. Snapshots of the previous scene become invalid."""
        self.scene = scene
        self.env = AssemblyEnv(scene, self.config.env)
        self.last_plan = None
        self._scene_key = scene_key(scene) if self.cache is not None else ''
        self._start_poses = {b.id: (np.asarray(b.position, dtype=float), yaw_quaternion(b.yaw))
                             for b in scene.blocks}

    def close(self) -> None:
        self.world.close()

    def __enter__(self) -> 'RobotAssemblyEnv':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def reset(self):
        self.twin.load_scene(self.scene)
        self.last_plan = None
        return self.env.reset()

    # ---- branching, for search ---------------------------------------------------
    def snapshot(self) -> 'RobotSnapshot':
        """Everything that decides the next step: the MDP state, the world (block poses
        and velocities, arm joints, Bullet's contact cache) and the last motion plan.
        Taken between steps (the twin idle, nothing held); restoring it and repeating an
        action gives the same outcome (poses equal to 1e-7 m)."""
        if self.twin.busy or self.twin.attached is not None:
            raise RadError('RobotAssemblyEnv.snapshot: the twin is executing or holding a block')
        return RobotSnapshot(self.env.snapshot(), self.world.save(), self.last_plan)

    def restore(self, snapshot: 'RobotSnapshot') -> None:
        """Go back to a snapshot of this env (it stays valid for further restores)."""
        self.world.restore(snapshot.world)
        self.twin.sync()
        self.env.restore(snapshot.state)
        self.last_plan = snapshot.last_plan

    # ---- one action ----------------------------------------------------------
    def _target(self, action: Action) -> tuple[str, np.ndarray, int]:
        """Block id, final anchor position and yaw the action asks for."""
        block_id = self.scene.blocks[action.block].id
        position, yaw = placement_pose(self.scene, block_id, action.unit, self.env.grid.centres[action.cell],
                                       action.rotation)
        return block_id, position, yaw

    def plan(self, action: Action):
        """GAMP's plan for an action from the world as it is now, without acting."""
        block_id, position, yaw = self._target(action)
        return plan_action(self.world, block_id, position, yaw, start=self.world.joint_positions(),
                           config=self.config.gamp)

    def step(self, action: Action, plan=None) -> StepResult:
        """One MDP step. plan: GAMP's answer for this action from the current state,
        if the caller already has it (from `plan`), so it is not computed twice."""
        env = self.env
        if action.is_terminate or env.state.done:
            return env.step(action)
        outcome, reason, cells, yaw = env.evaluate(action)
        if outcome is not None:
            return env.step(action)   # the same geometric failure, booked as the MDP does
        if not support.any_support(env.grid, env.state.occupancy, cells):
            return env.fail(Outcome.INVALID_UNSTABLE, 'the block would rest on nothing and fall', cells)
        key = None
        if self.cache is not None:
            key = (self._scene_key, tuple(sorted((b, tuple(c.tolist()), int(y)) for b, (c, y) in
                                                 env.state.placed.items())), tuple(action))
            known = self.cache.get(key)
            if known is not None:
                return self._replay(action, Outcome(known[0]), known[1], cells)
        block_id, position, yaw = self._target(action)
        plan = plan if plan is not None else self.plan(action)
        self.last_plan = plan
        if not plan.success:
            failure = Outcome.INVALID_GRASP if plan.failure == 'grasp' else Outcome.INVALID_PLACEMENT
            return self._remember(key, env.fail(failure, plan.reason, cells))
        self.world.present(block_id)     # from the feeder, where the scene has one
        before = {b: self.world.block_pose(b) for b in self.world.blocks}
        self._execute(plan, block_id, position, yaw)
        problem = self._judge(before, block_id, position, yaw)
        if problem is not None:
            return self._remember(key, env.fail(problem[0], problem[1], cells))
        result = env.step(action)
        self._snap_placed()
        result.info['timings'] = dict(plan.timings)
        return self._remember(key, result)

    def _remember(self, key, result: StepResult) -> StepResult:
        if key is not None:
            self.cache.put(key, result.outcome, result.reason)
        return result

    def _replay(self, action: Action, outcome: Outcome, reason: str, cells) -> StepResult:
        """A step whose verdict the cache knows: booked as the first time, the world
        put where that step left it (markov: a function of the new state)."""
        self.last_plan = None
        if outcome.is_invalid:
            return self.env.fail(outcome, reason, cells)
        result = self.env.step(action)
        self._snap_placed()
        result.info['timings'] = {'cached': True}
        return result

    def _execute(self, plan, block_id: str, position, yaw) -> None:
        twin = self.twin
        if self.config.execution == 'simulate':
            twin.execute_motion(plan.motion)     # what went wrong shows in the world, judged after
        else:
            self.world.set_block_pose(block_id, position, yaw_quaternion(yaw))
            self.world.studs.join(self.world, block_id)   # teleported: pressed home onto the studs under it
            self.world.set_joint_positions(plan.final_joints())
            twin.sync()
            rest = self.config.at_rest
            if rest is not None:
                awake = self._placed_ids() | {block_id}
                with self.world.asleep([b for b in self.world.blocks if b not in awake]):
                    twin.settle_until_rest(self.config.settle_s, rest.min_s, rest.every_s, rest.speed, rest.spin)
                return
        twin.settle(self.config.settle_s)

    def _placed_ids(self) -> set[str]:
        """The ids of the blocks placed in the structure."""
        return {self.scene.blocks[b].id for b in self.env.state.placed}

    def _judge(self, before: dict, block_id: str, position, yaw) -> tuple[Outcome, str] | None:
        """What went wrong physically, if anything (new block, structure, the rest)."""
        u, cfg = self.scene.unit, self.config
        p, q = self.world.block_pose(block_id)
        moved = float(np.linalg.norm(p - np.asarray(position)))
        turned = _yaw_gap(yaw_of_quaternion(q), yaw)
        if moved > cfg.new_block_tol * u or _tilt_deg(q) > cfg.tilt_tol_deg or turned > cfg.tilt_tol_deg:
            return Outcome.INVALID_UNSTABLE, (f'block {block_id} did not stay: {moved * 1e3:.1f} mm off its pose, '
                                              f'tilted {_tilt_deg(q):.1f} deg')
        placed = self._placed_ids()
        for other, (p0, q0) in before.items():
            if other == block_id:
                continue
            p1, q1 = self.world.block_pose(other)
            shift = float(np.linalg.norm(p1 - p0))
            tilt = _tilt_deg(q1)
            if other in placed and (shift >= cfg.structure_tol * u or tilt > cfg.tilt_tol_deg):
                return Outcome.INVALID_UNSTABLE, (f'the structure did not stand: block {other} moved '
                                                  f'{shift * 1e3:.1f} mm, tilted {tilt:.1f} deg')
            if other not in placed and (shift > cfg.disturbed_tol * u or tilt > cfg.tilt_tol_deg):
                return Outcome.INVALID_DISTURBED, f'the motion moved block {other} by {shift * 1e3:.1f} mm'
        return None

    def _snap_placed(self) -> None:
        """Put placed blocks back on their exact grid poses, so drift never accumulates
        and the world matches the MDP state the learner sees."""
        for b, (cells, yaw) in self.env.state.placed.items():
            # cells are in unit order: the first is the anchor's.
            anchor = self.env.grid.centres[cells[0]]
            self.world.set_block_pose(self.scene.blocks[b].id, anchor, yaw_quaternion(yaw))
        if self.config.markov:
            placed = self._placed_ids()
            for block_id, (position, quaternion) in self._start_poses.items():
                if block_id in placed:
                    continue
                if self.scene.in_feeder(block_id):
                    self.world.return_to_feeder(block_id)
                else:
                    self.world.set_block_pose(block_id, position, quaternion)
            self.world.set_joint_positions(panda.HOME)
        self.world.set_block_velocities_zero()
        self.twin.sync()

    def current_scene(self) -> Scene:
        return self.twin.current_scene(self.scene)


def _tilt_deg(q) -> float:
    """Angle between the body's z axis and the world's z axis."""
    x, y, z, w = q
    zz = 1 - 2 * (x * x + y * y)
    return float(np.degrees(np.arccos(np.clip(zz, -1.0, 1.0))))


def _yaw_gap(a: float, b: float) -> float:
    return abs((a - b + 180) % 360 - 180)

"""One PyBullet world: the table, the Franka Panda and a scene's blocks.

Everything that moves the robot or the blocks (GAMP's collision probes, the
digital twin, registration from motion capture) works on a `World`: its
``pybullet`` module with its ``client`` passed explicitly; there is no global
client.

Frames and conventions:
- World frame = scene frame: the table top is z = 0, the robot base is at the
  origin, the structure lies in front of it along +x.
- A block body's frame is the centre of its anchor unit (the type's first unit)
  turned by the block's yaw about +z, so `block_pose` speaks the scene format
  directly. The inertial frame is separate (at the centre of mass, along the
  principal axes of the exact polycube inertia; Bullet would otherwise take the
  bounding box's). PyBullet's base pose calls talk about the inertial frame;
  this module converts, so nobody else has to.
- Collision boxes are a hair narrower than a unit on the side faces and a hair
  taller (the same choice and reasons as `rad_core.sim.physics`, whose
  `block_shape` and `add_block_body` build the block bodies of both):
  side-by-side neighbours start apart, stacked layers start in contact instead
  of falling into each other. A scene's ``clearance`` sets the blocks' outer
  side faces back by half of it (collision and visual boxes alike, see
  `rad_core.domain.scene`), so GAMP's probes and the twin see the gaps.

Cost (measured, see tests/core/test_world.py): `preserved()` snapshots and
restores by hand what can change (joint states, block poses and velocities,
constraint ids): about 0.07 ms for a 6-block scene. saveState costs about
1.3 ms there (10 ms in bigger worlds) and is used only for
``preserved(exact=True)``, which also restores Bullet's contact cache so a
simulation replays bit-identically.

A scene's feeder (`rad_core.domain.scene.Feeder`): its blocks are bodies too, but parked: static
(mass 0) and far below the table, so they cost the physics nothing (100 resting blocks
would make every step 20 times slower) and no probe meets them. `present` is the feeder
at work: it puts one at its station pose, a body like any other from then on, and parks
again a presented block the robot did not take. What is parked is part of every snapshot.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from rad_core.cell import panda
from rad_core.cell.panda import JOINT_NAMES
from rad_core.domain.colours import TABLE, type_colour
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion
from rad_core.sim.clutch import StudJoints
from rad_core.sim.physics import (BlockShape, ClientOwner, PhysicsConfig, add_block_body, block_shape,
                                  direct_client)

STUD_CHECK_STEPS = 4
"""Every how many simulation steps stretched studs are looked for (`sim.clutch.StudJoints.check`)."""

PARK_Z = -20.0
"""Where parked feeder blocks wait (m below the table top), one metre apart along x."""


@dataclass(frozen=True)
class WorldConfig:
    """How the world is built and simulated."""

    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    """Gravity, time step, cube mass, friction, the collision-box hairs and the solver
    iterations: the same material the stability check simulates (rad_core.sim.physics)."""
    table_half_extents: tuple[float, float, float] = (1.2, 1.2, 0.025)
    """Half size of the static table box (m); its top is z = 0, centred under `table_centre`."""
    table_centre: tuple[float, float] = (0.3, 0.0)
    """x, y of the table's centre (m); grown by `load_scene` if a scene reaches past it."""
    effector: str = 'hand'
    """What the arm carries on its flange (`cell.panda.EFFECTORS`): Franka's hand, or the vacuum gripper."""
    stud_substeps: int = 4
    """In a scene of studded bricks (``scene.studs``), every step of ``physics.time_step`` is simulated
    as this many Bullet steps, each that much shorter (`World.step`); 1: as other scenes. See
    `stud_solver_iterations`."""
    stud_solver_iterations: int = 50
    """...each with this many solver iterations (other scenes: ``physics.solver_iterations``).

    Why (measured, benchmarks/bench_statics_twin.py): studded bricks are small and light (a LEGO
    cell at a 16 mm pitch weighs 2.3 g) and stand in tall thin stacks; Bullet's iterative solver
    leaves their contacts (and the stud joints, which it does not warm-start) too soft at 1/240 s,
    so a stack a real one would hold rocks over: the stem of a T, 16 2 x 4 bricks in one column,
    falls within 0.4 s even without studs, and 21 of 193 structures the statics stand fell. A shorter
    step stiffens contacts and joints far more than more iterations do at the same cost (200
    iterations at 1/240 s: 5 of those 21 stand; 2 steps of 100: 13), and 4 steps of 50 iterations
    cost about 2.2 times one step of 100 (the solver is most of a step). The step is made shorter
    rather than Bullet's ``numSubSteps`` set: with sub-steps Bullet caps a motor's force as an impulse
    over the whole step, which would make the arm's and the fingers' force limits 4 times their
    value (user constraints, the stud joints and the grasp, are capped per sub-step either way)."""
    stud_sleep: float = 1e-2
    """In a scene of studded bricks, a brick whose squared speeds (linear in m/s, angular in rad/s,
    summed) stay under this for 2 s (Bullet's timeout) sleeps, with everything it touches or is joined
    to, until something awake touches that group or the twin moves one of its bricks (`World.wake`);
    0: never. Why: the built structure and the bricks waiting on the table are most of the bodies and
    all of the stud joints, and at the studded scene's short steps the solver works on all of them
    while the arm moves elsewhere (measured with the structures of benchmarks/bench_statics_twin.py
    standing, arm away: the letter T of 26 bricks 27.8 ms a step awake, 0.5 asleep; the tower of 186
    bricks 129 and 2.2 ms). Why so high: a joined brick at rest jitters (measured over 1 s: up to
    3.8 mm/s and 4.3 deg/s, the stud joints being soft), so at 1e-3 a wall of 54 bricks never slept.
    A brick that tips or slides speeds past it in a fraction of a second and stays awake; what the
    threshold lets sleep is creep slower than 0.1 m/s and 5.7 deg/s held for 2 s."""

    def __post_init__(self):
        panda.check_effector(self.effector)
        if not (math.isfinite(self.stud_sleep) and self.stud_sleep >= 0):
            raise RadError(f'world config stud_sleep: expected a squared speed >= 0, got {self.stud_sleep!r}')
        if not (isinstance(self.stud_substeps, int) and self.stud_substeps >= 1
                and isinstance(self.stud_solver_iterations, int) and self.stud_solver_iterations >= 1):
            raise RadError(f'world config stud_substeps, stud_solver_iterations: expected integers >= 1, got '
                           f'{self.stud_substeps!r}, {self.stud_solver_iterations!r}')
        if not all(math.isfinite(v) and v > 0 for v in self.table_half_extents):
            raise RadError(f'world config table_half_extents: expected positive sizes, got {self.table_half_extents!r}')


class World(ClientOwner):
    """Table, robot and blocks in a private DIRECT client.

    Not thread-safe; one World per thread or process. Use as a context manager
    or call `close` (`ClientOwner`).
    """

    def __init__(self, scene: Scene | None = None, config: WorldConfig = WorldConfig()):
        self.config = config
        p, cid = direct_client(config.physics)    # imports pybullet here: importing it prints a banner
        self._p, self.client = p, cid
        self.scene: Scene | None = None
        self.blocks: dict[str, int] = {}
        self.obstacles: dict[str, int] = {}     # the scene's obstacles (set-aside blocks), fixed bodies
        self._shapes: dict[tuple, tuple[BlockShape, list[float]]] = {}   # -> shape, RGBA
        self._inertial: dict[int, tuple[list, list]] = {}   # body -> inertial frame in body frame
        self._mass: dict[int, tuple[float, tuple]] = {}     # body -> (mass, principal inertia)
        self.parked: set[str] = set()           # feeder blocks not presented (static, out of the way)
        self.presented: str | None = None       # the feeder block put at the station last
        self.studs = StudJoints()               # studded bricks pressed home (`sim.clutch`)
        self._steps = 0
        self.substeps = 1                       # Bullet steps per step: `WorldConfig.stud_substeps` while studded
        self._iterations = config.physics.solver_iterations     # the solver's now (`_solver_for`)
        self.table = -1
        self._table_box = (tuple(config.table_centre), tuple(config.table_half_extents))
        self._make_table(*self._table_box)
        self.robot = panda.load_panda(cid, effector=config.effector)
        self.effector = config.effector
        self.joint_index: dict[str, int] = {}
        self.link_index: dict[str, int] = {}
        for j in range(p.getNumJoints(self.robot, physicsClientId=cid)):
            info = p.getJointInfo(self.robot, j, physicsClientId=cid)
            self.joint_index[info[1].decode()] = j
            self.link_index[info[12].decode()] = j
        self.joints = [self.joint_index[n] for n in JOINT_NAMES]   # pybullet indices, JOINT_NAMES order
        self._movable = [j for j in range(p.getNumJoints(self.robot, physicsClientId=cid))
                         if p.getJointInfo(self.robot, j, physicsClientId=cid)[2] != p.JOINT_FIXED]
        self.arm_joints = self.joints[:7]
        self.finger_joints = self.joints[7:]
        self.ee_link = self.link_index[panda.GRASP_TARGET_LINK]
        self.hand_link = self.link_index[panda.HAND_LINK]
        self.finger_links = tuple(self.link_index[n] for n in panda.FINGER_LINKS)
        self._base_on_table()
        for link in self.finger_links:
            p.changeDynamics(self.robot, link, lateralFriction=config.physics.lateral_friction, physicsClientId=cid)
        self.set_joint_positions(panda.HOME)
        if scene is not None:
            self.load_scene(scene)

    @property
    def pybullet(self):
        """The pybullet module, for calls this class has no method for: pass
        ``physicsClientId=world.client`` with each (there is no global client)."""
        return self._p

    # ---- building --------------------------------------------------------
    def _make_table(self, centre, half) -> None:
        p, cid = self._p, self.client
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=cid)
        visual = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half), rgbaColor=[*TABLE, 1],
                                     physicsClientId=cid)
        self.table = p.createMultiBody(0, shape, visual, basePosition=[centre[0], centre[1], -half[2]],
                                       physicsClientId=cid)
        p.changeDynamics(self.table, -1, lateralFriction=self.config.physics.lateral_friction, frictionAnchor=1,
                         physicsClientId=cid)

    def _fit_table(self, scene: Scene) -> None:
        """Grow the table when a scene reaches past its edge (rare: the default is 2.4 m)."""
        pts = [scene.unit_positions(b) for b in scene.blocks]
        pts += [np.vstack(t.bounds(scene.pitch)) for t in scene.targets]
        pts = np.vstack(pts + [np.zeros((1, 3))])
        (cx, cy), half = self._table_box
        lo, hi = np.array([cx - half[0], cy - half[1]]), np.array([cx + half[0], cy + half[1]])
        if np.all(pts[:, :2] > lo + 0.1) and np.all(pts[:, :2] < hi - 0.1):
            return
        lo = np.minimum(lo, pts[:, :2].min(axis=0) - 0.3)
        hi = np.maximum(hi, pts[:, :2].max(axis=0) + 0.3)
        centre, half = tuple((lo + hi) / 2), (*((hi - lo) / 2), half[2])
        p, cid = self._p, self.client
        p.removeBody(self.table, physicsClientId=cid)
        self._table_box = (centre, half)
        self._make_table(centre, half)
        self._base_on_table()

    def _base_on_table(self) -> None:
        """The base stands on the table: that contact is by design, never a collision."""
        p, cid = self._p, self.client
        p.setCollisionFilterPair(self.robot, self.table, -1, -1, 0, physicsClientId=cid)
        p.setCollisionFilterPair(self.robot, self.table, self.link_index['panda_link1'], -1, 0,
                                 physicsClientId=cid)

    def _shape(self, type_name: str, offsets: np.ndarray, pitch, clearance: float = 0.0,
               mass: float | None = None) -> tuple[BlockShape, list[float]]:
        """pitch: the unit, or the lattice's x, y, z pitch (`Scene.pitch`) where courses are not a unit high;
        mass: of one cell (kg) where not the physics config's cube (a stud system's bricks)."""
        key = (type_name, tuple(map(tuple, offsets.tolist())), tuple(np.atleast_1d(pitch).tolist()), clearance, mass)
        shape = self._shapes.get(key)
        if shape is None:
            unit = float(np.atleast_1d(pitch)[0])
            physics = self.config.physics if mass is None else replace(self.config.physics, cube_mass=mass)
            shape = (block_shape(self._p, self.client, offsets, pitch, physics, frame='anchor',
                                 visual_half=unit / 2 * 0.98, clearance=clearance),
                     [*type_colour(type_name), 1.0])
            self._shapes[key] = shape
        return shape

    def load_scene(self, scene: Scene) -> None:
        """(Re)create every block body at its scene pose (plus its measured offset, if the scene has
        one) and send the robot HOME.

        Block bodies of the previous scene are removed; constraints on them go with them.
        """
        p, cid = self._p, self.client
        for body in [*self.blocks.values(), *self.obstacles.values()]:
            p.removeBody(body, physicsClientId=cid)
        self.blocks.clear()
        self.obstacles.clear()
        self.studs.clear()
        self._inertial.clear()
        self._mass.clear()
        self.parked.clear()
        self.presented = None
        self._fit_table(scene)
        self._solver_for(scene)
        def add(type_name: str, position, quaternion, rgba=None) -> int:
            offsets = np.asarray(scene.block_types[type_name].offsets, dtype=float)
            shape, colour = self._shape(type_name, offsets, scene.unit if scene.studs is None else scene.pitch,
                                        scene.clearance, None if scene.studs is None else scene.studs.mass)
            body = add_block_body(p, cid, shape, list(position), list(quaternion), self.config.physics)
            p.changeVisualShape(body, -1, rgbaColor=rgba or colour, physicsClientId=cid)
            if scene.studs is not None and self.config.stud_sleep > 0:
                p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING,
                                 sleepThreshold=self.config.stud_sleep, physicsClientId=cid)
            self._inertial[body] = (shape.com.tolist(), shape.axes)
            self._mass[body] = (shape.mass, tuple(shape.inertia))
            return body

        for block in scene.blocks:
            # Where motion capture saw it, when a registration says so (`Scene.measured_offsets`).
            self.blocks[block.id] = add(block.type, np.asarray(block.position) + scene.offset(block.id),
                                        yaw_quaternion(block.yaw + scene.turn(block.id)))
        for o in scene.obstacles:
            # A block set aside by registration, where it lies: fixed (mass 0), there to be steered around.
            body = self.obstacles[o.id] = add(o.type, o.position, o.quaternion, [0.5, 0.5, 0.5, 1.0])
            p.changeDynamics(body, -1, mass=0.0, physicsClientId=cid)
        self.scene = scene
        for block_id in (scene.feeder.blocks if scene.feeder is not None else ()):
            self._park(block_id)
        self.set_block_velocities_zero()
        self.set_joint_positions(panda.HOME)

    def repose(self, scene: Scene) -> bool:
        """Where `scene` holds the bodies this world does (the same blocks of the same types, unit and
        clearance; no studs, obstacles or constraints: a later state of the scene loaded), put each block
        where `load_scene` would and send the robot HOME, without making the bodies again (a planner
        loads every state of a 250-block plan: making them took it 60 ms a state). False, and nothing
        done, where it does not."""
        old, p, cid = self.scene, self._p, self.client
        if (old is None or scene.studs is not None or old.studs is not None or scene.obstacles or self.obstacles
                or scene.unit != old.unit or scene.clearance != old.clearance or scene.block_types != old.block_types
                or [(b.id, b.type) for b in scene.blocks] != [(b.id, b.type) for b in old.blocks]
                or p.getNumConstraints(physicsClientId=cid)):
            return False
        self._fit_table(scene)
        self.scene = scene
        self.presented = None
        feeder = set(scene.feeder.blocks) if scene.feeder is not None else set()
        for block in scene.blocks:
            if block.id in feeder:
                self._park(block.id)
                continue
            if block.id in self.parked:
                self.unpark(block.id)
            self.set_block_pose(block.id, np.asarray(block.position) + scene.offset(block.id),
                                yaw_quaternion(block.yaw + scene.turn(block.id)))
        self.set_block_velocities_zero()
        self.set_joint_positions(panda.HOME)
        return True

    def _solver_for(self, scene: Scene) -> None:
        """The time step and solver iterations of a scene: studded bricks get `WorldConfig.stud_substeps`
        shorter steps with `WorldConfig.stud_solver_iterations`; other scenes the physics config's, as
        `direct_client` set them (untouched unless a studded scene changed them). Before any joint is
        made: Bullet turns a constraint's force cap into an impulse over the step current then (a motor's
        too, which `load_scene`'s HOME and the twin's every command set again)."""
        cfg = self.config
        substeps = cfg.stud_substeps if scene.studs is not None else 1
        iterations = cfg.stud_solver_iterations if scene.studs is not None else cfg.physics.solver_iterations
        if (substeps, iterations) == (self.substeps, self._iterations):
            return
        p, cid = self._p, self.client
        p.setTimeStep(cfg.physics.time_step / substeps, physicsClientId=cid)
        p.setPhysicsEngineParameter(numSolverIterations=int(iterations), physicsClientId=cid)
        self.substeps, self._iterations = substeps, iterations

    # ---- the feeder --------------------------------------------------------
    def _static(self, block_id: str) -> None:
        """Mark a feeder block parked and make it static (mass 0); its pose is the caller's business."""
        self._p.changeDynamics(self.blocks[block_id], -1, mass=0.0, physicsClientId=self.client)
        self.parked.add(block_id)

    def _park(self, block_id: str) -> None:
        self._static(block_id)
        self.set_block_pose(block_id, (float(self.blocks[block_id]), 0.0, PARK_Z))

    def unpark(self, block_id: str) -> None:
        """A parked feeder block becomes a body like any other (where it is; move it next)."""
        self._dynamic(self.blocks[block_id])
        self.parked.discard(block_id)
        self.wake(block_id)

    def _dynamic(self, body: int) -> None:
        """A block body made static (mass 0) gets its mass and exact inertia back: Bullet recomputes the
        inertia from the collision shape when only the mass is set, which is not the block's."""
        mass, inertia = self._mass[body]
        self._p.changeDynamics(body, -1, mass=mass, localInertiaDiagonal=inertia, physicsClientId=self.client)

    @contextmanager
    def asleep(self, block_ids, robot: bool = True) -> Iterator[None]:
        """These blocks (and the robot) sleep inside the block: Bullet neither moves them nor solves their
        contacts with the table (a settling step of a heap of blocks at rest costs a tenth), and wakes
        them, with everything they touch, when a body that moves touches them. For bodies at rest.

        After it they are awake and cannot sleep, as pybullet makes bodies, with one trace left: Bullet
        keeps their collision objects marked asleep until its next step, which therefore does not move
        them (a velocity set before it is lost; measured: a block put in the air after a settle falls
        one step late). The planning twin steps only while settling, where this block puts them to sleep
        again, or moves them into a structure that then starts to settle one 1/240 s step later."""
        p, cid = self._p, self.client
        bodies = [self.blocks[b] for b in block_ids if b not in self.parked] + ([self.robot] if robot else [])
        for body in bodies:
            p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING, physicsClientId=cid)
            p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_SLEEP, physicsClientId=cid)
        try:
            yield
        finally:
            for body in bodies:
                p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=cid)
                p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING,
                                 physicsClientId=cid)

    def at_station(self, block_id: str) -> bool:
        """Whether a feeder block lies presented at the station, not taken (within half a unit)."""
        if block_id in self.parked or self.scene is None:
            return False
        return self.scene.at_station(block_id, self.block_pose(block_id)[0])

    def return_to_feeder(self, block_id: str) -> None:
        """Park a feeder block again (a presented block the robot did not take)."""
        if block_id not in self.parked:
            self._park(block_id)
        if self.presented == block_id:
            self.presented = None

    def present(self, block_id: str) -> bool:
        """The feeder puts a block at its station (its scene pose); a block it presented before that
        still lies there goes back. Returns whether anything moved (False: already presented, or a
        block on the table). RadError for an unknown block."""
        self._body(block_id)
        if block_id not in self.parked:
            return False
        scene = self.scene
        back = self.presented
        if back is not None and self.at_station(back):
            self._park(back)
        self.unpark(block_id)
        block = scene.block(block_id)
        self.set_block_pose(block_id, block.position, yaw_quaternion(block.yaw))
        self.presented = block_id
        return True

    # ---- blocks ----------------------------------------------------------
    def _body(self, block_id: str) -> int:
        try:
            return self.blocks[block_id]
        except KeyError:
            raise RadError(f'unknown block id {block_id!r}') from None

    def block_pose(self, block_id: str) -> tuple[np.ndarray, np.ndarray]:
        """Anchor unit centre (3,) and orientation quaternion x, y, z, w (4,) in the world."""
        p, cid = self._p, self.client
        body = self._body(block_id)
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        ipos, iorn = p.invertTransform(*self._inertial[body])
        pos, orn = p.multiplyTransforms(pos, orn, ipos, iorn)
        return np.array(pos), np.array(orn)

    def set_block_pose(self, block_id: str, position, quaternion=(0.0, 0.0, 0.0, 1.0)) -> None:
        """Teleport a block (anchor pose) and stop it."""
        p, cid = self._p, self.client
        body = self._body(block_id)
        pos, orn = p.multiplyTransforms(list(map(float, position)), list(map(float, quaternion)),
                                        *self._inertial[body])
        p.resetBasePositionAndOrientation(body, pos, orn, physicsClientId=cid)
        p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=cid)
        self.wake(block_id)

    def wake(self, block_id: str) -> None:
        """Wake a block that may sleep (`WorldConfig.stud_sleep`), and with it what it touches: a body
        teleported or pushed by the twin moves on the next step, not when something bumps it."""
        self._p.changeDynamics(self._body(block_id), -1, activationState=self._p.ACTIVATION_STATE_WAKE_UP,
                               physicsClientId=self.client)

    def in_inertial_frame(self, block_id: str, point) -> list[float]:
        """A point given in the block's own frame (its anchor unit's centre, its yaw) in the frame Bullet
        keeps the body in (its inertial frame): where constraints on the body are fixed."""
        p = self._p
        ipos, iorn = p.invertTransform(*self._inertial[self._body(block_id)])
        local, _ = p.multiplyTransforms(ipos, iorn, [float(v) for v in point], [0, 0, 0, 1])
        return list(local)

    def unit_centres(self, block_id: str) -> np.ndarray:
        """World centres (n, 3) of a block's units where it is now."""
        position, quaternion = self.block_pose(block_id)
        offsets = np.asarray(self.scene.block_types[self.scene.block(block_id).type].offsets, dtype=float)
        return position + (offsets * self.scene.pitch) @ matrix_from_quaternion(quaternion).T

    def set_block_velocities_zero(self) -> None:
        for body in self.blocks.values():
            self._p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)

    # ---- robot -----------------------------------------------------------
    def joint_positions(self) -> np.ndarray:
        """(9,) joint positions in JOINT_NAMES order."""
        states = self._p.getJointStates(self.robot, self.joints, physicsClientId=self.client)
        return np.array([s[0] for s in states])

    def joint_velocities(self) -> np.ndarray:
        states = self._p.getJointStates(self.robot, self.joints, physicsClientId=self.client)
        return np.array([s[1] for s in states])

    def set_joint_positions(self, q, hold: bool = True) -> None:
        """Teleport the robot to q, (9,) or (7,) arm only, with zero velocity.

        hold: also make q the position-control target, so stepping keeps the
        robot there instead of letting it sag under gravity.
        """
        p, cid = self._p, self.client
        q = np.asarray(q, dtype=float).ravel()
        if len(q) not in (7, 9) or not np.all(np.isfinite(q)):
            raise RadError(f'expected 7 or 9 finite joint positions, got {len(q)}')
        joints = self.joints[:len(q)]
        # One reset command for all joints (Bullet's CMD_INIT_POSE, as resetJointState sends one per
        # joint): the same joint positions, zero velocities and link transforms, measured bit for bit
        # (tests/core/test_world.py), at a sixth of the cost of nine commands.
        p.resetJointStatesMultiDof(self.robot, joints, q.reshape(-1, 1).tolist(), [[0.0]] * len(joints),
                                   physicsClientId=cid)
        if hold:
            p.setJointMotorControlArray(self.robot, joints, p.POSITION_CONTROL, targetPositions=q.tolist(),
                                        physicsClientId=cid)

    def link_pose(self, link: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World pose of a robot link frame (default: the grasp target between the fingertips)."""
        link = self.ee_link if link is None else link
        state = self._p.getLinkState(self.robot, link, computeForwardKinematics=True,
                                     physicsClientId=self.client)
        return np.array(state[4]), np.array(state[5])

    # ---- simulation ------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Simulate n steps of ``physics.time_step`` (each `substeps` Bullet steps: several in a studded
        scene, `WorldConfig.stud_substeps`); studs pulled off let go (`sim.clutch`, checked every few steps)."""
        p, cid, substeps = self._p, self.client, self.substeps
        for _ in range(int(n)):
            for _ in range(substeps):
                p.stepSimulation(physicsClientId=cid)
            self._steps += 1
            if self.studs.studs and self._steps % STUD_CHECK_STEPS == 0:
                self.studs.check(self)

    def _snapshot(self) -> tuple:
        p, cid = self._p, self.client
        n = p.getNumJoints(self.robot, physicsClientId=cid)
        joints = [s[:2] for s in p.getJointStates(self.robot, range(n), physicsClientId=cid)]
        bodies = {body: (p.getBasePositionAndOrientation(body, physicsClientId=cid),
                         p.getBaseVelocity(body, physicsClientId=cid)) for body in self.blocks.values()}
        constraints = {p.getConstraintUniqueId(i, physicsClientId=cid)
                       for i in range(p.getNumConstraints(physicsClientId=cid))}
        return joints, bodies, constraints, frozenset(self.parked), self.presented, self.studs.state()

    def _restore(self, snap: tuple) -> None:
        p, cid = self._p, self.client
        joints, bodies, constraints, parked, self.presented, studs = snap
        if parked != self.parked:
            for block_id in self.parked - parked:
                self.unpark(block_id)
            for block_id in parked - self.parked:
                self._static(block_id)          # its pose is restored below
        # The movable joints in one reset command; fixed joints have no state to restore.
        p.resetJointStatesMultiDof(self.robot, self._movable, [[joints[j][0]] for j in self._movable],
                                   [[joints[j][1]] for j in self._movable], physicsClientId=cid)
        for body, ((pos, orn), (lin, ang)) in bodies.items():
            p.resetBasePositionAndOrientation(body, pos, orn, physicsClientId=cid)
            p.resetBaseVelocity(body, lin, ang, physicsClientId=cid)
            p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=cid)
        now = {p.getConstraintUniqueId(i, physicsClientId=cid)
               for i in range(p.getNumConstraints(physicsClientId=cid))}
        for c in now - constraints:
            p.removeConstraint(c, physicsClientId=cid)
        if constraints - now:
            raise RadError('a constraint was removed inside World.preserved(); it cannot be restored')
        self.studs.restore(self, studs)

    def save(self) -> 'WorldState':
        """Everything that decides how this world goes on: joints, block poses and
        velocities, constraints, and Bullet's own state (contact cache included), so
        restoring it and simulating replays bit-identically. The Bullet state is freed
        when the WorldState is garbage-collected (or by `WorldState.free`)."""
        return WorldState(self, self._snapshot(), self._p.saveState(physicsClientId=self.client))

    def restore(self, state: 'WorldState') -> None:
        """Go back to a state `save` returned (it stays valid for further restores)."""
        if state.world is not self:
            raise RadError('World.restore: the state was saved from another world')
        if state.bullet < 0:
            raise RadError('World.restore: the state was freed')
        self._restore(state.snap)
        self._p.restoreState(stateId=state.bullet, physicsClientId=self.client)

    @contextmanager
    def joints_kept(self) -> Iterator[World]:
        """The robot's joints (positions and velocities) are put back on exit; for callers that move
        nothing else (IK). A fraction of `preserved`'s cost, which also puts back every block."""
        p, cid = self._p, self.client
        states = p.getJointStates(self.robot, self._movable, physicsClientId=cid)
        try:
            yield self
        finally:
            p.resetJointStatesMultiDof(self.robot, self._movable, [[s[0]] for s in states], [[s[1]] for s in states],
                                       physicsClientId=cid)

    @contextmanager
    def preserved(self, exact: bool = False) -> Iterator[World]:
        """Everything in the block is undone on exit: joints, block poses and
        velocities, constraints added inside.

        The default restores by hand (cheap, tens of microseconds for a scene).
        exact=True also uses saveState/restoreState (about 1-10 ms more) so
        Bullet's contact cache is restored and a later simulation replays
        bit-identically. Bodies must not be added or removed inside.
        """
        snap = self._snapshot()
        state = self._p.saveState(physicsClientId=self.client) if exact else None
        try:
            yield self
        finally:
            self._restore(snap)
            if state is not None:
                self._p.restoreState(stateId=state, physicsClientId=self.client)
                self._p.removeState(state, physicsClientId=self.client)


class WorldState:
    """A saved `World` (see World.save). Bodies must not be added or removed between
    save and restore; loading another scene invalidates it."""

    def __init__(self, world: World, snap: tuple, bullet: int):
        self.world, self.snap, self.bullet = world, snap, bullet

    def free(self) -> None:
        if self.bullet >= 0 and self.world.client >= 0:
            self.world.pybullet.removeState(self.bullet, physicsClientId=self.world.client)
        self.bullet = -1

    def __del__(self):
        try:
            self.free()
        except Exception:  # noqa: BLE001 - the client may be gone at interpreter exit
            pass


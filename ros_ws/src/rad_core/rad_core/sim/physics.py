"""Physical stability of a structure once a new block is added (PyBullet).

The MDP asks this after its geometric prune (`support.any_support`): every
placed block and the new one are put exactly at their grid poses, gravity acts,
and we watch what moves. The placement is invalid when the new block moves or
turns beyond a small tolerance (it slides, tips or falls), or when a block
already in the structure does (it was knocked over or dragged along: the
structure is destroyed, the predecessor's 1 cm rule).

Verdict: the structure stands unless a tolerance breaks within ``max_steps``
(1 s); stepping stops early once everything is at rest. Stable placements in
the benchmark's random structures move at most 0.8 mm and turn at most 0.6 deg
(p99 0.3 mm, 0.3 deg), against tolerances of 2.5 mm and 3 deg. A block whose
centre of mass is outside its support can still stand by wedging or hooking
against a neighbour (an S4 with its step around a column's top corner): rigid
bodies with friction 1 do hold there, and so does this check.

Choices, each measured (numbers at the default 5 cm unit; see
``benchmarks/bench_physics.py`` and tests/core/test_physics.py):

- Scale. Rigid blocks with Coulomb friction stand or fall whatever their size
  (statics has no length scale), so every structure is simulated with
  ``sim_unit`` cubes, where Bullet's contact tolerances are tuned, and lengths
  are reported back in the caller's millimetres. Tolerances are fractions of a
  unit for the same reason.
- Bodies. One compound rigid body per block (unit boxes, maximal coordinates),
  with its frame at the centre of mass along the principal axes and the exact
  polycube inertia: Bullet would take the inertia of the bounding box, wrong
  for an L. `block_shape` and `add_block_body` build them, here and in the
  twin's world (`rad_core.sim.world`, which keeps the block's own frame).
- Contact geometry. Bullet's box-box test reports nothing for boxes that only
  touch or are apart, so a block placed a hair above its support first falls
  into it (0.3-0.5 mm per layer: all eight cubes of a tower dropped 3.6 mm and
  swayed). Boxes are therefore a hair taller than a unit (``overlap``) so each
  layer starts in contact with the one below, and a hair narrower
  (``side_gap``) so side-by-side neighbours start apart and cannot pin each
  other by friction. The table is a big static box, not a plane: a box on a
  plane starts with one contact point and spins on its first step. A centre
  of mass exactly over an edge lies ``side_gap`` beyond the narrowed support
  and tips (past 3 deg after about 0.3 s): counted as unstable, as a real
  placement that precise would be.
- Clearance. A scene's ``clearance`` (`rad_core.domain.scene`) sets the outer side
  faces of every block back by half of it, on top of the hair; inner faces,
  tops and bottoms stay, so a block is one solid and stacks as before. The
  stability check gets it per call (the MDP passes its scene's).
- Solver. With PyBullet's default 50 iterations and no friction anchors, a
  load on one end of a balanced seesaw creeps at 2-3 mm/s; with 10 the seesaw
  collapses. 100 iterations with friction anchors bring it to rest (under
  0.05 mm/s).
- Speed. One DIRECT client per instance, created on first use and kept: the
  table stays, collision shapes are cached per block shape, and only block
  bodies are created and removed per call (0.07 ms a block; resetSimulation
  and rebuilding would cost about 0.4 ms more per call). Stepping stops as soon
  as a tolerance breaks (plus ``explain_steps`` to word the reason), or once
  every block has been at rest for a few checks.
- Determinism. Overlapping pairs are sorted, bodies are created in argument
  order and removed after each call, so no contact state survives a call: the
  same question gets the bit-identical answer whatever was asked before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Self

import numpy as np

from rad_core.domain.blocks import unit_boxes
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion, quaternion_from_matrix, rotation_angle_deg


@dataclass(frozen=True)
class PhysicsConfig:
    """How the stability check simulates and what it tolerates.

    Lengths are in units (fractions of a cube edge): at the default 5 cm unit,
    0.01 unit is 0.5 mm.
    """

    time_step: float = 1.0 / 240.0
    """Seconds per step; PyBullet's default, the rate its solver is tuned for."""
    gravity: float = 9.81
    """Magnitude of gravity along -z, m/s^2."""
    cube_mass: float = 0.1
    """Mass of one unit cube (kg); a block weighs its number of cubes times this."""
    lateral_friction: float = 1.0
    """Coulomb friction coefficient of blocks and table."""
    sim_unit: float = 0.05
    """Cube edge the structure is simulated at (m); the verdict does not depend on it."""
    side_gap: float = 0.002
    """Collision boxes are this much narrower on each side face (0.1 mm)."""
    overlap: float = 0.0002
    """...and this much taller on top and bottom (10 um): layers start in contact."""
    solver_iterations: int = 100
    """Constraint solver iterations per step; 50 lets off-centre loads creep."""
    max_steps: int = 240
    """Longest simulation (1 s). A centre of mass exactly over an edge, the slowest
    fall, tips past ``new_tilt_deg`` after about 0.3 s."""
    min_steps: int = 24
    """No verdict of rest before this many steps (0.1 s): a block that has only
    begun to tip still turns slower than ``rest_spin_deg`` in its first 10 steps."""
    check_every: int = 4
    """Poses and speeds are read every this many steps."""
    rest_checks: int = 3
    """At rest after this many checks in a row with every block below the rest speeds."""
    rest_speed: float = 0.02
    """Rest speed (units/s; 1 mm/s). Most stable structures get below it within
    0.1-0.4 s; the rare tall stack that keeps buzzing runs to ``max_steps``."""
    rest_spin_deg: float = 1.0
    """Rest turning rate (deg/s)."""
    new_move: float = 0.05
    """The new block may move at most this far (2.5 mm, any of its cube centres)."""
    new_tilt_deg: float = 3.0
    """...and turn at most this much."""
    placed_move: float = 0.2
    """A placed block moving this far means the structure is destroyed (1 cm,
    the predecessor's rule)."""
    placed_tilt_deg: float = 3.0
    """A placed block turning this much means the structure gave way."""
    explain_steps: int = 24
    """Once the new block has failed, keep stepping at most this long (0.1 s) to see
    whether placed blocks go too, for the reason; the verdict is settled already,
    so 0 saves a little time where nobody reads reasons."""

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise RadError(f'physics config {f.name}: expected a finite number >= 0, got {value!r}')
        for name in ('time_step', 'gravity', 'cube_mass', 'sim_unit', 'solver_iterations',
                     'max_steps', 'check_every', 'rest_checks'):
            if getattr(self, name) <= 0:
                raise RadError(f'physics config {name}: must be > 0')
        if self.side_gap >= 0.25 or self.overlap >= 0.05:
            raise RadError('physics config: side_gap and overlap are meant to be hairs (< 0.25, < 0.05 unit)')


def polycube_inertia(offsets: np.ndarray, edge, cube_mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass and inertia tensor about it of cubes at integer offsets (edge in m; or the
    lattice's x, y, z pitch, `Scene.pitch`, for boxes of a stud system's courses)."""
    pts = np.asarray(offsets, dtype=float) * edge
    com = pts.mean(axis=0)
    d = pts - com
    if np.ndim(edge) == 0:
        own = cube_mass * edge ** 2 / 6.0                 # a solid cube about its own centre
        return com, np.eye(3) * (own * len(d) + cube_mass * (d ** 2).sum()) - cube_mass * d.T @ d
    sq = np.asarray(edge, dtype=float) ** 2               # a solid box about its own centre
    own = cube_mass / 12.0 * np.array([sq[1] + sq[2], sq[0] + sq[2], sq[0] + sq[1]])
    return com, np.diag(own * len(d)) + np.eye(3) * cube_mass * (d ** 2).sum() - cube_mass * d.T @ d


def principal_frame(offsets: np.ndarray, edge, cube_mass: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre of mass, principal moments and principal axes (columns, right-handed) of a polycube."""
    com, tensor = polycube_inertia(offsets, edge, cube_mass)
    moments, axes = np.linalg.eigh(tensor)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return com, moments, axes


def direct_client(config: PhysicsConfig):
    """(the pybullet module, a new DIRECT client id) set up with the config's gravity, time step and
    solver: the stability check's client and the twin world's are the same material."""
    import pybullet as p  # here, not at the top: importing it prints a banner on stdout
    cid = p.connect(p.DIRECT)
    if cid < 0:
        raise RuntimeError('cannot start a PyBullet DIRECT client')
    p.setGravity(0, 0, -config.gravity, physicsClientId=cid)
    p.setTimeStep(config.time_step, physicsClientId=cid)
    p.setPhysicsEngineParameter(numSolverIterations=int(config.solver_iterations),
                                deterministicOverlappingPairs=1, physicsClientId=cid)
    return p, cid


class ClientOwner:
    """The lifetime of an object that owns one PyBullet client (`direct_client`), kept as the
    pybullet module ``_p`` and the client id ``client`` (-1: none): `close` disconnects it. A
    context manager that closes on exit, and closed when collected. Shared by the stability check
    and the twin's `World`."""

    _p = None
    client = -1     # until connected (also for an instance whose __init__ failed: close has nothing to do)

    def close(self) -> None:
        """Disconnect the client."""
        if self.client >= 0:
            self._p.disconnect(physicsClientId=self.client)
        self.client = -1

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:         # at interpreter exit pybullet may be gone already
            pass


@dataclass(frozen=True)
class BlockShape:
    """The PyBullet shapes of one polycube block, and its mass properties, to create bodies from.

    The body frame is either the inertial frame itself (``frame='principal'``: at the centre of
    mass along the principal axes, so a body stands axis-aligned when turned by `axes`) or the
    block's own frame (``frame='anchor'``: the anchor cube's centre, the type's axes; bodies then
    get `com` and `axes` as their separate inertial frame).
    """

    frame: str
    collision: int            # compound of one box per unit cube (merged beyond 16), in the body frame
    visual: int               # compound of visual boxes in the body frame, or -1
    mass: float
    inertia: list[float]      # principal moments, kg m^2
    com: np.ndarray           # centre of mass from the anchor cube's centre, block axes, m
    axes: list[float]         # principal axes in the block's axes, as a quaternion (x, y, z, w)


def block_shape(p, client: int, offsets: np.ndarray, edge, config: PhysicsConfig,
                frame: str = 'principal', visual_half: float | None = None,
                clearance: float = 0.0) -> BlockShape:
    """Shapes and mass properties of a block of cubes at integer `offsets` with this edge (m; or
    boxes of the lattice's x, y, z pitch, `Scene.pitch`, where courses are not a unit high).

    Collision boxes are a hair narrower (``config.side_gap``) and taller (``config.overlap``)
    than a cube, the mass is ``config.cube_mass`` per cube, the inertia the exact polycube's (see
    the module docstring). clearance: the scene's (a fraction of the edge, `rad_core.domain.scene`):
    the block's outer side faces are set back by half of it, its inner faces, top and bottom
    stay (`rad_core.domain.blocks.unit_boxes`), and visual boxes get the same set-back; the mass
    properties stay the full cubes' (the predecessor's filled blocks are that much lighter,
    which no verdict here depends on). visual_half: half edge of visual boxes at the cube
    centres (anchor frame only); None for no visual shape. Shapes live in `client` and can be
    shared by bodies.
    """
    if frame not in ('principal', 'anchor'):
        raise RadError(f"block_shape: frame must be 'principal' or 'anchor', got {frame!r}")
    offsets = np.asarray(offsets)
    n = len(offsets)
    com, moments, axes = principal_frame(offsets, edge, config.cube_mass)
    if not (math.isfinite(clearance) and 0 <= clearance < 0.5):
        raise RadError(f'block_shape: clearance must be in [0, 0.5) of the edge, got {clearance!r}')
    pitch = edge
    edge, course = (float(edge), float(edge)) if np.ndim(edge) == 0 else (float(edge[0]), float(edge[2]))
    side, height = edge / 2 - config.side_gap * edge, course / 2 + config.overlap * edge
    shift, half = unit_boxes(offsets, side, height, clearance * edge / 2)
    centres, half = compound_boxes(offsets * pitch + shift, half)
    m = len(centres)
    boxes = {'halfExtents': half.tolist()}
    if frame == 'principal':
        # Boxes in the principal frame, turned back so they are axis-aligned in the world.
        boxes.update(collisionFramePositions=((centres - com) @ axes).tolist(),
                     collisionFrameOrientations=[quaternion_from_matrix(axes.T)] * m)
    else:
        boxes.update(collisionFramePositions=centres.tolist())
    collision = p.createCollisionShapeArray([p.GEOM_BOX] * m, **boxes, physicsClientId=client)
    visual = -1
    if visual_half is not None:
        if frame != 'anchor':
            raise RadError("block_shape: visual boxes are made in the 'anchor' frame only")
        vshift, vhalf = unit_boxes(offsets, visual_half, visual_half * course / edge, clearance * edge / 2)
        vcentres, vhalf = compound_boxes(offsets * pitch + vshift, vhalf)
        visual = p.createVisualShapeArray([p.GEOM_BOX] * len(vcentres), halfExtents=vhalf.tolist(),
                                          visualFramePositions=vcentres.tolist(), physicsClientId=client)
    return BlockShape(frame, collision, visual, config.cube_mass * n, moments.tolist(), com,
                      quaternion_from_matrix(axes))


MAX_COMPOUND_BOXES = 16
"""The most children a PyBullet compound shape keeps: createCollisionShapeArray and
createVisualShapeArray silently drop the rest (pybullet 3.2.x, `MAX_COMPOUND_COLLISION_SHAPES`)."""


def compound_boxes(centres: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The boxes (centres, half extents (n, 3)) as at most `MAX_COMPOUND_BOXES` boxes that fill the same
    space: where there are more (a brick of many units: a LEGO 2x4 brick is 24), boxes that share their
    extent along two axes and meet or nearly meet (within the gap a unit's box leaves to the next) along
    the third are merged, until no two are left to merge; at most 16 boxes, unchanged. RadError where a
    block still needs more (a shape too ragged for one PyBullet body)."""
    centres, half = np.asarray(centres, dtype=float), np.asarray(half, dtype=float)
    if len(centres) <= MAX_COMPOUND_BOXES:
        return centres, half
    boxes = [(tuple(a), tuple(b)) for a, b in zip((centres - half).tolist(), (centres + half).tolist())]
    gap = 0.2 * float(np.min(half))          # unit boxes stand apart by a hair (side_gap), never by this much
    while True:
        count = len(boxes)
        for axis in range(3):
            rows: dict = {}
            for box in boxes:       # boxes that share their extent along the other two axes, in a row
                key = tuple(round(v, 9) for k in range(3) if k != axis for v in (box[0][k], box[1][k]))
                rows.setdefault(key, []).append(box)
            boxes = []
            for row in rows.values():
                row.sort(key=lambda b: b[0][axis])
                run_lo, run_hi = list(row[0][0]), list(row[0][1])
                for b_lo, b_hi in row[1:]:
                    if b_lo[axis] - run_hi[axis] <= gap:
                        run_hi[axis] = max(run_hi[axis], b_hi[axis])
                    else:
                        boxes.append((tuple(run_lo), tuple(run_hi)))
                        run_lo, run_hi = list(b_lo), list(b_hi)
                boxes.append((tuple(run_lo), tuple(run_hi)))
        if len(boxes) == count:
            break
    lo, hi = [np.array(b[0]) for b in boxes], [np.array(b[1]) for b in boxes]
    if len(lo) > MAX_COMPOUND_BOXES:
        raise RadError(f'a block of {len(centres)} units needs {len(lo)} boxes, more than the '
                       f'{MAX_COMPOUND_BOXES} a PyBullet body holds: split it into blocks of simpler shapes')
    lo, hi = np.array(lo), np.array(hi)
    return (lo + hi) / 2, (hi - lo) / 2


def add_block_body(p, client: int, shape: BlockShape, position, orientation, config: PhysicsConfig,
                   maximal_coordinates: bool = False, damping: float | None = None) -> int:
    """A body of this shape whose body frame (see `BlockShape`) is at position, orientation (x, y, z, w).

    Its dynamics get the shape's mass and exact principal inertia, ``config.lateral_friction``
    and friction anchors; damping (linear and angular) None keeps PyBullet's default.
    """
    extra = {}
    if shape.frame == 'anchor':
        extra.update(baseInertialFramePosition=shape.com.tolist(), baseInertialFrameOrientation=shape.axes)
    if maximal_coordinates:
        extra['useMaximalCoordinates'] = True
    body = p.createMultiBody(shape.mass, shape.collision, shape.visual, basePosition=position,
                             baseOrientation=orientation, **extra, physicsClientId=client)
    dynamics = {} if damping is None else {'linearDamping': damping, 'angularDamping': damping}
    # mass is repeated on purpose: for a maximal-coordinates body, setting the inertia alone zeroes it.
    p.changeDynamics(body, -1, mass=shape.mass, localInertiaDiagonal=shape.inertia,
                     lateralFriction=config.lateral_friction, frictionAnchor=1, **dynamics, physicsClientId=client)
    return body


BLOCK_PLAY = 0.01
"""Play of a block between its neighbours (fraction of a unit per side face: 0.5 mm at 5 cm, 0.2 mm at
2 cm), as real blocks have it: the twin's blocks (`sim.twin`) and the stability check's. The planning
worlds (GAMP, the MDP's robot env) keep the hairline `PhysicsConfig.side_gap` (0.1 mm at 5 cm)."""


class PhysicsStability(ClientOwner):
    """The MDP's `StabilityCheck`, backed by PyBullet (see the module docstring).

    ``check(unit, placed, new, clearance=0.0)`` returns (True, '') when the
    structure stands, else (False, reason), e.g. 'new block tipped 4 deg' or
    'placed block 1 moved 12 mm (structure destroyed)', where 1 indexes `placed`.
    clearance: the scene's, a fraction of the unit (see `block_shape`). Not
    thread-safe: give each thread or process its own instance.

    config: by default `PhysicsConfig` with the blocks' play (`BLOCK_PLAY`) as the side gap, the twin's:
    with the hairline gap, T4s corbelled out over the wheels of bench_large's car design at 2 cm held by
    friction against their neighbours, and the check said the structure stands where the twin, its blocks
    with play, let three of them fall, and the next steps' blocks with them (26 blocks lost).
    """

    def __init__(self, config: PhysicsConfig | None = None):
        self.config = PhysicsConfig(side_gap=BLOCK_PLAY) if config is None else config
        self._p = None            # the pybullet module, imported on first use
        self.client = -1          # connected on first use
        self._shapes: dict[tuple, BlockShape] = {}
        self._bodies: list[int] = []

    # ---- lifetime --------------------------------------------------------
    def close(self) -> None:
        """Disconnect the client; the next check connects a fresh one."""
        super().close()
        self._shapes.clear()
        self._bodies.clear()

    def _connect(self) -> None:
        cfg = self.config
        p, cid = direct_client(cfg)
        self._p, self.client = p, cid
        half = 100.0 * cfg.sim_unit
        table = p.createCollisionShape(p.GEOM_BOX, halfExtents=[half, half, half], physicsClientId=cid)
        ground = p.createMultiBody(0, table, basePosition=[0, 0, -half], physicsClientId=cid)
        p.changeDynamics(ground, -1, lateralFriction=cfg.lateral_friction, frictionAnchor=1, physicsClientId=cid)

    # ---- the check -------------------------------------------------------
    def __call__(self, unit: float, placed: list[np.ndarray], new: np.ndarray,
                 clearance: float = 0.0, course: float | None = None) -> tuple[bool, str]:
        """course: the lattice's z pitch (m) where it is not the unit (a stud system's, `Scene.course`)."""
        if not (math.isfinite(unit) and unit > 0):
            raise RadError(f'unit must be a positive length, got {unit!r}')
        if not (math.isfinite(clearance) and 0 <= clearance < 0.5):
            raise RadError(f'clearance must be in [0, 0.5) of a unit, got {clearance!r}')
        blocks = [np.asarray(b, dtype=float).reshape(-1, 3) for b in placed]
        blocks.append(np.asarray(new, dtype=float).reshape(-1, 3))
        if any(len(b) == 0 for b in blocks):
            raise RadError('every block needs at least one unit cube')
        if self.client < 0:
            self._connect()
        cubes = [b * (self.config.sim_unit / unit) for b in blocks]
        pitch = self.config.sim_unit if course is None else self.config.sim_unit * np.array([1.0, 1.0, course / unit])
        try:
            for c in cubes:
                self._bodies.append(self._add_body(c, clearance, pitch))
            return self._simulate(cubes, unit)
        finally:
            for body in self._bodies:
                self._p.removeBody(body, physicsClientId=self.client)
            self._bodies.clear()

    def _shape(self, offsets: np.ndarray, clearance: float, pitch) -> BlockShape:
        key = (tuple(map(tuple, offsets.tolist())), clearance, tuple(np.atleast_1d(pitch).tolist()))
        shape = self._shapes.get(key)
        if shape is None:
            shape = block_shape(self._p, self.client, offsets, pitch, self.config, clearance=clearance)
            self._shapes[key] = shape
        return shape

    def _add_body(self, cubes: np.ndarray, clearance: float, pitch) -> int:
        """A block whose unit cells have these world centres (simulation scale, the lattice's `pitch`)."""
        cfg = self.config
        shape = self._shape(np.round((cubes - cubes[0]) / pitch).astype(np.int64), clearance, pitch)
        return add_block_body(self._p, self.client, shape, (cubes[0] + shape.com).tolist(), shape.axes, cfg,
                              maximal_coordinates=True, damping=0.0)

    def _simulate(self, cubes: list[np.ndarray], unit: float) -> tuple[bool, str]:
        p, cid, cfg = self._p, self.client, self.config
        u, bodies = cfg.sim_unit, self._bodies
        new = len(bodies) - 1
        start = [p.getBasePositionAndOrientation(b, physicsClientId=cid) for b in bodies]
        origin = [np.asarray(pos) for pos, _ in start]
        arms = [c - o for c, o in zip(cubes, origin)]                  # cube centres from the COM
        unturn = [matrix_from_quaternion(q).T for _, q in start]
        rest_v, rest_w = cfg.rest_speed * u, math.radians(cfg.rest_spin_deg)
        calm, failed, explain_until = 0, '', 0
        for step in range(1, int(cfg.max_steps) + 1):
            p.stepSimulation(physicsClientId=cid)
            if step % cfg.check_every and step != cfg.max_steps:
                continue
            motion = []
            for i, b in enumerate(bodies):
                pos, q = p.getBasePositionAndOrientation(b, physicsClientId=cid)
                turn = matrix_from_quaternion(q) @ unturn[i]
                shift = arms[i] @ turn.T + (np.asarray(pos) - origin[i]) - arms[i]
                motion.append((float(np.sqrt((shift ** 2).sum(axis=1)).max()), rotation_angle_deg(turn)))
            destroyed = self._destroyed(motion[:new], unit)
            if destroyed:
                return False, f'{failed}; {destroyed} too' if failed else f'{destroyed} (structure destroyed)'
            if not failed:
                failed = self._new_failed(motion[new], unit)
                explain_until = step + cfg.explain_steps
            if failed:
                # The verdict is in; watch a little longer in case the structure goes too.
                if step >= explain_until:
                    return False, failed
                continue
            if all(math.hypot(*v) <= rest_v and math.hypot(*w) <= rest_w
                   for v, w in (p.getBaseVelocity(b, physicsClientId=cid) for b in bodies)):
                calm += 1
                if calm >= cfg.rest_checks and step >= cfg.min_steps:
                    return True, ''
            else:
                calm = 0
        if failed:
            return False, failed
        # Still jittering (a tall stack can buzz at 1-3 mm/s for good), yet nothing broke a
        # tolerance in max_steps: it stands.
        return True, ''

    def _destroyed(self, motion: list[tuple[float, float]], unit: float) -> str:
        cfg = self.config
        for i, (move, tilt) in enumerate(motion):
            if tilt > cfg.placed_tilt_deg:
                return f'placed block {i} tipped {tilt:.1f} deg'
            if move >= cfg.placed_move * cfg.sim_unit:
                return f'placed block {i} moved {move * unit / cfg.sim_unit * 1000:.1f} mm'
        return ''

    def _new_failed(self, motion: tuple[float, float], unit: float) -> str:
        cfg = self.config
        move, tilt = motion
        if tilt > cfg.new_tilt_deg:
            return f'new block tipped {tilt:.1f} deg'
        if move > cfg.new_move * cfg.sim_unit:
            return f'new block moved {move * unit / cfg.sim_unit * 1000:.1f} mm'
        return ''

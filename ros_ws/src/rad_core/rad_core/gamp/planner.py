"""Grasp and motion planning for one assembly action (the paper's Sec. IV-C).

Given the world as it is (blocks where they lie, robot at `start`) and an action
(which block, its final anchor position and yaw), find a PAIR of feasible grasp
and placement configurations, then the motion between them:

    start -> above grasp -> (down) grasp -> close -> (up) lift -> above placement
          -> (down) place -> open -> (up) retreat

For each predefined grasp (`grasps.scene_grasps`, best first) and each of the
two hand yaws of the symmetric hand, the pick half is checked first, the grasp target at
the unit's centre and the fingers open 1 cm off its faces; where a finger hits a neighbour
there, again with the tight grasp: the fingers 4 mm off, the target 13 mm under the unit's
top, only the fingers' rubber tips beside it (`grasp_styles`). IK at the
grasp and on every vertical waypoint up to the approach height, no collision of
the robot (fingers open) with the table, any block (the grasped one included:
the open fingers must clear it) or itself, at every waypoint and along every
joint-space segment between them (`collision.check_path`), then the lift with
the block held. Only then the placement half with the same grasp carried over:
the hand yaw turned by the action's rotation, IK at the placement and on the
vertical waypoints above it, the robot clear of everything and the carried
block not penetrating anything beyond face contact, the transfer from lift to
above placement, and the retreat with opened fingers from the placed block.

With `GampConfig.wide_grasps`, the wide grasps (`grasps.wide_grasps`: across the block's whole extent
along one axis) follow the unit grasps, planned the same way at the tight grasp's height
(`wide_grasp_styles`), the fingers opened off the row's outer faces and closed on them.

Failure classes as the paper's: 'grasp' (f_g) when no grasp passes the pick
half, 'placement' (f_p) when some grasp does but none of those also places the
block. The reason lists, per grasp, the first thing that blocked it.

Everything runs inside one ``world.preserved()``: the world is unchanged after.
"""

from __future__ import annotations

import math
import os
import re
import time
import weakref
from dataclasses import dataclass, field

import numpy as np

from rad_core.cell import panda
from rad_core.cell.motion import Motion
from rad_core.domain.blocks import BlockType
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, yaw_matrix, yaw_of_quaternion, yaw_quaternion
from rad_core.gamp.collision import CollisionConfig, attachment_from_world, check_path, make_collision_fn, world_key
from rad_core.gamp.grasps import (
    Grasp,
    grasp_centre,
    DROP_HEIGHT,
    drop_lift,
    grasp_lift,
    no_grasp_reason_for,
    scene_grasps,
    span_width,
    tip_floor_lift,
)
from rad_core.gamp.ik import IkConfig, hand_yaw_options, solve_top_down
from rad_core.gamp.trajectory import TimingConfig, plan_motion
from rad_core.sim.world import World


DROP_BY_DEFAULT = os.environ.get('RAD_GAMP_DROP', '1') != '0'
"""`GampConfig.drop` where a config does not say (read when each config is made): the hand drops where it
cannot set down. False (`RAD_GAMP_DROP=0` in the environment) gives every config made after it the paper's
hand, which only sets blocks down (the tests of what that hand cannot do set it so)."""


@dataclass(frozen=True)
class GampConfig:
    """Geometry of the motion and effort of the search."""

    approach_height: float = 0.12
    """The hand comes down on the grasp, lifts, and leaves the placement over this height (m)."""
    transit_clearance: float = 0.04
    """The hand rises before it moves over: until the carried block's bottom (or the empty
    fingertips) clears the top of every other block by this much (m), at least to
    ``approach_height``. A joint-space move between two such heights can still
    sag a little, so the clearance is generous; the segment is probed anyway."""
    cartesian_step: float = 0.04
    """Vertical moves get an IK waypoint at least every this many metres, so they stay straight."""
    near_step: float = 0.01
    """Where the carried block (or the open fingers) is among the blocks, the held block's height over the
    grasp or the placement and `near_margin` above it, vertical moves get an IK waypoint every this many
    metres: a straight joint-space segment between two waypoints bows off the vertical (about 1.4 mm over
    4 cm on a Panda), and flush neighbours leave a block a fraction of a millimetre each side. 0: none."""
    near_margin: float = 0.01
    """How far (m) above the held block's height the `near_step` waypoints go on."""
    finger_clearance: float = 0.01
    """Open fingers stand this far off the unit's faces (not the full 0.08 m opening:
    neighbours on the table are only a few cm away). The faces are the block's own:
    with a scene clearance, the grasped unit is that much narrower."""
    tight_finger_clearance: float = 0.004
    """Where a finger at `finger_clearance` hits a neighbour, the grasp is tried again as a tight
    grasp: the fingers this far off the unit's faces, the grasp target `grasps.GRASP_BELOW_TOP`
    under the unit's top (blocks packed 2.5 cm apart on the table); 0 or no less than
    `finger_clearance`: never. Not the first choice: the centre grasp holds a unit around its
    middle, the way every result before it was measured."""
    grip_squeeze: float = 0.001
    """Closed fingers are commanded this far inside the unit's faces, so a position-
    controlled gripper presses on the block."""
    path_step: float = 0.05
    """Largest joint step (rad) between collision probes along a segment."""
    seed: int = 0
    """Seed of the IK's random restarts: the same request gives the same plan."""
    ik: IkConfig = field(default_factory=IkConfig)
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    move_aside: int = 2
    """When no grasp of a block on the table is free because neighbours stand too close, and the
    caller asks for it, move them out of the way first, to free places on the table
    (`shapes.move_aside_spot`): at most this many per step (0: never). Used by
    `gamp.action.MotionPlanner` (the gamp node's `move_aside` request; `plan_assembly` asks for
    it); `plan_action` itself plans one pick and place."""
    timing: TimingConfig = field(default_factory=TimingConfig)
    drop: bool = field(default_factory=lambda: DROP_BY_DEFAULT)
    """Where the hand picks the block but a finger or the hand hits a neighbour at the placement in every
    way of holding it, try once more holding it by its top (`grasps.drop_lift`) and letting go of it
    `grasps.DROP_HEIGHT` over its place, the fingertips above the neighbours at its level: the block falls
    the rest (a drop; `GampResult.drop`). Tried last, so actions placed before are placed as before. Not
    with the vacuum gripper (it sets a block down where it goes) nor with studded bricks (the press needs
    the hand on the brick). Off: the hand only sets blocks down."""
    wide_grasps: bool = True
    """Also take a block across its whole extent along its x or y axis (`grasps.wide_grasps`), after
    every unit grasp failed: the fingers outside the block, at the tight grasp's height
    (`wide_grasp_styles`), closing on the row's outer faces. Only rows that fit the open hand have
    them (2 units up to 3.5 cm, 3 up to 2.5 cm), so scenes at 4 and 5 cm units plan as with unit
    grasps alone. Off: the unit grasps only (the paper's hand)."""
    effector: str = 'hand'
    """What the arm carries (`cell.panda.EFFECTORS`): 'hand', Franka's parallel hand, or 'suction',
    the vacuum gripper: its cup comes down on the top face of a unit (`grasps.suction_grasps`),
    `suction_hover` over it, the vacuum holds the block, and a drop-off lets it go at the placement;
    nothing goes down beside the block."""
    press_depth: float = 0.003
    """Studded bricks (a scene's ``studs``): after setting a brick down, the hand pushes it this far (m)
    further down, onto the studs under it, and comes back up before letting go: the press that joins it
    (the twin's `TwinConfig.press_force`); the arm's stiffness turns the depth into the force."""
    suction_hover: float = 0.005
    """The cup's lip stops this far (m) over the top face it takes: clear of the collision margin; the
    cup's bellows close the gap when the vacuum comes on (the twin seals within its own tolerance)."""
    vacuum: int = 50
    """The vacuum a suction grasp asks for, in 10 mbar (franka_vacuum_gripper's Vacuum goal, int8)."""
    vacuum_timeout_ms: int = 100
    """How long the vacuum may take to build up (ms; the Vacuum and DropOff goals' int8 timeout)."""

    def validate(self) -> None:
        panda.check_effector(self.effector)
        if not 0 <= self.press_depth <= 0.01:
            raise RadError(f'press_depth must be 0..0.01 m (0: no press), got {self.press_depth!r}')
        if not self.cartesian_step > 0:
            raise RadError(f'cartesian_step must be a positive length (m), got {self.cartesian_step!r}')
        if not (self.near_step >= 0 and self.near_margin >= 0):
            raise RadError(f'near_step and near_margin must be lengths >= 0 (m; near_step 0: no finer steps), '
                           f'got {self.near_step!r} and {self.near_margin!r}')
        if not (isinstance(self.vacuum, int) and 1 <= self.vacuum <= 127):
            raise RadError(f'vacuum must be 1..127 (x 10 mbar, an int8 goal field), got {self.vacuum!r}')
        if not (isinstance(self.vacuum_timeout_ms, int) and 1 <= self.vacuum_timeout_ms <= 127):
            raise RadError(f'vacuum_timeout_ms must be 1..127 (an int8 goal field), got {self.vacuum_timeout_ms!r}')


@dataclass
class GampResult:
    """What GAMP says about one action.

    motion: the arm trajectories (7 joints, timed within the robot model's limits)
    and gripper commands that do it, in order (`rad_core.cell.motion.Motion`). It is timed
    when first read (`trajectory.plan_motion` over the plan's waypoints, about 1 ms): a
    planning-twin step that teleports needs only where the motion ends (`final_joints`),
    and a search asks GAMP thousands of times. Timings in seconds (the motion's timing
    is not in total_s).
    """

    success: bool
    failure: str = ''                 # '' | 'grasp' | 'placement'
    reason: str = ''
    grasp: Grasp | None = None
    hand_yaw_deg: float = 0.0         # hand yaw at the grasp
    timings: dict = field(default_factory=lambda: {'ik_s': 0.0, 'collision_s': 0.0, 'total_s': 0.0})
    ik_calls: int = 0
    drop: float = 0.0
    """How far (m) over its place the motion lets the block go (`GampConfig.drop`); 0: set down. A
    dropping result's `reason` says why no grasp sets the block down."""
    moved_aside: list = field(default_factory=list)
    """Blocks the motion first moves out of the way on the table, in order:
    {'block', 'position' (anchor, m), 'yaw' (deg)}; the motion holds their pick and place first."""
    _motion: Motion | None = field(default=None, repr=False)
    _path: tuple | None = field(default=None, repr=False)
    """(start, waypoints, timing config, expected grasp width, vacuum) until the motion is timed; vacuum:
    None for the hand, else (level in 10 mbar, timeout in ms) of the vacuum gripper."""

    @property
    def motion(self) -> Motion | None:
        if self._motion is None and self._path is not None:
            start, waypoints, timing, grasp_expected, vacuum = self._path
            self._motion = plan_motion(start, waypoints, timing, grasp_expected=grasp_expected, vacuum=vacuum)
            self._path = None
        return self._motion

    @motion.setter
    def motion(self, motion: Motion | None) -> None:
        self._motion, self._path = motion, None

    def final_joints(self) -> np.ndarray:
        """The 9 joints where the motion leaves the robot (`Motion.final_joints`), without timing it:
        the motion ends at rest on its last waypoint, with the fingers as that waypoint has them
        (every finger change is a gripper command of the waypoints' own opening)."""
        if self._motion is None and self._path is not None:
            return np.array(self._path[1][-1], dtype=float)
        return self.motion.final_joints()


def placement_pose(scene: Scene, block_id: str, unit: int, cell_centre, rotation: int,
                   current_yaw: float | None = None) -> tuple[np.ndarray, int]:
    """Final anchor position and yaw (deg) of an MDP action: turn the block by
    rotation * 90 deg, then put its unit `unit` on the cell centred at cell_centre."""
    block = scene.block(block_id)
    btype = scene.block_types[block.type]
    if not 0 <= unit < btype.size:
        raise RadError(f'unit {unit} is not a unit of block {block_id!r}')
    yaw = int(round(((block.yaw if current_yaw is None else current_yaw) + 90 * rotation) / 90.0)) * 90 % 360
    offset = btype.rotated(yaw)[unit] * scene.pitch
    return np.asarray(cell_centre, dtype=float) - offset, yaw


def allocated_pose(scene: Scene, placement) -> tuple[np.ndarray, int]:
    """Anchor position and yaw (deg) of an allocation `Placement`: its cells list the
    units in type order, so the first cell is the anchor's."""
    region = scene.target(placement.target)
    return region.cell_center(placement.cells[0], scene.pitch), int(placement.yaw)


class _Clock:
    """Accumulates the IK and collision time of one plan."""

    def __init__(self):
        self.ik_s = self.collision_s = 0.0
        self.ik_calls = 0

    def timed(self, fn):
        def wrapped(q):
            t = time.perf_counter()
            try:
                return fn(q)
            finally:
                self.collision_s += time.perf_counter() - t
        return wrapped


class _Blocked(Exception):
    """One candidate failed; str() says where and why."""


def plan_action(world: World, block_id: str, position, yaw_deg: float, start=None,
                config: GampConfig | None = None) -> GampResult:
    """Plan picking `block_id` where it lies and placing its anchor at `position` with `yaw_deg`.

    start: (9,) joints the motion starts from (default: the robot's joints now). config: default `GampConfig()`.
    """
    t0 = time.perf_counter()
    config = GampConfig() if config is None else config
    if world.scene is None or block_id not in world.blocks:
        raise RadError(f'unknown block id {block_id!r}')
    position = np.asarray(position, dtype=float).ravel()
    if position.shape != (3,) or not np.all(np.isfinite(position)) or not math.isfinite(yaw_deg):
        raise RadError('the placement needs a finite position (3 numbers) and a finite yaw')
    scene = world.scene
    unit = scene.unit
    btype = scene.block_types[scene.block(block_id).type]
    clock = _Clock()
    rng = np.random.default_rng(config.seed)
    grasps = scene_grasps(btype, unit, scene.clearance, config.wide_grasps, config.effector)
    if scene.studs is not None and config.press_depth > 0:
        grasps = _over_the_studs(world, block_id, btype, position, float(yaw_deg), grasps)
    result = GampResult(False)
    if world.effector != config.effector:
        raise RadError(f'the planning world carries the {world.effector}, the config plans for the {config.effector}')
    if not grasps:
        return _finish(result, 'grasp', f'grasp: block {block_id} has no top-down grasp: '
                                        f'{no_grasp_reason_for(btype, unit, scene.clearance, config.effector)}',
                       clock, t0)

    pick_failures, place_failures = [], []
    with world.preserved():
        world.present(block_id)     # a block in the feeder is picked where the feeder presents it
        start = world.joint_positions() if start is None else _full(start)
        block_pos, block_quat = world.block_pose(block_id)
        job = _Job(world, block_id, btype, unit, scene.course, scene.clearance, position, float(yaw_deg), start,
                   block_pos, block_quat, _tops(world, exclude=block_id), world_key(world, (), None, config.collision),
                   config, clock, rng)
        for grasp in grasps:
            done, pick_reason, place_reason = _try_grasp(job, grasp)
            if done is not None:
                result._path, result.hand_yaw_deg, result.drop = done
                result.grasp, result.success = grasp, True
                return _finish(result, '', '', clock, t0)
            if place_reason:
                place_failures.append((grasp, place_reason))
            else:
                pick_failures.append(f'{grasp}: {pick_reason}')
        # No grasp sets the block down: where the hand hit a neighbour at the placement, let it go over it.
        for k, (grasp, place_reason) in enumerate(place_failures):
            if not _may_drop(job, place_reason):
                continue
            done, _, dropped = _try_grasp(job, grasp, drop=True)
            if done is not None:
                result._path, result.hand_yaw_deg, result.drop = done
                result.grasp, result.success = grasp, True
                # Why it could not be set down: a plan that takes no drops refuses it for that.
                return _finish(result, '', _placement_reason(place_failures, len(grasps)), clock, t0)
            if dropped:
                # Where the drop failed, not what it hit: order repair learns its precedences from the
                # blocks a refusal names, and those of the block set down are the ones to learn.
                place_failures[k] = (grasp, f'{place_reason} (nor let go {DROP_HEIGHT * 1000:.0f} mm over it: '
                                            f'{dropped.split(":")[0]})')
    if not place_failures:
        reason = f'grasp: all {len(grasps)} grasps blocked: ' + '; '.join(pick_failures)
        return _finish(result, 'grasp', reason, clock, t0)
    return _finish(result, 'placement', _placement_reason(place_failures, len(grasps)), clock, t0)


def _placement_reason(place_failures: list, n_grasps: int) -> str:
    return (f'placement: {len(place_failures)} of {n_grasps} grasps feasible, none places the block: '
            + '; '.join(f'{grasp}: {why}' for grasp, why in place_failures))


def _over_the_studs(world: World, block_id: str, btype: BlockType, position, yaw_deg: float,
                    grasps: tuple[Grasp, ...]) -> tuple[Grasp, ...]:
    """A studded brick's grasps, those whose target is nearest the studs it goes onto first (stable):
    the press pushes through the grasp, so over the studs it seats rather than out on what they hold
    (the statics of the press, `env.mdp`, assume so)."""
    scene = world.scene
    turn = yaw_matrix(yaw_deg)
    units = np.asarray(position) + (np.asarray(btype.offsets, dtype=float) * scene.pitch) @ turn.T
    under = units - [0.0, 0.0, scene.course]
    below = [world.unit_centres(b) for b in world.blocks if b != block_id and b not in world.parked]
    if not below:
        return grasps
    theirs = np.concatenate(below)
    on = np.array([np.any(np.all(np.abs(theirs - u) < 0.25 * scene.pitch, axis=1)) for u in under])
    if not on.any():
        return grasps
    studs = units[on, :2].mean(axis=0)

    def distance(g: Grasp) -> float:
        at = np.asarray(position) + (grasp_centre(btype, g) * scene.pitch) @ turn.T
        return round(float(np.hypot(*(at[:2] - studs))), 6)
    return tuple(sorted(grasps, key=distance))


@dataclass
class _Job:
    """What every grasp of one `plan_action` call is planned against."""

    world: World
    block_id: str
    btype: BlockType
    unit: float
    course: float
    clearance: float
    position: np.ndarray
    yaw_deg: float
    start: np.ndarray
    block_pos: np.ndarray
    block_quat: np.ndarray
    tops: float
    bodies: tuple
    config: GampConfig
    clock: _Clock
    rng: np.random.Generator
    # The block's pose now and at the placement, once per call (`__post_init__`).
    block_yaw: float = field(init=False)
    rot: np.ndarray = field(init=False)
    final_rot: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.block_yaw = math.radians(yaw_of_quaternion(self.block_quat))
        self.rot = matrix_from_quaternion(self.block_quat)
        self.final_rot = yaw_matrix(self.yaw_deg)


def _try_grasp(job: _Job, grasp: Grasp, drop: bool = False) -> tuple[tuple | None, str, str]:
    """Plan one grasp, both hand yaws: ((the result's path, hand yaw (deg), drop (m)) or None, the pick's
    reason, the placement's reason). drop: held by its top and let go `DROP_HEIGHT` over its place
    (`GampConfig.drop`), not set down."""
    config = job.config
    if config.effector == 'suction':
        # The finger coordinate stands for the vacuum (the vacuum gripper has no fingers, and its URDF's
        # finger links no shape): open = off, closed = on, so that plan_motion places its commands.
        width, closed_f = float('nan'), 0.0
        styles = suction_styles(job.course, config)
    else:
        width = span_width(grasp.span, job.unit, job.clearance)      # grasp_width's for one unit
        styles = (grasp_styles if grasp.span == 1 else wide_grasp_styles)(width, job.course, config)
        closed_f = max(0.0, width / 2 - config.grip_squeeze)
    if drop:
        return _try_styles(job, grasp, width, closed_f, drop_styles(width, job.course, config), DROP_HEIGHT)
    return _try_styles(job, grasp, width, closed_f, styles, 0.0)


def _may_drop(job: _Job, place_reason: str) -> bool:
    """Whether a drop may help: the hand's, no studs, and the placement refused for the fingers, the hand or
    the links rigid with it hitting a block (not the carried block, not the reach)."""
    return (job.config.drop and job.config.effector == 'hand' and job.world.scene.studs is None
            and re.search(r'(finger|hand|link7|link8) hits block', place_reason) is not None)


def _try_styles(job: _Job, grasp: Grasp, width: float, closed_f: float, styles, drop: float
                ) -> tuple[tuple | None, str, str]:
    """`_try_grasp` in the given ways of holding the block (`grasp_styles`), the block let go `drop` (m)
    over its place."""
    world, block_id, btype, unit, config = job.world, job.block_id, job.btype, job.unit, job.config
    rot, final_rot = job.rot, job.final_rot
    turn = math.radians(job.yaw_deg) - job.block_yaw
    centre = grasp_centre(btype, grasp) * np.array([unit, unit, job.course])
    closing = job.block_yaw + math.radians(grasp.yaw)
    pick_reason = place_reason = ''
    for hand_yaw in hand_yaw_options(job.block_pos + rot @ centre, closing):
        pick, why = None, []
        for open_f, lift in styles:
            offset = centre + (0.0, 0.0, lift)
            # From the grasp point down to the held block's bottom; a plate is held above its tight grasp.
            hang = (offset[2] - min(o[2] for o in btype.offsets) * job.course) + job.course / 2
            if config.effector != 'suction':
                raise_by = tip_floor_lift(hang)
                offset, hang = offset + (0.0, 0.0, raise_by), hang + raise_by
            grasp_point = job.block_pos + rot @ offset
            transit_z = job.tops + hang + config.transit_clearance
            rise_pick = max(config.approach_height, transit_z - grasp_point[2])
            near = hang + config.near_margin
            try:
                pick = _remembered_pick(job.bodies, world, block_id, grasp_point, hand_yaw, job.start, open_f,
                                        closed_f, (rise_pick, near), config, job.clock, job.rng)
                break
            except _Blocked as e:
                why.append(str(e) if not why else f'tight grasp: {e}')
                # A lift check that failed carried the block with the hand: put it back, so
                # the next try is planned against the world as it is (as after a failed
                # placement).
                world.set_block_pose(block_id, job.block_pos, job.block_quat)
                if 'finger hits' not in str(e):
                    break       # a tight grasp cannot help
        if pick is None:
            pick_reason = pick_reason or '; '.join(why)
            continue
        place_point = job.position + final_rot @ offset + (0.0, 0.0, drop)
        rise_place = max(config.approach_height, transit_z - place_point[2])
        try:
            place = _plan_place(world, block_id, pick, place_point, job.position, job.yaw_deg,
                                hand_yaw + turn, open_f, (rise_place, near), config, job.clock, job.rng)
        except _Blocked as e:
            place_reason = place_reason or str(e)
            world.set_block_pose(block_id, job.block_pos, job.block_quat)
            continue
        vacuum = (config.vacuum, config.vacuum_timeout_ms) if config.effector == 'suction' else None
        path = (job.start, pick['waypoints'] + place['waypoints'], config.timing, width / 2, vacuum)
        return (path, math.degrees(hand_yaw), drop), pick_reason, place_reason
    return None, pick_reason, place_reason


# World -> {pick key -> (pick or the reason it was blocked, generator state after)}: picks planned
# before. A pick reads the world's bodies and their poses (the held block's included: it lies where
# it lies, put back after every try), the start, the grasp, the fingers, the rise, the config and the
# generator's state (IK's random restarts), and not the robot's joints as a try leaves them (IK
# sets its seeds, every probe its q). One plan tries several picks; the moves of one state from
# one search pick the same block with the same grasps again, only their placements differ. So
# a pick met again is answered from memory, with the generator put where the pick left it, and the
# carried-block check made anew for this plan's clock. Bounded: cleared when it grows large.
_PICK_MEMO: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_PICK_MEMO_MAX = 2048


def grasp_styles(width: float, height: float, config: GampConfig = GampConfig()) -> tuple[tuple[float, float], ...]:
    """How the planner takes a unit `width` wide (of a block of cells `height` high), in the order it tries:
    (each finger's travel when open (m), the grasp target's height over the unit's centre (m)).
    First the fingers `finger_clearance` off its faces at its centre; then the tight grasp,
    `tight_finger_clearance` off its faces near its top (`grasps.grasp_lift`)."""
    out = [(min(panda.FINGER_OPEN, width / 2 + config.finger_clearance), 0.0)]
    if 0 < config.tight_finger_clearance < config.finger_clearance:
        out.append((min(panda.FINGER_OPEN, width / 2 + config.tight_finger_clearance), grasp_lift(height)))
    return tuple(out)


def wide_grasp_styles(width: float, height: float,
                      config: GampConfig = GampConfig()) -> tuple[tuple[float, float], ...]:
    """How the planner takes a wide grasp across `width` (m) of a block of cells `height` high, in the
    order it tries: (each finger's travel when open (m), the grasp target's height over the held units'
    centre (m)), always at the tight grasp's height (`grasps.grasp_lift`): first the fingers
    `finger_clearance` off the row's outer faces, then `tight_finger_clearance` off them (never wider
    than the hand opens)."""
    out = [(min(panda.FINGER_OPEN, width / 2 + config.finger_clearance), grasp_lift(height))]
    if 0 < config.tight_finger_clearance < config.finger_clearance:
        tight = (min(panda.FINGER_OPEN, width / 2 + config.tight_finger_clearance), grasp_lift(height))
        if tight != out[0]:
            out.append(tight)
    return tuple(out)


def drop_styles(width: float, height: float, config: GampConfig = GampConfig()) -> tuple[tuple[float, float], ...]:
    """How the planner holds a unit `width` wide (or a wide grasp's row) to drop it (`GampConfig.drop`), as
    `grasp_styles` gives it: the fingers `tight_finger_clearance` off its faces (or `finger_clearance`
    where tight grasps are off), the target `grasps.drop_lift` over the unit's centre."""
    off = config.tight_finger_clearance if 0 < config.tight_finger_clearance else config.finger_clearance
    return ((min(panda.FINGER_OPEN, width / 2 + off), drop_lift(height)),)


def suction_styles(height: float, config: GampConfig = GampConfig()) -> tuple[tuple[float, float], ...]:
    """How the planner takes a unit with the vacuum gripper, as `grasp_styles` gives it for the hand: the
    finger coordinate at open (it stands for the vacuum off: the gripper has no fingers) and the cup's
    lip `suction_hover` over the unit's top face."""
    return ((panda.FINGER_OPEN, height / 2 + config.suction_hover),)


def _remembered_pick(bodies, world, block_id, grasp_point, hand_yaw, start, open_f, closed_f, rise, config,
                     clock, rng) -> dict:
    memo = _PICK_MEMO.setdefault(world, {})
    if len(memo) >= _PICK_MEMO_MAX:
        memo.clear()
    key = (bodies, block_id, np.asarray(grasp_point, dtype=float).tobytes(), float(hand_yaw), start.tobytes(),
           float(open_f), float(closed_f), tuple(map(float, rise)), config, repr(rng.bit_generator.state))
    found = memo.get(key)
    if found is not None:
        answer, rng.bit_generator.state = found
        if isinstance(answer, str):
            raise _Blocked(answer)
        attachment = answer['attachment']
        carry = clock.timed(make_collision_fn(world, attached=attachment, config=config.collision, remember=True))
        return {'waypoints': [q.copy() for q in answer['waypoints']], 'attachment': attachment, 'carry': carry,
                'top': answer['top'].copy()}
    try:
        pick = _plan_pick(world, block_id, grasp_point, hand_yaw, start, open_f, closed_f, rise, config, clock, rng)
    except _Blocked as e:
        memo[key] = (str(e), rng.bit_generator.state)
        raise
    memo[key] = ({'waypoints': [q.copy() for q in pick['waypoints']], 'attachment': pick['attachment'],
                  'top': pick['top'].copy()}, rng.bit_generator.state)
    return pick


def _plan_pick(world, block_id, grasp_point, hand_yaw, start, open_f, closed_f, rise, config, clock,
               rng) -> dict:
    start_open = start.copy()
    start_open[7:] = open_f
    free = clock.timed(make_collision_fn(world, config=config.collision, remember=True))
    q_grasp = _ik(world, grasp_point, hand_yaw, [start_open, panda.HOME], open_f, config, clock, rng,
                  'IK at the grasp')
    _probe(free, q_grasp, 'at the grasp')
    column = _vertical(world, grasp_point, q_grasp, hand_yaw, rise, config, clock, rng, 'above the grasp')
    _check_column(free, q_grasp, column, config, 'above the grasp', 'on the approach')
    _segment(free, start, column[-1], config, 'on the way to the grasp')
    # The hand holds the block from here on.
    world.set_joint_positions(q_grasp, hold=False)
    attachment = attachment_from_world(world, block_id)
    carry = clock.timed(make_collision_fn(world, attached=attachment, config=config.collision, remember=True))
    q_closed = _with_fingers(q_grasp, closed_f)
    lift = [_with_fingers(q, closed_f) for q in column]
    _check_column(carry, q_closed, lift, config, 'lifting the block', 'lifting the block')
    return {'waypoints': _down_and_up(column, q_grasp, q_closed, lift), 'attachment': attachment,
            'carry': carry, 'top': lift[-1]}


def _plan_place(world, block_id, pick, place_point, position, yaw_deg, hand_yaw, open_f, rise, config,
                clock, rng) -> dict:
    carry, top = pick['carry'], pick['top']
    closed_f = top[7]
    q_place = _ik(world, place_point, hand_yaw, [top], closed_f, config, clock, rng, 'IK at the placement')
    _probe(carry, q_place, 'at the placement')
    column = _vertical(world, place_point, q_place, hand_yaw, rise, config, clock, rng, 'above the placement')
    _check_column(carry, q_place, column, config, 'above the placement', 'on the descent')
    _segment(carry, top, column[-1], config, 'carrying the block over')
    # Released: the block at its final pose (a dropped one falls there), the fingers open.
    world.set_block_pose(block_id, position, yaw_quaternion(yaw_deg))
    after = clock.timed(make_collision_fn(world, config=config.collision, remember=True))
    q_open = _with_fingers(q_place, open_f)
    _probe(after, q_open, 'opening the fingers')
    retreat = [_with_fingers(q, open_f) for q in column]
    _check_column(after, q_open, retreat, config, 'on the retreat', 'on the retreat')
    if world.scene.studs is None or config.press_depth <= 0:
        return {'waypoints': _down_and_up(column, q_place, q_open, retreat)}
    # The press: into the studs under the brick on purpose, so no collision probe; back up to q_place.
    press_point = np.asarray(place_point) - [0.0, 0.0, config.press_depth]
    q_press = _ik(world, press_point, hand_yaw, [q_place], closed_f, config, clock, rng, 'IK for the press')
    return {'waypoints': column[::-1] + [q_place, q_press, q_place, q_open] + retreat}


def _ik(world, point, hand_yaw, seeds, fingers, config, clock, rng, where) -> np.ndarray:
    seeds = [_with_fingers(_full(s), fingers) for s in seeds]
    r = solve_top_down(world, point, 0.0, seeds, config.ik, rng, hand_yaw=hand_yaw)
    clock.ik_s += r.seconds
    clock.ik_calls += r.calls
    if not r.ok:
        raise _Blocked(f'{where}: {r.reason}')
    return r.q


def _vertical(world, point, q_low, hand_yaw, rise, config, clock, rng, where) -> list[np.ndarray]:
    """IK waypoints straight above `point` up to rise = (top, near), bottom up, each seeded from the one
    below (`column_heights`)."""
    out, q = [], q_low
    for h in column_heights(*rise, config):
        target = np.asarray(point) + [0.0, 0.0, h]
        q = _ik(world, target, hand_yaw, [q], q_low[7], config, clock, rng, f'IK {where}')
        out.append(q)
    return out


def column_heights(top: float, near: float, config: GampConfig = GampConfig()) -> list[float]:
    """Heights (m, over the grasp or placement point, rising, ending at `top`) of a vertical move's
    waypoints: every `near_step` up to `near` (where the block is among its neighbours), then evenly at
    most `cartesian_step` apart."""
    near = min(max(near, 0.0), top) if config.near_step > 0 else 0.0
    low = []
    if near > 0:
        n = max(1, math.ceil(near / config.near_step - 1e-9))
        low = [near * k / n for k in range(1, n + 1)]
    n = max(1, math.ceil((top - near) / config.cartesian_step - 1e-9)) if top > near else 0
    return low + [near + (top - near) * k / n for k in range(1, n + 1)]


def _tops(world: World, exclude: str) -> float:
    """Highest point of any block but one (m; 0 for the bare table)."""
    p = world.pybullet
    tops = [p.getAABB(body, -1, physicsClientId=world.client)[1][2]
            for bid, body in [*world.blocks.items(), *world.obstacles.items()] if bid != exclude]
    return max(tops, default=0.0)


def _probe(fn, q, where) -> None:
    reason = fn(q)
    if reason:
        raise _Blocked(f'{where}: {reason}')


def _segment(fn, q_from, q_to, config, where) -> None:
    reason = check_path(fn, q_from, q_to, config.path_step)
    if reason:
        raise _Blocked(f'{where}: {reason}')


def _check_column(fn, q_bottom, column, config, probe_where, segment_where) -> None:
    """Probe each waypoint of a column (bottom up) and each segment up to it from q_bottom."""
    q_prev = q_bottom
    for q in column:
        _probe(fn, q, probe_where)
        _segment(fn, q_prev, q, config, segment_where)
        q_prev = q


def _down_and_up(column, q_at, q_gripped, up) -> list[np.ndarray]:
    """Waypoints down a column (given bottom up) to q_at, the gripper acting (q_gripped), back up."""
    return column[::-1] + [q_at, q_gripped] + up


def _finish(result: GampResult, failure: str, reason: str, clock: _Clock, t0: float) -> GampResult:
    result.failure, result.reason = failure, reason
    result.timings = {'ik_s': clock.ik_s, 'collision_s': clock.collision_s,
                      'total_s': time.perf_counter() - t0}
    result.ik_calls = clock.ik_calls
    return result


def _full(q) -> np.ndarray:
    q = np.asarray(q, dtype=float).ravel()
    if len(q) == 7:
        return np.concatenate([q, panda.HOME[7:]])
    if len(q) != 9 or not np.all(np.isfinite(q)):
        raise RadError(f'expected 7 or 9 finite joint positions, got {len(q)}')
    return q.copy()


def _with_fingers(q, f: float) -> np.ndarray:
    q = np.array(q, dtype=float)
    q[7:] = f
    return q

"""Motion-capture registration: the twin's scene from tracked rigid-body poses.

A motion-capture system (OptiTrack-style) reports one pose per rigid body. Here
a body's pose is the pose of its block's anchor unit: the centre of the block's
first unit cube, with the block's yaw as orientation, in the scene frame (table
top at z = ``table_z``). That is what `scene_to_bodies` emits and what the
twin's World reports with ``block_pose``, so the twin can publish poses and
registration rebuilds the scene it came from.

Real measurements are noisy and real blocks are not exactly where a plan put
them, so registration snaps each pose to what a scene can express, within
tolerances, and refuses what it cannot express:

- yaw to the nearest multiple of 90 degrees (the scene format only has those);
  a block on its side or standing on an edge is rejected, not rounded;
- height to a unit lattice above the table (blocks rest on the table or on
  other blocks, so their anchor is at u/2 + k u);
- x/y to the target grid when the block is inside a target region, so a placed
  block registers exactly on its cells and the grid, the allocation and the MDP
  see it as placed. A scene with a clearance (`rad_core.domain.scene`) gives a block
  that much room in its cell (it can rest up to clearance / 2 unit off the cell
  centre and touch nothing), so the x/y tolerance there grows by clearance / 2
  (at most 0.49 unit, where snapping would become ambiguous). Blocks elsewhere keep their measured x/y, rounded to the
  config's ``resolution``: the table is not a lattice, and snapping there would
  invent collisions or gaps.

Whatever survives is validated by `Scene.from_dict` (overlaps, blocks half in a
region, blocks below the table), with errors translated to the body's name.

`register_scene` raises for the first body a scene cannot express. During
execution that is too strict: a block that slipped out of the hand and lies on
its side, or one pushed off its cell, is a fact of the world to plan around, not
a reason to stop. `register_world` registers the same way but sets such blocks
aside with the reason (tilted, turned, off the height lattice, off its grid in a
region, sticking into a region, overlapping another) and returns the scene of the
rest as a `Registration`. A block lying flat on the table but turned off the
90-degree yaws is not set aside there: it is registered at the nearest one with the
turn kept as its measured offset, so it can be picked where it lies and put down
straight. The scene lists the set-aside blocks as ``obstacles`` at their measured
poses, so motion planning steers clear of them. A set-aside block is still there, physically: one
lying over a target region occupies cells a plan would fill. The registration
records those cells (`Registration.blocked`: every target cell a set-aside
block's units overlap by more than `BLOCKED_OVERLAP` in each axis, at its
measured pose, and no registered block sits on), and `Registration.plannable()`
is the scene without them as target cells: a plan from it neither places a block
into an obstacle nor counts on cells it cannot fill, while coverage is still
measured against the real targets. Set-up errors (an unknown body, a body
reported twice, a NaN or non-unit quaternion, an untracked body) still raise in
both: they are not something the world did.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from rad_core.domain.errors import RadError, SceneError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion

# Quaternions from a tracker are normalised by the tracker; anything further off
# than this is a corrupted message or a wrong field order, not rounding.
QUAT_NORM_TOL = 1e-3
# Snapped coordinates are rounded to a nanometre so that a round trip gives
# bit-identical numbers for positions that were already on the lattice.
_DECIMALS = 9
# A set-aside block blocks a target cell when its units overlap the cell's box by more than this (m)
# in every axis: deeper than resting contact and tracker noise, far less than any real intrusion.
BLOCKED_OVERLAP = 0.003


@dataclass(frozen=True)
class RigidBodyPose:
    """One tracked rigid body: anchor-unit centre (m) and orientation (x, y, z, w)."""

    name: str
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]
    tracking_valid: bool = True


@dataclass(frozen=True)
class RegistrationConfig:
    """How motion-capture bodies map to blocks and how far a pose may be off.

    body_map: rigid-body name -> (block id, block type). Bodies not in it are
        rejected: an unknown body in the capture volume is a set-up error worth
        seeing, not something to ignore silently.
    position_tol: how far (fraction of a unit) a pose may be off the height
        lattice, or off the grid inside a target region (plus half the scene's
        clearance there). 0.25 unit (12.5 mm at 5 cm) is well above tracker noise
        (< 1 mm) and placement error of a few mm, and well below half a unit,
        where snapping would become ambiguous.
    tilt_tol_deg: the most a block may be tilted (roll/pitch) and still count as
        lying flat. Blocks are rigid and rest on flat faces; 10 degrees allows
        for tracker noise and a block leaning on a slightly uneven neighbour.
    yaw_tol_deg: the most the yaw may be away from a multiple of 90 degrees.
        A block turned 45 degrees cannot be expressed in a scene at all.
    table_z: height of the table top in the motion-capture frame (m).
    resolution: measured x/y (blocks off the grid) are rounded to this (m).
        0.1 mm is finer than a tracker's accuracy (0.1-0.5 mm), and it keeps
        float32 artefacts (-0.20000000298) and the micrometre creep of resting
        bodies in a simulator out of the scene, so a twin at rest reports the
        scene it was loaded with. 0 keeps every digit.
    """

    body_map: dict[str, tuple[str, str]] = field(default_factory=dict)
    position_tol: float = 0.25
    tilt_tol_deg: float = 10.0
    yaw_tol_deg: float = 15.0
    table_z: float = 0.0
    resolution: float = 1e-4
    offset_floor: float = 3e-4
    """A block snapped onto a target cell from farther than this (m, in x or y) keeps the offset as a
    measured offset of the scene. 0.3 mm: above the creep of resting bodies and a tracker's
    resolution, below any offset that can make two flush neighbours touch."""

    def __post_init__(self):
        if not (math.isfinite(self.position_tol) and 0 < self.position_tol < 0.5):
            raise RadError(f'position_tol must be in (0, 0.5) units, got {self.position_tol!r}')
        if not (math.isfinite(self.tilt_tol_deg) and 0 < self.tilt_tol_deg < 45):
            raise RadError(f'tilt_tol_deg must be in (0, 45), got {self.tilt_tol_deg!r}')
        if not (math.isfinite(self.yaw_tol_deg) and 0 < self.yaw_tol_deg < 45):
            raise RadError(f'yaw_tol_deg must be in (0, 45), got {self.yaw_tol_deg!r}')
        if not math.isfinite(self.table_z):
            raise RadError(f'table_z must be finite, got {self.table_z!r}')
        if not (math.isfinite(self.resolution) and 0 <= self.resolution <= 0.01):
            raise RadError(f'resolution must be in 0..0.01 m, got {self.resolution!r}')
        if not (math.isfinite(self.offset_floor) and self.offset_floor >= 0):
            raise RadError(f'offset_floor must be finite and >= 0, got {self.offset_floor!r}')
        blocks = {}
        for body, entry in self.body_map.items():
            if not (isinstance(entry, (tuple, list)) and len(entry) == 2):
                raise RadError(f'body_map[{body!r}]: expected (block id, block type), got {entry!r}')
            if entry[0] in blocks:
                raise RadError(f'rigid bodies {blocks[entry[0]]!r} and {body!r} are both mapped to '
                               f'block {entry[0]!r}')
            blocks[entry[0]] = body

    @classmethod
    def for_noise(cls, position_noise: float, yaw_noise_deg: float, unit: float, **kw) -> RegistrationConfig:
        """The tolerances `kw` gives (or the defaults), widened where a tracker's noise (std dev: m per
        axis, deg) would otherwise push a correct pose past them: at least 5 sigma; measured offsets
        are kept from 3 sigma up.
        Raises RadError when the noise is too large to snap to a lattice of this unit at all."""
        if not (math.isfinite(position_noise) and position_noise >= 0 and math.isfinite(yaw_noise_deg)
                and yaw_noise_deg >= 0 and math.isfinite(unit) and unit > 0):
            raise RadError(f'registration noise: expected finite, non-negative noise and a positive unit, got '
                           f'{position_noise!r} m, {yaw_noise_deg!r} deg, unit {unit!r}')
        base = cls(**kw)
        position_tol = max(base.position_tol, 5 * position_noise / unit)
        yaw_tol = max(base.yaw_tol_deg, 5 * yaw_noise_deg)
        # A measured offset smaller than 3 sigma is as likely noise as a block off its cell.
        offset_floor = max(base.offset_floor, 3 * position_noise)
        if position_tol >= 0.45 or yaw_tol >= 40:
            raise RadError(f'motion-capture noise of {position_noise * 1000:.1f} mm and {yaw_noise_deg:g} deg is '
                           f'too large to register {unit * 1000:.0f} mm blocks reliably (5 sigma must stay under '
                           f'0.45 unit and 40 deg)')
        return replace(base, position_tol=position_tol, yaw_tol_deg=yaw_tol, offset_floor=offset_floor)


def body_map_for(scene: Scene, names: dict[str, str] | None = None) -> dict[str, tuple[str, str]]:
    """The body_map that registers `scene_to_bodies(scene, names)` back to scene's blocks."""
    names = names or {}
    return {names.get(b.id, b.id): (b.id, b.type) for b in scene.blocks}


def scene_to_bodies(scene: Scene, names: dict[str, str] | None = None,
                    table_z: float = 0.0) -> list[RigidBodyPose]:
    """What a motion-capture system would report for a scene, in block order.

    names maps block id -> rigid-body name (default: the block id).
    """
    names = names or {}
    out = []
    for b in scene.blocks:
        x, y, z = b.position
        out.append(RigidBodyPose(names.get(b.id, b.id), (x, y, z + table_z), yaw_quaternion(b.yaw)))
    return out


@dataclass(frozen=True)
class Registration:
    """A frame registered leniently (`register_world`): the scene of the blocks a scene can express,
    and the blocks set aside with why."""

    scene: Scene
    set_aside: dict[str, str] = field(default_factory=dict)
    """Block id -> why it cannot be in a scene now (fallen on its side, pushed off its cell, ...)."""
    in_regions: frozenset[str] = frozenset()
    """The set-aside blocks that lie over a target region (below its top)."""
    blocked: dict[str, tuple[tuple[int, int, int], ...]] = field(default_factory=dict)
    """Region name -> the target cells set-aside blocks occupy (and no registered block does)."""
    unseated: dict[str, float] = field(default_factory=dict)
    """Block id -> how far (m) above its seat it stands: studded bricks seen a stud's height up, standing
    on the studs under them, not pressed home (registered at their seat)."""

    def plannable(self) -> Scene:
        """The registered scene without the blocked cells among its targets' filled cells (a region left
        with none is dropped); RadError when no target cell is left to build."""
        if not self.blocked:
            return self.scene
        doc = self.scene.to_dict()
        targets = []
        for t in doc['targets']:
            gone = set(self.blocked.get(t['name'], ()))
            t['filled'] = [c for c in t['filled'] if tuple(c) not in gone]
            if t['filled']:
                targets.append(t)
        if not targets:
            raise RadError('every target cell is occupied by a block no scene can express ('
                           + '; '.join(f'{b}: {why}' for b, why in sorted(self.set_aside.items())) + ')')
        doc['targets'] = targets
        return Scene.from_dict(doc)


class _Unexpressible(RadError):
    """A body whose pose is real but cannot be a block of a scene (tilted, turned, off a lattice)."""


def register_scene(bodies: list[RigidBodyPose], template: Scene, config: RegistrationConfig) -> Scene:
    """The template's unit, block types and targets with one block per tracked body.

    The template's own blocks are ignored: the bodies are the truth. Body map
    entries without a reported body give no block (not seen, not there).
    Raises RadError naming the body for anything that cannot be a scene.
    """
    return _register(bodies, template, config, lenient=False).scene


def register_world(bodies: list[RigidBodyPose], template: Scene, config: RegistrationConfig) -> Registration:
    """As `register_scene`, but a body whose pose a scene cannot express is set aside with the
    reason instead of raising (see the module docstring); set-up errors still raise RadError."""
    return _register(bodies, template, config, lenient=True)


def _register(bodies: list[RigidBodyPose], template: Scene, config: RegistrationConfig,
              lenient: bool) -> Registration:
    seen_bodies: set[str] = set()
    blocks, names = [], []
    offsets: dict[str, list[float]] = {}
    set_aside: dict[str, str] = {}
    unseated: dict[str, float] = {}
    in_regions: set[str] = set()
    for body in bodies:
        name = body.name
        if name in seen_bodies:
            raise RadError(f'rigid body {name!r} is reported twice')
        seen_bodies.add(name)
        if name not in config.body_map:
            raise RadError(f'rigid body {name!r} is unknown (not in the body map; known: '
                           f'{_listing(config.body_map)})')
        block_id, block_type = config.body_map[name]
        if block_type not in template.block_types:
            raise RadError(f'rigid body {name!r}: block type {block_type!r} of block {block_id!r} is not '
                           f'in the scene\'s block types ({_listing(template.block_types)})')
        if not body.tracking_valid:
            raise RadError(f'rigid body {name!r} (block {block_id!r}) is not tracked (tracking_valid is '
                           f'false): its pose is unknown')
        if template.in_feeder(block_id) and template.at_station(
                block_id, np.asarray(body.position, dtype=float) - [0.0, 0.0, config.table_z]):
            continue        # presented by the feeder and not taken: still the feeder's (kept below)
        try:
            position, yaw, offset, raised = _snap(body, template, template.block_types[block_type], config,
                                                  lenient)
        except _Unexpressible as e:
            if not lenient:
                raise
            set_aside[block_id] = str(e)
            if _over_regions(body, template, template.block_types[block_type]):
                in_regions.add(block_id)
            continue
        blocks.append({'id': block_id, 'type': block_type, 'position': position, 'yaw': yaw})
        names.append(name)
        if raised:
            unseated[block_id] = raised
        if offset is not None and (len(offset) == 3 or max(abs(v) for v in offset) >= config.offset_floor):
            offsets[block_id] = offset
    by_block = {entry[0]: body for body in bodies for entry in [config.body_map.get(body.name)] if entry}
    doc = template.to_dict()
    if template.feeder is not None:
        # Motion capture cannot see into the feeder: its blocks stay there unless seen elsewhere.
        taken = {b['id'] for b in blocks} | set(set_aside)
        kept_in = [b for b in template.feeder.blocks if b not in taken]
        doc['feeder'] = {**doc['feeder'], 'blocks': kept_in}
        blocks = blocks + [{'id': b, 'type': template.block(b).type} for b in kept_in]
        names = names + [f'(feeder) {b}' for b in kept_in]
    while True:
        doc['blocks'] = blocks
        kept = {b['id'] for b in blocks}
        doc['measured_offsets'] = {k: v for k, v in offsets.items() if k in kept}
        doc['obstacles'] = [_obstacle(b, by_block[b], config) for b in sorted(set_aside)]
        try:
            scene = Scene.from_dict(doc)
        except SceneError as e:
            i = _blamed(e)
            if not lenient or i is None:
                raise RadError(_translate(e, names, blocks)) from None
            # The scene is valid but for this block (its pose is real: it overlaps or sticks into a region).
            set_aside[blocks[i]['id']] = _translate(e, names, blocks)
            block = blocks.pop(i)
            names.pop(i)
            body = by_block[block['id']]
            if _over_regions(body, template, template.block_types[block['type']]):
                in_regions.add(block['id'])
            continue
        blocked = _blocked_cells([by_block[b] for b in set_aside], [config.body_map[by_block[b].name][1]
                                                                    for b in set_aside], scene)
        return Registration(scene, set_aside, frozenset(in_regions), blocked,
                            {b: h for b, h in unseated.items() if b not in set_aside})


def _obstacle(block_id: str, body: RigidBodyPose, config: RegistrationConfig) -> dict:
    """A set-aside block as the scene's obstacle: where it lies, for motion planning."""
    quat = np.asarray(body.quaternion, dtype=float)
    x, y, z = (float(v) for v in body.position)
    return {'id': block_id, 'type': config.body_map[body.name][1], 'position': [x, y, z - config.table_z],
            'quaternion': (quat / np.linalg.norm(quat)).tolist()}


def _blocked_cells(bodies: list[RigidBodyPose], types: list[str], scene: Scene) -> dict[str, tuple]:
    """The filled target cells the bodies' units overlap (by more than BLOCKED_OVERLAP in every axis)
    that no block of the scene occupies."""
    u = scene.pitch
    taken = [scene.unit_positions(b) for b in scene.blocks]
    taken = np.vstack(taken) if taken else np.zeros((0, 3))
    out: dict[str, tuple] = {}
    for body, type_name in zip(bodies, types):
        pos = np.asarray(body.position, dtype=float)
        quat = np.asarray(body.quaternion, dtype=float)
        r = matrix_from_quaternion(quat / np.linalg.norm(quat))
        units = pos + (np.asarray(scene.block_types[type_name].offsets, dtype=float) * u) @ r.T
        half = np.abs(r) @ (u / 2)                    # half extents of a turned unit cell's bounding box
        for t in scene.targets:
            for ijk in t.filled:
                centre = t.cell_center(ijk, u)
                if len(taken) and np.any(np.all(np.abs(taken - centre) < u / 2, axis=1)):
                    continue
                if np.any(np.all(np.abs(units - centre) < half + u / 2 - BLOCKED_OVERLAP, axis=1)):
                    cells = out.setdefault(t.name, ())
                    if tuple(ijk) not in cells:
                        out[t.name] = cells + (tuple(int(v) for v in ijk),)
    return out


def _blamed(e: SceneError) -> int | None:
    """The index of the block a scene error names, or None when it is not about one block."""
    if not e.field.startswith('blocks['):
        return None
    return int(e.field[len('blocks['):e.field.index(']')])


def _over_regions(body: RigidBodyPose, template: Scene, block_type) -> bool:
    """Whether any unit of the block, at its measured pose, lies over a target region's footprint
    (below its top: a block fallen onto the structure or into a region's cells)."""
    pos = np.asarray(body.position, dtype=float)
    quat = np.asarray(body.quaternion, dtype=float)
    r = matrix_from_quaternion(quat / np.linalg.norm(quat))
    offsets = np.asarray(block_type.offsets, dtype=float) * template.pitch
    pts = pos + offsets @ r.T
    for t in template.targets:
        lo, hi = t.bounds(template.pitch)
        inside = np.all((pts[:, :2] > lo[:2]) & (pts[:, :2] < hi[:2]), axis=1) & (pts[:, 2] < hi[2] + template.course)
        if inside.any():
            return True
    return False


def _snap(body: RigidBodyPose, template: Scene, block_type, config: RegistrationConfig,
          lenient: bool = False) -> tuple[list[float], int, list[float] | None, float]:
    """The block's anchor position and yaw as a scene can express them, its measured offset from
    there: x/y (m) for a block snapped onto a target region's grid; [0, 0, turn (deg)] for one lying
    on the table turned off the lattice (lenient only; strict registration refuses it); else None;
    and how far (m) above its seat it stands: in a studded scene, a brick whose height fits a level
    plus a stud's height better than a level stands on the studs under it, not pressed home (0 else)."""
    name, u = body.name, template.unit
    pos = np.asarray(body.position, dtype=float).reshape(-1)
    quat = np.asarray(body.quaternion, dtype=float).reshape(-1)
    if pos.shape != (3,) or quat.shape != (4,):
        raise RadError(f'rigid body {name!r}: expected a 3-vector position and a 4-vector quaternion')
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))):
        raise RadError(f'rigid body {name!r}: pose contains NaN or infinity '
                       f'(position {pos.tolist()}, quaternion {quat.tolist()})')
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise RadError(f'rigid body {name!r}: quaternion {quat.tolist()} is not unit length (norm {norm:.4f})')
    r = matrix_from_quaternion(quat / norm)
    tilt = math.degrees(math.acos(min(1.0, max(-1.0, r[2, 2]))))
    if tilt > config.tilt_tol_deg:
        raise _Unexpressible(f'rigid body {name!r} is tilted {tilt:.1f} deg from upright (limit '
                       f'{config.tilt_tol_deg:g}): a block must lie flat, not on its side or an edge')
    yaw = math.degrees(math.atan2(r[1, 0], r[0, 0]))
    snapped_yaw = round(yaw / 90.0) * 90
    turned = yaw - snapped_yaw
    if abs(turned) > config.yaw_tol_deg:
        turn_error = (f'rigid body {name!r}: yaw {yaw:.1f} deg is {abs(turned):.1f} deg from a multiple of 90 '
                      f'(limit {config.yaw_tol_deg:g})')
        if not lenient:
            raise _Unexpressible(turn_error)
    else:
        turn_error = ''
    snapped_yaw %= 360

    c = template.course
    height = (pos[2] - config.table_z - c / 2) / c
    level = round(height)
    raised = 0.0
    if template.stud_height:
        on_studs = height - template.stud_height / c
        seat = round(on_studs)
        if seat >= 1 and abs(on_studs - seat) < abs(height - level):
            # Higher than a seat by about a stud (the table has none): on the studs of the brick under it.
            raised = round((height - seat) * c, 4)
            height, level = on_studs, seat
    if abs(height - level) > config.position_tol:
        raise _Unexpressible(f'rigid body {name!r}: height {pos[2]:.4f} m is {abs(height - level) * c * 1000:.1f} mm '
                       f'off the unit lattice above the table (limit {config.position_tol * c * 1000:.1f} mm)')
    out = [_quantise(pos[0], config.resolution), _quantise(pos[1], config.resolution),
           round(c / 2 + level * c, _DECIMALS)]

    region = _region_of(template, snapped_yaw, block_type, np.array(out))
    if turn_error:
        # Lying flat on the table, turned off the lattice (a block that slipped or fell): registered at
        # the nearest yaw a scene has, the turn kept as its measured offset, so it can be picked up
        # where it really lies and put down straight. Anywhere else it cannot be expressed.
        if region is not None or level != 0 or _over_regions(body, template, block_type):
            raise _Unexpressible(turn_error)
        return out, snapped_yaw, [0.0, 0.0, round(turned, 3)], raised
    if region is not None:
        origin = np.asarray(region.origin)
        idx = (np.array(out[:2]) - origin[:2]) / u
        off = np.abs(idx - np.round(idx))
        tol = grid_tolerance(config, template)
        if off.max() > tol:
            raise _Unexpressible(f'rigid body {name!r} is in target region {region.name!r} but '
                           f'{off.max() * u * 1000:.1f} mm off its grid '
                           f'(limit {tol * u * 1000:.1f} mm)')
        measured = out[:2]
        for a in range(2):
            out[a] = round(float(origin[a] + u * np.round(idx[a])), _DECIMALS)
        return out, snapped_yaw, [round(measured[a] - out[a], _DECIMALS) for a in range(2)], raised
    return out, snapped_yaw, None, raised


def grid_tolerance(config: RegistrationConfig, scene: Scene) -> float:
    """How far (fraction of a unit) a block in a target region may be off its cell centre
    in x/y and still register to it: position_tol, plus the room a clearance leaves."""
    if not scene.clearance:
        return config.position_tol
    return min(config.position_tol + scene.clearance / 2, 0.49)


def _quantise(x: float, step: float) -> float:
    return float(x) if step == 0 else round(round(float(x) / step) * step, _DECIMALS)


def _region_of(scene: Scene, yaw: int, block_type, anchor: np.ndarray):
    """The target region holding most of the block's units (by unit centre), or None."""
    pts = anchor + scene.pitch * block_type.rotated(yaw)
    best, best_count = None, 0
    for t in scene.targets:
        lo, hi = t.bounds(scene.pitch)
        count = int(np.all((pts > lo) & (pts < hi), axis=1).sum())
        if count > best_count:
            best, best_count = t, count
    return best


def _translate(e: SceneError, names: list[str], blocks: list[dict]) -> str:
    """Scene validation speaks of blocks[i]; the user knows rigid bodies."""
    field_ = e.field
    if field_.startswith('blocks['):
        i = int(field_[len('blocks['):field_.index(']')])
        problem = e.problem
        for j, b in enumerate(blocks):
            if j != i and repr(b['id']) in problem:
                problem = problem.replace(repr(b['id']), f'{b["id"]!r} (rigid body {names[j]!r})')
        return f'rigid body {names[i]!r} (block {blocks[i]["id"]!r}): {problem}'
    return f'registered scene is invalid: {e}'


def _listing(keys) -> str:
    keys = sorted(keys)
    text = ', '.join(repr(k) for k in keys[:8])
    return text + (f', ... ({len(keys)} in all)' if len(keys) > 8 else '') if keys else 'none'

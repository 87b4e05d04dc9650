"""Motion capture as real drivers publish it, turned into what registration expects.

A cell's motion capture (natnet_ros2, vrpn_mocap, mocap4r2) differs from what
`rad_core.cell.mocap.register_scene` takes in four ways, each handled here:

- Names. Bodies are named in the tracker's software ('Block_3'), not by block
  id, and other things are tracked too (a tool, the robot's flange). A `BodyMap`
  maps body names to block ids and lists bodies to ignore; a block without an
  entry is tracked by a body named like the block. A body that is neither mapped
  nor ignored is skipped and reported once: it must not fail a registration.
- Pivots. A body's pose is wherever its pivot was put when it was defined (the
  markers' centroid, a corner), not the centre of the block's anchor unit.
  Each entry gives the pivot's offset from the anchor unit's centre in the
  block frame, so p_anchor = p_pivot - R_body @ pivot.
- Frames. Poses arrive in the motion-capture frame. `FrameTransform` is the
  calibration mocap -> base (p_base = R p_mocap + t, orientation q_base =
  q_cal * q_mocap); every message's frame_id is checked against the frame the
  cell says motion capture reports in, and a mismatch is refused naming both.
  Motion capture whose frame cannot be told from the base frame, or that has no
  calibration, is refused unless the cell says it reports in the base frame.
- Dropouts. A marker set hidden behind the arm is reported with tracking_valid
  false or not at all. That block is "not seen" for the moment, not gone:
  `MocapTracker` keeps each body's last valid pose and when it was last seen,
  `wait_for_bodies` waits (bounded) until every block is seen and fails naming
  each block whose body stays lost longer than lost_timeout_s.

Pure Python (no rclpy): rad_ros.mocap_input feeds the tracker from the three
message formats (and fiducial tags on /tf), the assembly node calls `wait_for_bodies`.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from rad_core.cell.mocap import RigidBodyPose
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion

# A calibration quaternion off unit length by more than this is a typo or a wrong field
# order, not rounding in a parameter file.
QUAT_UNIT_TOL = 1e-3
# A pivot further than this from the anchor unit's centre is not on the block.
MAX_PIVOT_M = 0.5
# Bodies the tracker keeps at most: a driver streaming more is misconfigured, and the
# tracker must not grow without bound on its input.
MAX_BODIES = 1024


def _vector(value, n: int, what: str) -> tuple[float, ...]:
    """value as n finite floats, or RadError naming `what`."""
    if isinstance(value, (str, bytes)) or not hasattr(value, '__len__') or len(value) != n:
        raise RadError(f'{what} must be {n} numbers, got {value!r}')
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise RadError(f'{what} must be {n} numbers, got {value!r}') from None
    if not all(math.isfinite(v) for v in out) or any(isinstance(v, bool) for v in value):
        raise RadError(f'{what} must be {n} finite numbers, got {list(value)!r}')
    return out


def _name(value, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise RadError(f'{what} must be a non-empty string, got {value!r}')
    return value


def _body_name(value):
    """A body name as written in a body map: numbers as text (mocap4r2's OptiTrack driver names rigid
    bodies by their Motive ID, '1', '2', ..., which YAML reads as integers)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    return value


def quaternion_multiply(a, b) -> tuple[float, float, float, float]:
    """a * b for quaternions x, y, z, w (b first, then a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


# ---- the calibration ---------------------------------------------------------------

@dataclass(frozen=True)
class FrameTransform:
    """mocap -> base: p_base = R(quaternion) p_mocap + translation (m; quaternion x, y, z, w)."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def __post_init__(self):
        t = _vector(self.translation, 3, 'mocap_to_base_translation')
        q = _vector(self.quaternion, 4, 'mocap_to_base_quaternion ([x, y, z, w])')
        norm = math.sqrt(sum(v * v for v in q))
        if abs(norm - 1.0) > QUAT_UNIT_TOL:
            raise RadError(f'mocap_to_base_quaternion {list(q)} is not unit length (norm {norm:.6f}); '
                           'give [x, y, z, w] of a rotation')
        object.__setattr__(self, 'translation', t)
        object.__setattr__(self, 'quaternion', tuple(v / norm for v in q))

    @property
    def rotation(self) -> np.ndarray:
        return matrix_from_quaternion(self.quaternion)

    @property
    def is_identity(self) -> bool:
        return all(v == 0.0 for v in self.translation) and abs(abs(self.quaternion[3]) - 1.0) < 1e-12

    def apply(self, position, quaternion) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """A pose (position, orientation x, y, z, w) from the motion-capture frame into the base frame."""
        p = self.rotation @ np.asarray(position, dtype=float) + np.asarray(self.translation)
        q = quaternion_multiply(self.quaternion, tuple(float(v) for v in quaternion))
        return (float(p[0]), float(p[1]), float(p[2])), q

    def inverse(self) -> FrameTransform:
        """base -> mocap (what a motion-capture system in that frame reports for a base-frame pose)."""
        x, y, z, w = self.quaternion
        conj = (-x, -y, -z, w)
        t = -(matrix_from_quaternion(conj) @ np.asarray(self.translation))
        return FrameTransform(tuple(float(v) for v in t), conj)


@dataclass(frozen=True)
class MocapFrames:
    """Which frame motion capture reports in and how it maps to the robot base frame.

    frame_id: the robot base frame (the assembly node's frame_id; 'base' for franka_description).
    mocap_frame: the frame motion capture reports in; '' = frame_id.
    transform: the calibration mocap_frame -> frame_id.
    in_base_frame: the cell says motion capture already reports in the base frame (no calibration;
        the twin's case). Without it, motion capture whose frame cannot be told from the base frame
        (mocap_frame '' or equal to frame_id) or that has no calibration (the identity) is refused:
        `refusal` says why, naming both frames and the fix, and `check` raises it for every message.
        Drivers report in a frame of their own by default ('world' for natnet_ros2 and vrpn_mocap,
        'map' for mocap4r2), so raw motion-capture coordinates must never pass as base coordinates.
    """

    frame_id: str = 'world'
    mocap_frame: str = ''
    transform: FrameTransform = field(default_factory=FrameTransform)
    in_base_frame: bool = False

    def __post_init__(self):
        _name(self.frame_id, 'frame_id')
        if not isinstance(self.mocap_frame, str):
            raise RadError(f'mocap_frame must be a string, got {self.mocap_frame!r}')
        if not isinstance(self.in_base_frame, bool):
            raise RadError(f'mocap_in_base_frame must be true or false, got {self.in_base_frame!r}')
        if self.transform.is_identity:
            return
        if not self.distinct:
            said = "is ''" if not self.mocap_frame else f'equals frame_id {self.frame_id!r}'
            raise RadError(f'mocap_to_base_translation/quaternion give a calibration, but mocap_frame {said}: '
                           'set mocap_frame to the frame motion capture reports in')
        if self.in_base_frame:
            raise RadError(f'mocap_in_base_frame is true (motion capture reports in frame_id {self.frame_id!r}), '
                           f'but mocap_to_base_translation/quaternion give a calibration from mocap_frame '
                           f'{self.mocap_frame!r}: keep one of the two')

    @classmethod
    def from_params(cls, frame_id, mocap_frame, translation, quaternion, in_base_frame=False) -> MocapFrames:
        return cls(frame_id, mocap_frame, FrameTransform(translation, quaternion), in_base_frame)

    @property
    def distinct(self) -> bool:
        """mocap_frame names a frame other than frame_id."""
        return bool(self.mocap_frame) and self.mocap_frame != self.frame_id

    @property
    def refusal(self) -> str:
        """Why motion capture cannot be taken in these frames ('' when it can)."""
        if self.in_base_frame or not self.transform.is_identity:
            return ''
        fix = ('set mocap_frame to the frame your driver reports in (natnet_ros2: its global_frame, vrpn_mocap: its '
               "frame_id, 'world' by default; mocap4r2: 'map'; a camera: its optical frame) and "
               'mocap_to_base_translation / mocap_to_base_quaternion to the calibration `rad calibrate` prints '
               '(`rad calibrate --hand-eye` for a camera), or set mocap_in_base_frame: true if motion capture '
               f'really reports in the robot base frame {self.frame_id!r} (the twin does)')
        if not self.distinct:
            said = ("mocap_frame is '', which means" if not self.mocap_frame
                    else f'mocap_frame {self.mocap_frame!r} equals')
            return (f'motion capture refused: {said} the robot base frame frame_id {self.frame_id!r}, and no '
                    'calibration is given, so raw motion-capture coordinates would pass as base coordinates: '
                    + fix)
        return (f'motion capture refused: mocap_frame {self.mocap_frame!r} is not the robot base frame frame_id '
                f'{self.frame_id!r}, but no calibration from {self.mocap_frame!r} to {self.frame_id!r} is given '
                '(mocap_to_base_translation/quaternion are the identity): ' + fix)

    @property
    def calibrated(self) -> bool:
        """True when motion capture reports in a frame of its own, under the base (/tf_static)."""
        return self.distinct and not self.refusal

    @property
    def expected_frame(self) -> str:
        """The frame_id every incoming motion-capture message must carry."""
        return self.mocap_frame or self.frame_id

    def check(self, frame_id: str, source: str) -> None:
        if self.refusal:
            raise RadError(self.refusal)
        if frame_id != self.expected_frame:
            where = (f"mocap_frame is {self.mocap_frame!r}" if self.mocap_frame
                     else f"mocap_frame is '' so motion capture must report in frame_id {self.frame_id!r}")
            raise RadError(f'{source} is in frame {frame_id!r}, expected {self.expected_frame!r} ({where}): '
                           'set mocap_frame (and the calibration) to the frame your motion capture reports in')


# ---- the body map ------------------------------------------------------------------

@dataclass(frozen=True)
class BodyEntry:
    """One tracked body: the block it is on and its pivot's offset from the anchor unit's centre
    (m, in the block frame)."""

    body: str
    block: str
    pivot: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        _name(self.body, 'a body name in the body map')
        _name(self.block, f'body map entry {self.body!r}: block')
        pivot = _vector(self.pivot, 3, f'body map entry {self.body!r}: pivot')
        if math.hypot(*pivot) > MAX_PIVOT_M:
            raise RadError(f'body map entry {self.body!r}: pivot {list(pivot)} is {math.hypot(*pivot):.3f} m from '
                           f'the anchor unit (limit {MAX_PIVOT_M} m): give metres, not millimetres')
        object.__setattr__(self, 'pivot', pivot)


@dataclass(frozen=True)
class ResolvedBodies:
    """A body map applied to one task's blocks (block id -> type, in the task's order)."""

    by_body: dict[str, BodyEntry]
    """Body name -> entry, for each block of the task."""
    block_types: dict[str, str]
    other_blocks: dict[str, str]
    """Body name -> block id for bodies mapped to blocks the task does not have."""
    ignore: frozenset[str]

    @property
    def registration_map(self) -> dict[str, tuple[str, str]]:
        """The body_map RegistrationConfig takes: body name -> (block id, block type)."""
        return {b: (e.block, self.block_types[e.block]) for b, e in self.by_body.items()}

    def describe(self, body: str) -> str:
        entry = self.by_body[body]
        return f'block {entry.block!r}' + (f' (rigid body {body!r})' if body != entry.block else '')


@dataclass(frozen=True)
class BodyMap:
    """Body names -> blocks and pivots, and bodies to ignore.

    A block without an entry is tracked by a body named like the block, its pivot
    at the anchor unit's centre (what the twin publishes).
    """

    entries: tuple[BodyEntry, ...] = ()
    ignore: frozenset[str] = frozenset()

    def __post_init__(self):
        bodies, blocks = set(), {}
        for e in self.entries:
            if e.body in bodies:
                raise RadError(f'body map: rigid body {e.body!r} is listed twice')
            if e.block in blocks:
                raise RadError(f'body map: rigid bodies {blocks[e.block]!r} and {e.body!r} are both mapped to '
                               f'block {e.block!r}')
            bodies.add(e.body)
            blocks[e.block] = e.body
        for name in self.ignore:
            _name(name, 'an ignored body name')
            if name in bodies:
                raise RadError(f'body map: rigid body {name!r} is both mapped and ignored')
        object.__setattr__(self, 'ignore', frozenset(self.ignore))

    @classmethod
    def from_dict(cls, doc, ignore: Iterable[str] = (), where: str = 'body map') -> BodyMap:
        """{bodies: {NAME: {block: ID, pivot: [x, y, z]}}, ignore: [NAME, ...]} (both optional)."""
        if doc is None:
            doc = {}
        if not isinstance(doc, Mapping):
            raise RadError(f'{where}: expected a mapping with "bodies" and "ignore", got {type(doc).__name__}')
        unknown = set(doc) - {'bodies', 'ignore'}
        if unknown:
            raise RadError(f'{where}: unknown keys {sorted(map(str, unknown))} (expected bodies, ignore)')
        bodies = doc.get('bodies') or {}
        if not isinstance(bodies, Mapping):
            raise RadError(f'{where}: "bodies" must map body names to {{block, pivot}}')
        entries = []
        for body, spec in bodies.items():
            if not isinstance(spec, Mapping) or 'block' not in spec or set(spec) - {'block', 'pivot'}:
                raise RadError(f'{where}: body {body!r} must be {{block: ID, pivot: [x, y, z]}} (pivot optional), '
                               f'got {spec!r}')
            entries.append(BodyEntry(_name(_body_name(body), f'{where}: a body name'), _body_name(spec['block']),
                                     spec.get('pivot', (0.0, 0.0, 0.0))))
        listed = doc.get('ignore') or []
        if isinstance(listed, str) or not isinstance(listed, (list, tuple)):
            raise RadError(f'{where}: "ignore" must be a list of body names, got {listed!r}')
        return cls(tuple(entries), frozenset(_body_name(n) for n in listed) | frozenset(ignore))

    @classmethod
    def load(cls, path: str | Path, ignore: Iterable[str] = ()) -> BodyMap:
        """A body map file: YAML (.yaml, .yml) or JSON (anything else)."""
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as e:
            raise RadError(f'body map {path}: cannot read it ({e.strerror or e})') from None
        kind = 'YAML' if path.suffix.lower() in ('.yaml', '.yml') else 'JSON'
        try:
            if kind == 'YAML':
                doc = yaml.safe_load(text)
            else:
                doc = json.loads(text)
        except Exception as e:  # noqa: BLE001 - any parser error is a bad file
            first = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise RadError(f'body map {path}: not valid {kind} ({first})') from None
        return cls.from_dict(doc, ignore, where=f'body map {path}')

    @classmethod
    def from_params(cls, path: str, ignore: Iterable[str] = ()) -> BodyMap:
        """The assembly node's body_map_file ('' = no file) and ignore_bodies."""
        ignore = [str(n) for n in ignore if str(n)]
        return cls.load(path, ignore) if path else cls((), frozenset(ignore))

    def resolve(self, blocks: Mapping[str, str]) -> ResolvedBodies:
        """The body of each of a task's blocks (block id -> type); RadError when two would share a name."""
        by_block = {e.block: e for e in self.entries}
        by_body: dict[str, BodyEntry] = {}
        for block in blocks:
            entry = by_block.get(block) or BodyEntry(block, block)
            if entry.body in self.ignore:
                raise RadError(f'block {block!r} is tracked by rigid body {entry.body!r}, which ignore_bodies lists')
            if entry.body in by_body:
                raise RadError(f'rigid body {entry.body!r} would be both block {by_body[entry.body].block!r} and '
                               f'block {block!r}: map each block to a body of its own in the body map')
            by_body[entry.body] = entry
        other = {e.body: e.block for e in self.entries if e.block not in blocks}
        return ResolvedBodies(by_body, dict(blocks), other, self.ignore)


# ---- the tracker ---------------------------------------------------------------------

@dataclass
class _Track:
    position: tuple[float, float, float] | None = None      # last valid pose, motion-capture frame
    quaternion: tuple[float, float, float, float] | None = None
    last_valid: float | None = None                         # when it was last seen valid
    visible: bool = False                                   # seen in the latest frame of a frame source


@dataclass(frozen=True)
class Snapshot:
    """The tracker's view of one task's blocks at one moment.

    bodies: base frame, anchor poses, body names, for every block whose body has
        been seen valid (its last valid pose when it is not seen now).
    not_seen: block id -> seconds since its body was last seen valid (since the
        tracker started when never), for blocks not seen now but not yet lost.
    """

    bodies: list[RigidBodyPose]
    not_seen: dict[str, float]
    warnings: list[str]


class MocapTracker:
    """Per body: the last valid pose and when it was seen. Thread-safe (driver callbacks feed it,
    requests read it)."""

    def __init__(self, frames: MocapFrames, lost_timeout_s: float = 2.0, fresh_s: float = 1.0,
                 start: float | None = None, clock: Callable[[], float] = time.monotonic):
        if not (isinstance(lost_timeout_s, (int, float)) and math.isfinite(lost_timeout_s) and lost_timeout_s > 0):
            raise RadError(f'lost_timeout_s must be a positive number of seconds, got {lost_timeout_s!r}')
        if not (isinstance(fresh_s, (int, float)) and math.isfinite(fresh_s) and fresh_s > 0):
            raise RadError(f'the freshness bound must be a positive number of seconds, got {fresh_s!r}')
        self.frames = frames
        self.lost_timeout_s = float(lost_timeout_s)
        self.fresh_s = float(fresh_s)
        self.clock = clock
        self.start = clock() if start is None else float(start)
        self.tracks: dict[str, _Track] = {}
        self.last_message: float | None = None
        self.refused: tuple[float, str] | None = None
        self.warned: set[str] = set()
        self.lock = threading.Lock()

    # -- input ------------------------------------------------------------------------
    def _accept(self, frame_id: str, source: str, now: float) -> None:
        try:
            self.frames.check(frame_id, source)
        except RadError as e:
            self.refused = (now, str(e))
            raise

    def _track(self, name: str) -> _Track | None:
        track = self.tracks.get(name)
        if track is None and len(self.tracks) < MAX_BODIES:
            track = self.tracks[name] = _Track()
        return track

    @staticmethod
    def _valid(body: RigidBodyPose) -> bool:
        values = (*body.position, *body.quaternion)
        return bool(body.tracking_valid) and len(values) == 7 and all(math.isfinite(v) for v in values)

    def _update(self, track: _Track, body: RigidBodyPose, now: float) -> None:
        if self._valid(body):
            track.position = tuple(float(v) for v in body.position)
            track.quaternion = tuple(float(v) for v in body.quaternion)
            track.last_valid, track.visible = now, True
        else:
            track.visible = False

    def frame(self, frame_id: str, bodies: Iterable[RigidBodyPose], now: float | None = None,
              source: str = 'motion capture') -> None:
        """One frame of all bodies (rad or mocap4r2 RigidBodies). A body missing from it or with
        tracking_valid false is not seen from now on; its last valid pose is kept."""
        now = self.clock() if now is None else now
        bodies = list(bodies)
        with self.lock:
            self._accept(frame_id, source, now)
            names = [b.name for b in bodies]
            if len(set(names)) != len(names):
                twice = sorted({n for n in names if names.count(n) > 1})
                reason = f'{source}: rigid bod{"y" if len(twice) == 1 else "ies"} {twice} reported twice in one frame'
                self.refused = (now, reason)
                raise RadError(reason)
            self.last_message = now
            for track in self.tracks.values():
                track.visible = False
            for body in bodies:
                track = self._track(body.name)
                if track is not None:
                    self._update(track, body, now)

    def pose(self, frame_id: str, body: RigidBodyPose, now: float | None = None,
             source: str = 'motion capture') -> None:
        """One body's pose (a per-body PoseStamped topic): seen while its latest valid pose is fresh."""
        now = self.clock() if now is None else now
        with self.lock:
            self._accept(frame_id, source, now)
            self.last_message = now
            track = self._track(body.name)
            if track is not None:
                self._update(track, body, now)

    # -- output -----------------------------------------------------------------------
    def _seen(self, track: _Track | None, now: float) -> bool:
        return (track is not None and track.visible and track.last_valid is not None
                and now - track.last_valid <= self.fresh_s)

    def _warnings(self, resolved: ResolvedBodies) -> list[str]:
        out = []
        for name in sorted(self.tracks):
            if name in resolved.by_body or name in resolved.ignore or name in self.warned:
                continue
            self.warned.add(name)
            if name in resolved.other_blocks:
                out.append(f'rigid body {name!r} is mapped to block {resolved.other_blocks[name]!r}, which the task '
                           'does not have: skipped')
            else:
                out.append(f'rigid body {name!r} is not in the body map and names no block of the task: skipped '
                           '(list it in ignore_bodies to silence this)')
        if len(self.tracks) >= MAX_BODIES and '' not in self.warned:
            self.warned.add('')
            out.append(f'motion capture reports more than {MAX_BODIES} rigid bodies: the rest are not tracked')
        return out

    def snapshot(self, resolved: ResolvedBodies, now: float | None = None, optional=frozenset()) -> Snapshot:
        """The task's blocks as motion capture sees them now; RadError naming each block whose body has
        not been seen for longer than lost_timeout_s (and why, when the input was refused). optional:
        blocks that may never be seen (in a feeder: no camera sees into it), left out until they are."""
        now = self.clock() if now is None else now
        with self.lock:
            warnings = self._warnings(resolved)
            silent = now - (self.start if self.last_message is None else self.last_message)
            if silent > self.lost_timeout_s:
                what = (f'for {silent:.1f} s' if self.last_message is not None
                        else f'since motion capture input started {silent:.1f} s ago')
                raise RadError(f'no motion capture {what}: is the motion capture (or the twin) running?'
                               + self._refusal(now))
            bodies, not_seen, lost = [], {}, []
            for body, entry in resolved.by_body.items():
                track = self.tracks.get(body)
                if self._seen(track, now):
                    bodies.append(self._anchor(body, entry, track))
                    continue
                since = track.last_valid if track is not None and track.last_valid is not None else None
                if since is None and entry.block in optional:
                    continue
                age = now - (self.start if since is None else since)
                if age > self.lost_timeout_s:
                    lost.append(f'{resolved.describe(body)} ' + (f'not seen for {age:.1f} s' if since is not None
                                                                 else 'never seen'))
                    continue
                not_seen[entry.block] = age
                if since is not None:
                    bodies.append(self._anchor(body, entry, track))
            if lost:
                raise RadError(f'motion capture lost {"; ".join(lost)} (lost_timeout_s {self.lost_timeout_s:g}): '
                               'is it in the capture volume, its markers visible, its body named as the body map '
                               'says?' + self._refusal(now))
            return Snapshot(bodies, not_seen, warnings)

    def _refusal(self, now: float) -> str:
        if self.refused is None or (self.last_message is not None and self.last_message > self.refused[0]):
            return ''
        return f'; the latest motion capture was refused {now - self.refused[0]:.1f} s ago: {self.refused[1]}'

    def _anchor(self, body: str, entry: BodyEntry, track: _Track) -> RigidBodyPose:
        """The anchor unit's pose in the base frame from the pivot's pose in the motion-capture frame."""
        position, quaternion = self.frames.transform.apply(track.position, track.quaternion)
        q = np.asarray(quaternion)
        norm = float(np.linalg.norm(q))
        if any(entry.pivot) and norm > 0:
            offset = matrix_from_quaternion(q / norm) @ np.asarray(entry.pivot)
            position = tuple(float(p - o) for p, o in zip(position, offset))
        return RigidBodyPose(body, position, quaternion, True)


def wait_for_bodies(tracker: MocapTracker, resolved: ResolvedBodies, timeout_s: float | None = None,
                    poll_s: float = 0.02, sleep: Callable[[float], None] = time.sleep,
                    warn: Callable[[str], None] | None = None, optional=frozenset()) -> list[RigidBodyPose]:
    """The task's bodies for register_scene, once every block is seen.

    Waits up to timeout_s (default: the tracker's lost_timeout_s) for blocks that
    are momentarily not seen. A block whose body stays lost longer than
    lost_timeout_s fails the wait with a RadError naming it; a block seen within
    that bound but never all at once with the others registers at its last valid
    pose; a block never seen at all fails naming it, unless it is `optional` (in the task's
    feeder: seen only once presented).
    """
    timeout_s = tracker.lost_timeout_s if timeout_s is None else timeout_s
    deadline = tracker.clock() + timeout_s
    while True:
        snap = tracker.snapshot(resolved, optional=optional)
        for message in snap.warnings:
            if warn is not None:
                warn(message)
        if not snap.not_seen:
            return snap.bodies
        if tracker.clock() >= deadline:
            posed = {resolved.by_body[b.name].block for b in snap.bodies}
            never = sorted(b for b in snap.not_seen if b not in posed)
            if never:
                names = ', '.join(resolved.describe(body) for body, e in resolved.by_body.items() if e.block in never)
                raise RadError(f'motion capture has not seen {names} yet (waited {timeout_s:g} s)')
            return snap.bodies
        sleep(poll_s)

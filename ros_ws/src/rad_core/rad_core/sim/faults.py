"""The faults of a real cell, for the twin to inject: what each is, how likely, how large.

A real cell's motion capture is noisy and drops bodies and frames; a real hand
leaves a block a few millimetres from where it was meant to go, sometimes loses
it during the carry, sometimes closes on nothing, and its fingers sometimes push
a neighbour. A studded brick is sometimes not pressed home, or a brick is knocked off
its studs. Its controllers, too, now and then refuse a goal or end one early: an arm
held back, a hand that stops short. `FaultConfig` says how often and how much; the twin
(`rad_core.sim.twin`) injects them and records each as an event, so tests and
benchmarks can count injected against recovered faults.

All faults are off by default and each is set on its own. They are seeded: the
twin draws every fault kind from its own numpy Generator seeded with
``(seed, kind)``, so turning one fault on or off does not change when another
happens.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import yaml

from rad_core.domain.errors import RadError

KINDS = ('noise', 'drop_body', 'drop_frame', 'placement', 'slip', 'miss', 'nudge',
         'arm_abort', 'arm_reject', 'gripper_abort', 'gripper_reject', 'unpressed', 'knock')
"""The fault kinds, each with its own random stream (index = stream number)."""

_PROBABILITIES = ('drop_body', 'drop_frame', 'slip', 'miss', 'nudge', 'arm_abort', 'arm_reject', 'gripper_abort',
                  'gripper_reject', 'unpressed', 'knock')
_MAGNITUDES = ('mocap_position_noise', 'mocap_yaw_noise_deg', 'placement_error', 'nudge_distance', 'knock_speed')


@dataclass(frozen=True)
class FaultConfig:
    """Which faults the twin injects, how often (probabilities) and how large (SI units)."""

    seed: int = 0
    """Seed of the faults' random streams."""
    mocap_position_noise: float = 0.0
    """Std dev (m) per axis of each reported body position."""
    mocap_yaw_noise_deg: float = 0.0
    """Std dev (deg) of each reported body yaw."""
    drop_body: float = 0.0
    """Probability that a body is missing from a frame (reported with tracking_valid false and its
    last reported pose, as mocap4r2 and rad's RigidBodies do; not published on its PoseStamped topic)."""
    drop_frame: float = 0.0
    """Probability that a whole motion-capture frame is not published (the node's business)."""
    placement_error: float = 0.0
    """Std dev (m) of the x/y offset a released block is left at."""
    slip: float = 0.0
    """Probability that a held block slips out of the hand at a random moment of the carry."""
    miss: float = 0.0
    """Probability that a grasp misses: the hand closes on nothing."""
    nudge: float = 0.0
    """Probability that the fingers push a neighbour of a block they release."""
    nudge_distance: float = 0.004
    """How far (m) a nudged neighbour is pushed."""
    arm_abort: float = 0.0
    """Probability that the arm controller stops a trajectory partway (PATH_TOLERANCE_VIOLATED), as it
    does when something holds the arm back; the arm stops where it is, still moving when it is told."""
    arm_reject: float = 0.0
    """Probability that the arm controller refuses a trajectory (INVALID_GOAL): the arm does not move."""
    gripper_abort: float = 0.0
    """Probability that the hand stops short of an opening move (open, release): the goal ends aborted,
    reached_goal false, the fingers where they stopped."""
    gripper_reject: float = 0.0
    """Probability that the gripper action refuses a command: the fingers do not move."""
    unpressed: float = 0.0
    """Probability that a studded brick the arm pressed is not pressed home (a stud caught on the edge of
    its socket): it is let go standing on the studs under it, not joined to them, and motion capture
    sees it a stud's height above its seat."""
    knock: float = 0.0
    """Probability that letting go of a brick knocks a brick of the structure off its studs: that brick's
    studs let go and it is pushed sideways at `knock_speed`."""
    knock_speed: float = 1.0
    """How fast (m/s) a knocked brick is pushed off."""

    def __post_init__(self):
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise RadError(f'faults: seed must be a non-negative integer, got {self.seed!r}')
        for name in _PROBABILITIES:
            v = getattr(self, name)
            if not (_is_number(v) and 0.0 <= v <= 1.0):
                raise RadError(f'faults: {name} is a probability and must be in [0, 1], got {v!r}')
        for name in _MAGNITUDES:
            v = getattr(self, name)
            if not (_is_number(v) and math.isfinite(v) and v >= 0.0):
                raise RadError(f'faults: {name} must be finite and >= 0, got {v!r}')

    @classmethod
    def none(cls) -> FaultConfig:
        """No faults: the twin reports exact poses and places blocks exactly."""
        return cls()

    @classmethod
    def realistic(cls, seed: int = 0) -> FaultConfig:
        """A real cell's levels: 1 mm and 0.5 deg motion-capture noise, 2 % dropped bodies, 1 % dropped
        frames, 2 mm placement error, 5 % slipped grasps, 2 % missed grasps, 5 % nudges."""
        return cls(seed=seed, mocap_position_noise=0.001, mocap_yaw_noise_deg=0.5, drop_body=0.02, drop_frame=0.01,
                   placement_error=0.002, slip=0.05, miss=0.02, nudge=0.05)

    @classmethod
    def from_dict(cls, doc, seed: int | None = None, where: str = 'faults') -> FaultConfig:
        """From a mapping of FaultConfig fields; unknown keys are refused, naming them. `seed`, when given,
        is used where the mapping has none."""
        if not isinstance(doc, dict):
            raise RadError(f'{where}: expected a mapping of fault settings, got {type(doc).__name__}')
        known = {f.name for f in fields(cls)}
        unknown = sorted(str(k) for k in doc if k not in known)
        if unknown:
            raise RadError(f'{where}: unknown fault setting(s) {", ".join(unknown)} '
                           f'(known: {", ".join(sorted(known))})')
        values = dict(doc)
        if seed is not None:
            values.setdefault('seed', seed)
        return cls(**values)

    @classmethod
    def from_file(cls, path: str | Path, seed: int | None = None) -> FaultConfig:
        """A JSON (.json) or YAML (.yaml, .yml; needs PyYAML) file with FaultConfig fields."""
        path = Path(path)
        try:
            text = path.read_text(encoding='utf-8')
        except OSError as e:
            raise RadError(f'faults file {str(path)!r} cannot be read: {e.strerror}') from None
        except UnicodeDecodeError:
            raise RadError(f'faults file {str(path)!r} is not UTF-8 text') from None
        if path.suffix.lower() in ('.yaml', '.yml'):
            try:
                doc = yaml.safe_load(text)
            except yaml.YAMLError as e:
                raise RadError(f'faults file {str(path)!r} is not valid YAML: {e}') from None
        else:
            try:
                doc = json.loads(text)
            except json.JSONDecodeError as e:
                raise RadError(f'faults file {str(path)!r} is not valid JSON: {e.msg} at line {e.lineno} '
                               f'column {e.colno}') from None
        return cls.from_dict(doc, seed, where=f'faults file {str(path)!r}')

    @classmethod
    def parse(cls, spec: str, seed: int = 0) -> FaultConfig:
        """'none' | 'realistic' | a path to a JSON or YAML file (its own seed wins over `seed`)."""
        spec = str(spec).strip()
        if spec in ('', 'none'):
            return cls(seed=seed)
        if spec == 'realistic':
            return cls.realistic(seed)
        if not Path(spec).is_file():
            raise RadError(f'faults: expected none, realistic or a JSON/YAML file, got {spec!r} '
                           f'(no such file)')
        return cls.from_file(spec, seed)

    def to_dict(self) -> dict:
        return asdict(self)

    def active(self) -> bool:
        """True when any fault can happen."""
        return any(getattr(self, name) > 0 for name in
                   ('mocap_position_noise', 'mocap_yaw_noise_deg', 'placement_error') + _PROBABILITIES)

    def describe(self) -> str:
        """One line for a log: the faults that are on."""
        if not self.active():
            return 'no faults'
        on = [f'{k}={v:g}' for k, v in self.to_dict().items()
              if k not in ('seed', 'nudge_distance') and v > 0]
        if self.nudge > 0:
            on.append(f'nudge_distance={self.nudge_distance:g}')
        return f'faults (seed {self.seed}): ' + ', '.join(on)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

"""One step's motion as a real cell runs it: arm trajectories and gripper commands, in order.

A franka_ros2 cell moves the arm through a FollowJointTrajectory action (the 7
arm joints only) and the hand through a GripperCommand action, so a pick and
place is a program of both:

    gripper open (pre-grasp width) -> arm: approach and descend -> gripper grasp
    -> arm: lift, carry, descend -> gripper release -> arm: retreat

(A first step whose hand is wider than the approach opening closes the empty hand
before it opens: franka_gripper's gripper_action moves only when opening; a command
to a narrower width is a grasp, which on air closes fully and fails.)

`Motion` holds the arm trajectories in execution order and the gripper commands,
each placed before the arm trajectory with index `before` (len(trajectories):
after the last). Its dict form is what plans and rad-result documents carry:
``{"trajectories": [...], "gripper": [{"before", "action", "position",
"max_effort", "expected_position"}, ...]}``.

Gripper positions are per finger (m), the unit of the Panda's finger joints and
of control_msgs/GripperCommand as a Franka hand's gripper action takes it: the
hand's opening is twice the position. A grasp commands a position a little inside
the block and a force (`max_effort`, N); the hand stalls on the block's faces, and
the width it reports tells whether the block is held (`grasp_problem`).

With the vacuum gripper in the hand's place the same list holds its commands, as franka_ros's
franka_vacuum_gripper serves them: 'vacuum' (its Vacuum action: `vacuum` in 10 mbar, `timeout_ms`)
once the cup is on the block, and 'drop_off' (DropOff: `timeout_ms`) at the placement; each answers
success and an error text, and a vacuum that did not reach its level holds nothing.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from rad_core.cell.panda import FINGER_OPEN
from rad_core.cell.trajectory import Trajectory, reversed_trajectory
from rad_core.domain.errors import RadError

GRIPPER_ACTIONS = ('close', 'open', 'grasp', 'release', 'vacuum', 'drop_off')
VACUUM_ACTIONS = ('vacuum', 'drop_off')


@dataclass(frozen=True)
class GripperCommand:
    """One command to the hand."""

    action: str                  # 'close' (the empty hand) | 'open' (before a grasp) | 'grasp' | 'release'
    #                              | 'vacuum' | 'drop_off' (the vacuum gripper)
    position: float              # per finger (m); the vacuum gripper's: FINGER_OPEN (it has none)
    max_effort: float            # N; the grasp force
    before: int                  # runs before trajectories[before]
    expected_position: float = float('nan')
    """For a grasp: where the fingers stop when they hold the block (its faces, per finger)."""
    vacuum: int = 0
    """For 'vacuum': the level to reach, in 10 mbar (the Vacuum goal's `vacuum`)."""
    timeout_ms: int = 0
    """For 'vacuum' and 'drop_off': the goal's `timeout` (ms)."""

    def to_dict(self) -> dict:
        d = {'before': self.before, 'action': self.action, 'position': float(self.position),
             'max_effort': float(self.max_effort)}
        if np.isfinite(self.expected_position):
            d['expected_position'] = float(self.expected_position)
        if self.action in VACUUM_ACTIONS:
            d.update(vacuum=int(self.vacuum), timeout_ms=int(self.timeout_ms))
        return d

    @classmethod
    def from_dict(cls, d: dict) -> GripperCommand:
        try:
            cmd = cls(str(d['action']), float(d['position']), float(d['max_effort']), int(d['before']),
                      float(d.get('expected_position', float('nan'))), int(d.get('vacuum', 0)),
                      int(d.get('timeout_ms', 0)))
        except (KeyError, TypeError, ValueError) as e:
            raise RadError(f'not a gripper command: {e}') from None
        if cmd.action not in GRIPPER_ACTIONS:
            raise RadError(f'gripper command: action {cmd.action!r} is not one of {", ".join(GRIPPER_ACTIONS)}')
        if cmd.action in VACUUM_ACTIONS and not (0 <= cmd.vacuum <= 127 and 0 <= cmd.timeout_ms <= 127):
            raise RadError(f'gripper command {cmd.action}: vacuum and timeout_ms are int8 goal fields (0..127), '
                           f'got {cmd.vacuum} and {cmd.timeout_ms}')
        return cmd

    def moved(self, before: int) -> GripperCommand:
        """The same command before another trajectory."""
        return replace(self, before=before)


@dataclass
class Motion:
    """A step's arm trajectories and gripper commands (see the module docstring)."""

    trajectories: list[Trajectory] = field(default_factory=list)
    gripper: list[GripperCommand] = field(default_factory=list)

    def sequence(self) -> Iterator[Trajectory | GripperCommand]:
        """Every command in execution order."""
        for k in range(len(self.trajectories) + 1):
            yield from (g for g in self.gripper if g.before == k)
            if k < len(self.trajectories):
                yield self.trajectories[k]

    @property
    def final_arm(self) -> np.ndarray:
        """The arm's 7 joints at the end (robot model order)."""
        return np.asarray(self.trajectories[-1].points[-1].positions, dtype=float)

    def final_joints(self) -> np.ndarray:
        """The 9 joints (arm in model order, then both fingers) where the motion leaves the robot;
        the fingers as the last gripper command left them (open when there is none)."""
        fingers = self.gripper[-1].position if self.gripper else FINGER_OPEN
        return np.concatenate([self.final_arm, [fingers, fingers]])

    @property
    def opening(self) -> float:
        """The hand's opening (per finger) on the approach: what it opens to before a grasp."""
        return next((g.position for g in self.gripper if g.action in ('open', 'release')), FINGER_OPEN)

    @property
    def duration(self) -> float:
        """Seconds of arm motion (gripper moves come on top)."""
        return float(sum(t.duration for t in self.trajectories))

    def then(self, other: Motion) -> Motion:
        """This motion followed by `other` (which starts where this one ends)."""
        n = len(self.trajectories)
        return Motion(self.trajectories + other.trajectories,
                      self.gripper + [g.moved(g.before + n) for g in other.gripper])

    def to_dict(self) -> dict:
        return {'trajectories': [t.to_dict() for t in self.trajectories],
                'gripper': [g.to_dict() for g in self.gripper]}

    @classmethod
    def from_dict(cls, d: dict) -> Motion:
        if not isinstance(d, dict) or not isinstance(d.get('trajectories'), list):
            raise RadError('not a motion: expected {"trajectories": [...], "gripper": [...]}')
        motion = cls([Trajectory.from_dict(t) for t in d['trajectories']],
                     [GripperCommand.from_dict(g) for g in d.get('gripper') or []])
        for g in motion.gripper:
            if not 0 <= g.before <= len(motion.trajectories):
                raise RadError(f'gripper command before trajectory {g.before}: there are '
                               f'{len(motion.trajectories)}')
        return motion


class GripperFailed(RadError):
    """A gripper goal that the hand's action refused, or ended without an answer to judge (cancelled by
    its server, no result in time): the step stops there."""


@dataclass(frozen=True)
class GripperResult:
    """What a GripperCommand action answers."""

    position: float              # per finger (m), where the fingers stopped
    effort: float = 0.0
    stalled: bool = False
    reached_goal: bool = False
    error: str = ''
    """The vacuum gripper's actions: their result's error text (reached_goal is their success)."""


def grasp_problem(command: GripperCommand, result: GripperResult, tol: float = 0.003) -> str:
    """Why a grasp did not end holding the block, or '' (a real hand's width check).

    Closed past the block's faces: nothing between the fingers (a miss, or the block
    slipped out); stopped short of them: something else in the way.
    """
    if command.action in VACUUM_ACTIONS:
        if result.reached_goal:
            return ''
        what = 'the vacuum did not hold the block' if command.action == 'vacuum' else 'the drop-off failed'
        return f'{what}: {result.error or "no reason given"}'
    if command.action != 'grasp' or not np.isfinite(command.expected_position):
        return ''
    width, expected = 2 * result.position, 2 * command.expected_position
    if result.position < command.expected_position - tol:
        return (f'the gripper closed to {width * 1000:.1f} mm, past the block\'s {expected * 1000:.1f} mm: '
                'nothing is held')
    if result.position > command.expected_position + tol:
        return (f'the gripper stopped at {width * 1000:.1f} mm, short of the block\'s {expected * 1000:.1f} mm: '
                'something is in the way')
    return ''


def gripper_problem(command: GripperCommand, result: GripperResult, tol: float = 0.001) -> str:
    """Why a gripper command did not leave the hand as the step needs it, or ''.

    A grasp and the vacuum gripper's commands: `grasp_problem`. An opening move ('open' before a
    grasp, 'release' after a placement) must have opened the fingers to within `tol` (per finger) of
    the command: a hand that stopped short, however its goal ended, would descend onto a block with
    its fingers in the way or carry the block off. 'close' (the empty hand) must have closed to within
    3 mm of the command. An aborted or unreached goal whose fingers are where they were sent is taken:
    the width is what the next motion needs (franka_gripper ends a move that stalls a hair short as
    aborted)."""
    if command.action == 'grasp' or command.action in VACUUM_ACTIONS:
        return grasp_problem(command, result)
    width, wanted = 2 * result.position * 1000, 2 * command.position * 1000
    said = f' ({result.error})' if result.error else ('' if result.reached_goal else ' (the goal was not reached)')
    if command.action in ('open', 'release') and result.position < command.position - tol:
        what = 'open before the grasp' if command.action == 'open' else 'let go of the block'
        return f'the hand did not {what}: it stopped at {width:.1f} mm of the {wanted:.1f} mm commanded{said}'
    if command.action == 'close' and result.position > command.position + 0.003:
        return f'the empty hand did not close: it stopped at {width:.1f} mm of the {wanted:.1f} mm commanded{said}'
    return ''


def run_motion(motion: Motion, move_arm, move_gripper, start=None) -> str:
    """Run a step's commands in order through a plant's two actions.

    move_arm(trajectory) runs an arm trajectory to its end and raises RadError when
    the controller refuses or aborts it (a fault to stop on); move_gripper(command)
    returns the gripper's `GripperResult` (GripperFailed when the hand refused or dropped the
    goal). Returns '' when the step went through, or why a gripper command failed (a fault to
    re-register and replan on: `gripper_problem`). After a failed grasp the hand opens again and,
    given `start` (the arm's 7 joints when the step began), the arm backs out along the approach it
    came down (the checked path, reversed) to where the step began. After a failed release the arm
    retreats as planned once the fingers are clear of the block (`_let_go`), and the step reports the
    failure. Any other failed gripper command stops the step where it is: the arm never descends with
    its fingers closed.
    """
    done: list[Trajectory] = []
    released = ''
    for command in motion.sequence():
        if isinstance(command, GripperCommand):
            try:
                result = move_gripper(command)
                problem = gripper_problem(command, result)
            except GripperFailed as e:
                result, problem = None, str(e)
            if problem and command.action == 'release':
                released = f'release failed: {_let_go(motion, command, result, problem, move_gripper)}'
                continue        # the retreat: planned for the wider hand, it clears the narrower one too
            if problem and command.action not in ('grasp', 'vacuum'):
                return f'{command.action} failed: {problem}'
            if problem:
                if command.action in VACUUM_ACTIONS:
                    let_go = GripperCommand('drop_off', command.position, 0.0, command.before,
                                            timeout_ms=command.timeout_ms)
                else:
                    let_go = GripperCommand('open', motion.opening, 0.0, command.before)
                try:
                    answer = move_gripper(let_go)
                    # A drop-off after a vacuum that held nothing fails as "part not present": no news.
                    stuck = gripper_problem(let_go, answer) if let_go.action == 'open' else ''
                except GripperFailed as e:
                    stuck = str(e)
                if start is not None and len(done) == 1:
                    move_arm(reversed_trajectory(done[0], start))    # straight up the way it came down
                return f'grasp failed: {problem}' + (f'; then {let_go.action} failed: {stuck}' if stuck else '')
        else:
            move_arm(command)
            done.append(command)
    return released


def _let_go(motion: Motion, release: GripperCommand, result: GripperResult | None, problem: str,
            move_gripper) -> str:
    """After a failed release: the problem, once the fingers are clear of the block (past its faces by
    a millimetre each), asking once more where they are not. RadError when the hand still holds it:
    the arm cannot leave a block it holds in the structure, and a person must free it."""
    grasp = next((g for g in reversed(motion.gripper) if g.action == 'grasp' and g.before <= release.before), None)
    faces = grasp.expected_position if grasp is not None and np.isfinite(grasp.expected_position) else None

    def clear(r: GripperResult | None) -> bool:
        return r is not None and faces is not None and r.position >= faces + 0.001
    if clear(result):
        return f'{problem}; the fingers cleared the block, and the arm retreated'
    try:
        again = move_gripper(release)
        retry = gripper_problem(release, again)
    except GripperFailed as e:
        again, retry = None, str(e)
    if not retry or clear(again):
        return f'{problem}; asked again, the hand let go, and the arm retreated'
    raise RadError(f'release failed: {problem}; asked again: {retry}: the hand still holds the block it placed, '
                   'and the arm stays there: free the block by hand')

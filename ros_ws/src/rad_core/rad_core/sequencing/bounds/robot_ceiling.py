"""The robot-feasible ceiling: what the best order of a scene's allocations, and of their
re-allocations at dead ends, builds with the robot (`robot_ceiling`).

The branch and bound is `decide.exact.exact_search`; here it runs in a planning twin (a
`RobotAssemblyEnv`, teleporting execution) with each move planned once per state
(`_FailedMoves`), re-allocation at dead ends and the arm's coverage bound
(`allocation.bounds.ArmCoverageBound`, capped at the root by `planning.courses.course_bound`).
"""

from __future__ import annotations

import time

from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.bounds import ArmCoverageBound
from rad_core.cell.panda import check_effector
from rad_core.domain.errors import RadError
from rad_core.env.mdp import Action, Outcome
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
from rad_core.gamp.planner import GampConfig
from rad_core.sequencing.decide.actions import AllocationActions
from rad_core.sequencing.decide.deciders import Check, simulated_check
from rad_core.sequencing.decide.exact import ExactResult, _placements, exact_search
from rad_core.sequencing.decide.search import EnvModel
from rad_core.sequencing.planning.courses import course_bound
from rad_core.sequencing.planning.reallocation import ReallocationConfig, Reallocator, reallocation_support


class _FailedMoves:
    """The planning twin of one `robot_ceiling` search, remembering why each move failed from
    each state, so that a move is planned from a state once.

    The branch and bound expands each set of placements once (`seen`) and steps every move from
    a restore of that one world. At a dead end the same moves are stepped again from it: by the
    re-allocation's checks of the open poses, and by each new space, which keeps most poses. A
    move met again there meets the same world and gets the same verdict, so it is booked as the
    first time (`AssemblyEnv.fail`, the world left as it is) instead of being planned again. A
    move is (block, cells, yaw), as the search dedupes them; only failures that reached GAMP or
    physics are remembered (the MDP's own checks are cheaper than a look-up). Stepping a world
    Bullet has probed fewer times leaves settled poses different by at most micrometres
    (docs/results/planning_step.md), far inside the verdicts' millimetre tolerances.

    hand: an `allocation.arm.HandBlocked` of the scene: a move whose every grasp puts the hand
    into a built cell is refused without planning, as GAMP would refuse it at the placement. It
    is booked as a placement failure: its pick is not planned, so where the block could not have
    been picked either, the re-allocation learns that at another pose."""

    def __init__(self, renv, hand=None):
        self.renv, self.env = renv, renv.env
        self.hand = hand
        self.failed: dict[tuple, tuple] = {}    # (placements, block, cells, yaw) -> (outcome, reason, plan)
        self.last_plan = None
        self.hits = self.hand_refused = 0

    def key(self, action: Action) -> tuple | None:
        """The move from this state, as remembered; None where the MDP's own checks decide it."""
        env = self.env
        if action.is_terminate or env.state.done or env.evaluate(action)[0] is not None:
            return None
        cells, yaw = env.resulting_cells(action)
        return _placements(env), action.block, tuple(sorted(int(c) for c in cells)), yaw

    def _known(self, action: Action, key: tuple | None) -> tuple | None:
        """(outcome, reason, plan) of the move's remembered failure, or of the hand test's
        refusal (remembered then); None: it is to be planned."""
        if key is None:
            return None
        known = self.failed.get(key)
        if known is not None:
            self.hits += 1
            return known
        return self.failed[key] if self._refused_by_hand(action, key) else None

    def step(self, action: Action):
        key = self.key(action)
        known = self._known(action, key)
        if known is not None:
            outcome, reason, self.last_plan = known
            return self.env.fail(outcome, reason, self.env.resulting_cells(action)[0])
        self.renv.last_plan = None
        result = self.renv.step(action)
        self.last_plan = self.renv.last_plan
        if key is not None and result.outcome.is_invalid:
            self.failed[key] = (result.outcome, result.reason, self.last_plan)
        return result

    def _refused_by_hand(self, action: Action, key: tuple) -> bool:
        """Whether the hand test refuses the move (remembered as a failure then): every grasp
        of its pose puts the hand into a built cell, which GAMP refuses whatever the arm does
        (`allocation.arm.HandBlocked`), so it is not planned."""
        if self.hand is None:
            return False
        env = self.env
        cells, yaw = env.resulting_cells(action)
        if not self.hand.blocked(env.scene.blocks[action.block].type, yaw, cells, env.state.occupancy >= 0):
            return False
        self.hand_refused += 1
        self.failed[key] = (Outcome.INVALID_PLACEMENT, 'placement: at the placement: every grasp puts the hand, '
                            'its fingers or link7 into a built cell (allocation.arm.HandBlocked)', None)
        return True

    def snapshot(self):
        return self.renv.snapshot()

    def restore(self, snapshot) -> None:
        self.renv.restore(snapshot)
        self.last_plan = self.renv.last_plan

    def check(self):
        """The re-allocation's check (`deciders.simulated_check` through this memo): a remembered
        failure answers at once, without a snapshot of the world."""
        stepped = simulated_check(self)

        def check(action) -> Check:
            known = self._known(action, self.key(action))
            if known is None:
                return stepped(action)
            outcome, reason, plan = known
            return Check(False, reason, plan, 'grasp' if outcome is Outcome.INVALID_GRASP else '')
        return check


def robot_ceiling(scene, time_limit_s: float = 60.0, support: str | tuple[str, ...] = ('arm', 'hand'),
                  reallocation=None, max_states: int = 100_000, incumbent: float = 0.0,
                  every_pose: bool = True, ordered: bool = True, effector: str = 'hand') -> ExactResult:
    """What the best order of the scene's allocation, and of its re-allocations at dead ends,
    builds with the robot: the branch and bound from the empty scene in a planning twin
    (teleporting execution), children most target cells first, re-allocating where no move
    succeeds (the no-goods found there excluded) and bounded by what the blocks left could
    cover at most with poses the arm might still build (`allocation.bounds.ArmCoverageBound`:
    `allocation.cpsat.coverage_bound` without blocks it cannot pick, poses out of reach and
    poses the hand can no longer enter between built cells; `ordered`: and only poses with an
    order the hand can place them in, `ArmCoverageBound.ordered_bound`). Each move is planned
    once per state, and moves the hand test refuses are not planned (`_FailedMoves`). At the root
    the bound course by course (`courses.course_bound`) caps it: tighter where the ordered bound is
    not proven in its time (a 72-block wall). An answer at its bound
    (`proof` 'bound') is the robot-feasible ceiling over every allocation; an exhausted one
    ('exhausted') the best of the allocations searched; a cut one a lower bound (its `reason`
    says so).

    support: the first allocation's support rule, or several: each allocation is searched in turn
    from the empty scene, with the best found so far as its incumbent, while the searches before
    were exhausted below the bound and time is left (the default: the arm's allocation, then the
    hand's, `allocation.cpsat`'s 'hand' rounds, a different cover the first search may never
    reach); the same allocation twice is searched once. The answer is complete only where every
    search that ran was, and states and time are summed over them.
    reallocation: a `ReallocationConfig` (default: its defaults with the re-solves' support
    `agent_plan.reallocation_support` of the first support).
    incumbent: a coverage the robot is known to build on the scene (an agent's plan, built in the
    twin): the search starts from it (`exact_search`), and the answer is the better of the two.
    every_pose: where the allocations' searches were exhausted below the bound and time is left,
    search once more over every pose the bound counts (every pose of every type an allocation may
    propose, more target cells than others, that the arm might build: `ArmCoverageBound.candidates`),
    from the best found;
    exhausted there, the answer is the true ceiling over all of them (`proof` 'all poses'). Its
    moves per state are many (each pose times each block of its type), so it finishes on small
    targets; cut, the answer stays 'exhausted' with the other searches' proof, its line the best found.
    ordered: the bound asks for a hand order too (`ArmCoverageBound`, and at the root the course
    bound): where no order of the target's poses lets the hand place the last ones (a flush, closed
    course), the bound is below 1 and an answer at it is the true ceiling without the every-pose
    search; False: the bound without it (slower to finish, kept to compare).
    effector: what the arm carries (`cell.panda.EFFECTORS`): the planning twin's GAMP, the bound's
    blocking cells and every allocation count on its grasps."""
    check_effector(effector)
    supports = (support,) if isinstance(support, str) else tuple(support)
    if not supports:
        raise RadError('robot_ceiling: give at least one support rule')
    config = reallocation or ReallocationConfig(params=AllocationParams(
        support=reallocation_support(supports[0]), effector=effector))
    deadline = time.monotonic() + time_limit_s
    with RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport', gamp=GampConfig(effector=effector))) as renv:
        renv.reset()
        env = renv.env
        arm_bound = _root_bound(scene, renv, time_limit_s, ordered)
        memo = _FailedMoves(renv, arm_bound.hand)
        on_dead_end = _reallocate_at_dead_end(env, memo.check(), config)

        def bound_of(_model) -> float:   # re-allocating: what any allocation of the free cells could cover
            return arm_bound(env)

        answer = _search_allocations(scene, supports, env, memo, deadline, max_states, incumbent,
                                     on_dead_end, bound_of, effector)
        left = deadline - time.monotonic()
        if every_pose and answer.complete and answer.proof == 'exhausted' and left > 0:
            answer = _search_every_pose(answer, env, memo, arm_bound, left, max_states, incumbent, bound_of)
        return answer


def _root_bound(scene, renv, time_limit_s: float, ordered: bool) -> ArmCoverageBound:
    """The arm's coverage bound of the scene in the planning twin, its value at the root (the empty
    scene) proven with more time, and capped there course by course where `ordered`."""
    env = renv.env
    arm_bound = ArmCoverageBound(scene, env.grid, renv.config.gamp, ordered=ordered)
    # The root's bound decides whether an answer is the true ceiling: CP-SAT gets longer there
    # (remembered for every search from the root), the states below it the bound's own limit.
    root = arm_bound(env, max(arm_bound.time_limit_s, min(30.0, time_limit_s / 10)))
    if ordered and root > env.coverage() + 1e-9:
        # Where the hand's order is not proven in its time (a 72-block wall's 590 poses), the
        # bound course by course, a relaxation of it that CP-SAT proves in seconds, is tighter.
        arm_bound.cap(env, course_bound(scene, min(30.0, max(10.0, time_limit_s / 10))))
    return arm_bound


def _reallocate_at_dead_end(env, check, config: ReallocationConfig):
    """The search's `on_dead_end`: re-allocate the line's space where no move succeeds (None where
    the re-allocation changes nothing)."""
    def on_dead_end(_model, current):
        # A copy of the line's space (its parent keeps its own), with the no-goods found on the line.
        sub = AllocationActions(env, current.guide.placements)
        reallocator = Reallocator(sub, check, config)
        reallocator.no_goods = dict(getattr(current, 'no_goods', {}))
        reallocator.blocked = dict(getattr(current, 'blocked', {}))
        event = reallocator.stalled(env, 'exact search: dead end')
        sub.no_goods, sub.blocked = reallocator.no_goods, reallocator.blocked
        return sub if event.changed else None
    return on_dead_end


def _search_allocations(scene, supports: tuple[str, ...], env, memo: _FailedMoves, deadline: float,
                        max_states: int, incumbent: float, on_dead_end, bound_of,
                        effector: str = 'hand') -> ExactResult:
    """The branch and bound over each support rule's allocation in turn (`robot_ceiling`'s support),
    each from the best found so far, while the searches before were exhausted below the bound and
    time is left; the same allocation twice is searched once."""
    answer, searched = None, set()
    for rule in supports:
        placements = solve(scene, AllocationParams(support=rule, effector=effector)).placements
        key = frozenset(placements)
        left = deadline - time.monotonic()
        if answer is not None and (key in searched or left <= 0):
            continue
        left = max(left, 1e-9)      # the first search runs, if only to say the limit cut it
        searched.add(key)
        known = incumbent if answer is None else max(incumbent, answer.coverage)
        found = exact_search(EnvModel(memo, None, AllocationActions(env, placements)), left,
                             max_states=max_states if answer is None else max(1, max_states - answer.states),
                             on_dead_end=on_dead_end, bound_of=bound_of, incumbent=known)
        answer = found if answer is None else _better(answer, found)
        if not answer.complete or answer.proof == 'bound':
            break
    return answer


def _search_every_pose(answer: ExactResult, env, memo: _FailedMoves, arm_bound: ArmCoverageBound, left: float,
                       max_states: int, incumbent: float, bound_of) -> ExactResult:
    """The search over every pose the bound counts, in one space, from the allocations' best
    (`answer`, exhausted below the bound): exhausted, no placement sequence of them does better,
    which is what the bound is over: the true ceiling ('all poses')."""
    space = AllocationActions(env, [c.placement for c in arm_bound.candidates])
    found = exact_search(EnvModel(memo, None, space), left,
                         max_states=max(1, max_states - answer.states), bound_of=bound_of,
                         incumbent=max(incumbent, answer.coverage))
    done = found.complete
    answer = _better(answer, found)
    # Cut, it still searched more than the allocations did: their answer stands, or the line it found.
    answer.complete, answer.reason = True, ''
    answer.proof = {'bound': 'bound', 'exhausted': 'all poses'}.get(found.proof, 'exhausted') if done \
        else 'exhausted'
    return answer


def _better(first: ExactResult, then: ExactResult) -> ExactResult:
    """Two searches from the same state, the second started from the first's best as its incumbent."""
    line = then.actions if then.actions else first.actions
    return ExactResult(max(first.coverage, then.coverage), list(line), then.complete, max(first.bound, then.bound),
                       first.states + then.states, first.elapsed_s + then.elapsed_s, then.reason, then.proof)

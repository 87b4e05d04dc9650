"""What the best order of the allocation's poses can build with the robot.

The robot-feasible ceiling: a depth-first branch and bound over the orders in
which the allocation's open poses can be filled, each move a real step of the
search model (`sequencing.search.EnvModel` over a `RobotAssemblyEnv`: GAMP,
execution, physics) from a snapshot, undone with `restore`. `sequencing.search.bnb`
serves it as a search like the others (budget: seconds). Unlike the no-robot
ceiling (`sequencing.ceiling`), which block of a type fills a pose matters here:
the robot picks each block from its own place on the table, so a move is (block,
the cells it fills, its yaw), one per distinct final pose of each block still on
the table.

- A step the robot or physics fails is a dead child (nothing below it).
- Visited states are memoized by what is placed where (block and cells), so two
  orders of the same placements are searched once.
- A state is pruned when its coverage plus the target cells of the allocation's
  poses still open cannot beat the best coverage found; the root's value of that
  (`coverage.optimum_coverage`) is the bound, and reaching it ends the search at once.
- `on_dead_end` lets the caller re-allocate where no move succeeds although
  allocated poses remain (or the allocation is used up with target cells free);
  the search goes on from that state with the new action space for that subtree
  (the memo does not tell spaces apart: a state reached again under another space
  is not searched again). A re-allocation can cover cells the first allocation
  does not, so such a search needs a bound of its own (`bound_of`, e.g.
  `allocation.cpsat.coverage_bound`: what the blocks left could cover at most);
  with it, complete answers are a true ceiling over orders and re-allocations.

Anytime: when the time or state limit cuts the search, the best line found so
far comes back with complete=False and its coverage is a lower bound only.

Incumbent: a coverage some plan is known to reach from here (e.g. an agent's plan built
in the twin) starts the search as the best found, as a branch and bound's incumbent does:
states that cannot beat it are pruned from the start, and one equal to the bound ends the
search at once. The answer is then the better of the two; `actions` is empty where the
search found nothing better than the incumbent.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from rad_core.errors import RadError
from rad_core.coverage import optimum_coverage
from rad_core.mdp import Action, AssemblyEnv, Outcome
from rad_core.sequencing.actions import AllocationActions

_EPS = 1e-9   # coverages are ratios of cell counts computed two ways

Order = Callable[[AssemblyEnv, list[Action]], list[Action]]
OnDeadEnd = Callable[[object, AllocationActions], 'AllocationActions | None']   # (model, space)


@dataclass
class ExactResult:
    """What `exact_search` found.

    coverage: the best target coverage any searched order reached (the incumbent where none beat it).
    actions: the line that reaches it, from the given state (MDP actions); empty where no line
        the search found beats the `incumbent` it was given.
    complete: the search was exhausted or reached the bound, so no order of the
        allocation's poses (and, with on_dead_end, of its re-allocations) does better;
        False when a limit cut it (then coverage is a lower bound only, and `reason`
        says which limit).
    bound: the root's upper bound (coverage plus open allocated target cells, or bound_of's).
    states: states visited (distinct sets of placements).
    elapsed_s: wall time of the search.
    reason: why the search is not complete ('' when it is).
    proof: how a complete search ended: 'bound' where the best coverage reached the root's bound
        (with a `bound_of` over every allocation, as `robot_ceiling`'s, no plan of any allocation
        does better: the true ceiling), 'exhausted' where every state the search could reach was
        searched below the bound (the best of the orders and re-allocations it reached, not a
        proof over allocations it never took); '' when a limit cut it. `robot_ceiling` adds
        'all poses': exhausted over every pose its bound counts, the true ceiling too.
    """

    coverage: float
    actions: list[Action] = field(default_factory=list)
    complete: bool = True
    bound: float = 1.0
    states: int = 0
    elapsed_s: float = 0.0
    reason: str = ''
    proof: str = 'exhausted'


class _Cut(Exception):
    """A limit ends the search; args[0] names it."""


class _AtBound(Exception):
    """The best coverage found equals the root's bound: nothing can beat it."""


def _placements(env: AssemblyEnv) -> frozenset:
    """A state of the search: which block fills which cells (the yaw follows, but for symmetric blocks)."""
    return frozenset((b, tuple(sorted(int(c) for c in cells))) for b, (cells, _) in env.state.placed.items())


def by_gain_then_height(env: AssemblyEnv, actions: list[Action]) -> list[Action]:
    """The default child order: most target cells filled first, then the lowest
    cells first (bottom-up), then the lowest cell ids (deterministic)."""
    grid = env.grid

    def key(action):
        cells, _ = env.resulting_cells(action)
        return (-int(grid.is_target[cells].sum()), int(grid.ijk[cells][:, 2].min()), sorted(int(c) for c in cells))
    return sorted(actions, key=key)


def exact_search(model, time_limit_s: float = 60.0, max_states: int = 100_000,
                 order: Order | None = None, on_dead_end: OnDeadEnd | None = None,
                 bound_of: Callable[[object], float] | None = None, incumbent: float = 0.0) -> ExactResult:
    """Branch and bound over the orders of the allocation's poses with the robot in
    the loop (module docstring), from the model's current state.

    model: a search model with the env it steps and the allocation's action space
        (`sequencing.search.EnvModel`: `.env`, `.space`, `.step`, `.snapshot`,
        `.restore`), between steps; it is left in the state it was given. The space's
        guide (an `AllocationActions`) gives the bound.
    order: `order(env, actions) -> the same actions, best first` (e.g. a policy's
        ranking), so good lines come first; default `by_gain_then_height`.
    on_dead_end: `on_dead_end(model, space) -> new space or None`, called where no move
        succeeds (allocated poses open, or the allocation used up with target cells
        free; the model is put back in that state after the call).
    bound_of: `bound_of(model) -> coverage no continuation from this state beats`, for
        searches that re-allocate (a re-allocation can cover cells the first allocation
        does not: its open poses are no bound then); e.g. `allocation.cpsat.coverage_bound`
        of the state. Default: the allocation's own, coverage plus its open target cells.
    incumbent: a coverage known to be reachable from this state (module docstring); 0: none.
    """
    if not (isinstance(time_limit_s, (int, float)) and time_limit_s > 0):
        raise RadError(f'exact_search: time_limit_s must be a positive number of seconds, got {time_limit_s!r}')
    if not (isinstance(max_states, int) and max_states >= 1):
        raise RadError(f'exact_search: max_states must be a positive integer, got {max_states!r}')
    env, space = model.env, model.space
    if env.state.done:
        raise RadError('exact_search: the episode is over; give it an env between steps')
    if not (isinstance(incumbent, (int, float)) and 0.0 <= incumbent <= 1.0):
        raise RadError(f'exact_search: incumbent must be a coverage in [0, 1], got {incumbent!r}')
    order = order or by_gain_then_height
    start_time = time.monotonic()
    deadline = start_time + time_limit_s
    root = model.snapshot()
    bound = optimum_coverage(env, space.guide) if bound_of is None else bound_of(model)
    best, best_line = max(env.coverage(), float(incumbent)), []
    seen: set[frozenset] = set()


    def moves(space) -> list[tuple[Action, frozenset]]:
        """The distinct moves (deduped as first_feasible dedupes a ranking), in order,
        each with the placements it would lead to."""
        distinct = {}
        for action in space(env):
            cells, yaw = env.resulting_cells(action)
            distinct.setdefault((action.block, tuple(sorted(int(c) for c in cells)), yaw), action)
        actions = list(distinct.values())
        ordered = list(order(env, actions))
        if len(ordered) != len(actions) or set(ordered) != set(actions):
            raise RadError('exact_search: order() must return the actions it was given, reordered '
                           f'(got {len(ordered)} for {len(actions)})')
        key = _placements(env)
        child = {a: key | {(a.block, k[1])} for k, a in distinct.items()}
        return [(a, child[a]) for a in ordered]

    def open_poses(space) -> frozenset:
        guide = space.guide
        return frozenset(tuple(guide.pose_cells[k].tolist()) for k in guide.open_poses(env.state))

    def check_time() -> None:
        if time.monotonic() > deadline:
            raise _Cut(f'time limit of {time_limit_s:g} s')

    def expand(space, line: list[Action]) -> bool:
        """Search every move of the space from here; whether any step succeeded."""
        here = model.snapshot()
        any_valid = False
        try:
            for action, child in moves(space):
                if child in seen:
                    # Searched already (another order, or another yaw of the same move): not
                    # stepped again, and not a dead end here (its subtree is searched).
                    any_valid = True
                    continue
                check_time()
                _, _, invalid = model.step(action)
                if not invalid:
                    any_valid = True
                    search(space, line + [action])
                model.restore(here)
        finally:
            model.restore(here)
        return any_valid

    def search(space, line: list[Action]) -> None:
        nonlocal best, best_line
        key = _placements(env)
        if key in seen:
            return
        if len(seen) >= max_states:
            raise _Cut(f'state limit of {max_states}')
        seen.add(key)
        coverage = env.coverage()
        if coverage > best:
            best, best_line = coverage, list(line)
        if best >= bound - _EPS:
            raise _AtBound()
        if env.state.done:
            return
        if bound_of is not None and bound_of(model) <= best + _EPS:
            return                                             # nothing from here beats the best
        tried = set()
        while bound_of is not None or optimum_coverage(env, space.guide) > best + _EPS:
            tried.add(open_poses(space))
            if expand(space, line) or on_dead_end is None:
                return
            if not open_poses(space) and not (env.grid.is_target & (env.state.occupancy < 0)).any():
                return                                         # the target is full
            here = model.snapshot()
            new = on_dead_end(model, space)
            model.restore(here)
            if new is None or open_poses(new) in tried:
                return   # no new space, or the same open poses again: nothing new to try
            space = new
            check_time()

    complete, reason, proof = True, '', 'exhausted'
    try:
        search(space, [])
    except _AtBound:
        proof = 'bound'
    except _Cut as cut:
        complete, proof = False, ''
        reason = (f'{cut.args[0]} reached after {len(seen)} states; '
                  f'{best:.2f} is a lower bound')
    finally:
        model.restore(root)
    return ExactResult(best, best_line, complete, bound, len(seen),
                       time.monotonic() - start_time, reason, proof)


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
        from rad_core.sequencing.deciders import Check, simulated_check
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
                  every_pose: bool = True, ordered: bool = True) -> ExactResult:
    """What the best order of the scene's allocation, and of its re-allocations at dead ends,
    builds with the robot: the branch and bound from the empty scene in a planning twin
    (teleporting execution), children most target cells first, re-allocating where no move
    succeeds (the no-goods found there excluded) and bounded by what the blocks left could
    cover at most with poses the arm might still build (`allocation.arm.ArmCoverageBound`:
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
    search; False: the bound without it (slower to finish, kept to compare)."""
    from rad_core.allocation import AllocationParams, solve
    from rad_core.allocation.arm import ArmCoverageBound
    from rad_core.robot_env import RobotAssemblyEnv, RobotEnvConfig
    from rad_core.sequencing.reallocation import ReallocationConfig, Reallocator
    from rad_core.sequencing.search import EnvModel
    from rad_core.sequencing.agent_plan import reallocation_support
    supports = (support,) if isinstance(support, str) else tuple(support)
    if not supports:
        raise RadError('robot_ceiling: give at least one support rule')
    config = reallocation or ReallocationConfig(params=AllocationParams(support=reallocation_support(supports[0])))
    deadline = time.monotonic() + time_limit_s
    with RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport')) as renv:
        renv.reset()
        env = renv.env
        arm_bound = ArmCoverageBound(scene, env.grid, renv.config.gamp, ordered=ordered)
        # The root's bound decides whether an answer is the true ceiling: CP-SAT gets longer there
        # (remembered for every search from the root), the states below it the bound's own limit.
        root = arm_bound(env, max(arm_bound.time_limit_s, min(30.0, time_limit_s / 10)))
        if ordered and root > env.coverage() + 1e-9:
            # Where the hand's order is not proven in its time (a 72-block wall's 590 poses), the
            # bound course by course, a relaxation of it that CP-SAT proves in seconds, is tighter.
            from rad_core.sequencing.courses import course_bound
            arm_bound.cap(env, course_bound(scene, min(30.0, max(10.0, time_limit_s / 10))))
        memo = _FailedMoves(renv, arm_bound.hand)
        check = memo.check()

        def on_dead_end(_model, current):
            # A copy of the line's space (its parent keeps its own), with the no-goods found on the line.
            sub = AllocationActions(env, current.guide.placements)
            reallocator = Reallocator(sub, check, config)
            reallocator.no_goods = dict(getattr(current, 'no_goods', {}))
            reallocator.blocked = dict(getattr(current, 'blocked', {}))
            event = reallocator.stalled(env, 'exact search: dead end')
            sub.no_goods, sub.blocked = reallocator.no_goods, reallocator.blocked
            return sub if event.changed else None

        def bound_of(_model) -> float:   # re-allocating: what any allocation of the free cells could cover
            return arm_bound(env)

        answer, searched = None, set()
        for rule in supports:
            placements = solve(scene, AllocationParams(support=rule)).placements
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
        left = deadline - time.monotonic()
        if every_pose and answer.complete and answer.proof == 'exhausted' and left > 0:
            # Every pose the bound counts, in one space: exhausted, no placement sequence of them does
            # better, which is what the bound is over: the true ceiling.
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

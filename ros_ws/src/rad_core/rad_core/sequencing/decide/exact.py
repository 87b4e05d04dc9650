"""What the best order of the allocation's poses can build with the robot.

The robot-feasible ceiling: a depth-first branch and bound over the orders in
which the allocation's open poses can be filled, each move a real step of the
search model (`sequencing.decide.search.EnvModel` over a `RobotAssemblyEnv`: GAMP,
execution, physics) from a snapshot, undone with `restore`. `sequencing.decide.search.bnb`
serves it as a search like the others (budget: seconds). Unlike the no-robot
ceiling (`sequencing.bounds.ceiling`), which block of a type fills a pose matters here:
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

from rad_core.domain.coverage import optimum_coverage
from rad_core.domain.errors import RadError
from rad_core.env.mdp import Action, AssemblyEnv
from rad_core.sequencing.decide.actions import AllocationActions

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


class _BranchAndBound:
    """One `exact_search`: its limits, the states visited and the best line found so far."""

    def __init__(self, model, space, time_limit_s: float, deadline: float, max_states: int, order: Order,
                 on_dead_end: OnDeadEnd | None, bound_of: Callable[[object], float] | None,
                 bound: float, best: float):
        self.model, self.env = model, model.env
        self.root_space = space
        self.time_limit_s, self.deadline, self.max_states = time_limit_s, deadline, max_states
        self.order, self.on_dead_end, self.bound_of = order, on_dead_end, bound_of
        self.bound = bound
        self.best, self.best_line = best, []
        self.seen: set[frozenset] = set()

    def moves(self, space) -> list[tuple[Action, frozenset]]:
        """The distinct moves (deduped as first_feasible dedupes a ranking), in order,
        each with the placements it would lead to."""
        env = self.env
        distinct = {}
        for action in space(env):
            cells, yaw = env.resulting_cells(action)
            distinct.setdefault((action.block, tuple(sorted(int(c) for c in cells)), yaw), action)
        actions = list(distinct.values())
        ordered = list(self.order(env, actions))
        if len(ordered) != len(actions) or set(ordered) != set(actions):
            raise RadError('exact_search: order() must return the actions it was given, reordered '
                           f'(got {len(ordered)} for {len(actions)})')
        key = _placements(env)
        child = {a: key | {(a.block, k[1])} for k, a in distinct.items()}
        return [(a, child[a]) for a in ordered]

    def open_poses(self, space) -> frozenset:
        """The cells of the space's allocated poses still open."""
        guide = space.guide
        return frozenset(tuple(guide.pose_cells[k].tolist()) for k in guide.open_poses(self.env.state))

    def check_time(self) -> None:
        if time.monotonic() > self.deadline:
            raise _Cut(f'time limit of {self.time_limit_s:g} s')

    def expand(self, space, line: list[Action]) -> bool:
        """Search every move of the space from here; whether any step succeeded."""
        model = self.model
        here = model.snapshot()
        any_valid = False
        try:
            for action, child in self.moves(space):
                if child in self.seen:
                    # Searched already (another order, or another yaw of the same move): not
                    # stepped again, and not a dead end here (its subtree is searched).
                    any_valid = True
                    continue
                self.check_time()
                _, _, invalid = model.step(action)
                if not invalid:
                    any_valid = True
                    self.search(space, line + [action])
                model.restore(here)
        finally:
            model.restore(here)
        return any_valid

    def search(self, space, line: list[Action]) -> None:
        """Search the state the model is in, reached by `line`: record it, prune it against the
        bound, then expand it, re-allocating at dead ends (`on_dead_end`)."""
        env, model = self.env, self.model
        key = _placements(env)
        if key in self.seen:
            return
        if len(self.seen) >= self.max_states:
            raise _Cut(f'state limit of {self.max_states}')
        self.seen.add(key)
        coverage = env.coverage()
        if coverage > self.best:
            self.best, self.best_line = coverage, list(line)
        if self.best >= self.bound - _EPS:
            raise _AtBound()
        if env.state.done:
            return
        if self.bound_of is not None and self.bound_of(model) <= self.best + _EPS:
            return                                             # nothing from here beats the best
        tried = set()
        while self.bound_of is not None or optimum_coverage(env, space.guide) > self.best + _EPS:
            tried.add(self.open_poses(space))
            if self.expand(space, line) or self.on_dead_end is None:
                return
            if not self.open_poses(space) and not (env.grid.is_target & (env.state.occupancy < 0)).any():
                return                                         # the target is full
            here = model.snapshot()
            new = self.on_dead_end(model, space)
            model.restore(here)
            if new is None or self.open_poses(new) in tried:
                return   # no new space, or the same open poses again: nothing new to try
            space = new
            self.check_time()

    def run(self, root) -> tuple[bool, str, str]:
        """Search from the root space; (complete, reason, proof). The model is restored to `root`."""
        complete, reason, proof = True, '', 'exhausted'
        try:
            self.search(self.root_space, [])
        except _AtBound:
            proof = 'bound'
        except _Cut as cut:
            complete, proof = False, ''
            reason = (f'{cut.args[0]} reached after {len(self.seen)} states; '
                      f'{self.best:.2f} is a lower bound')
        finally:
            self.model.restore(root)
        return complete, reason, proof


def exact_search(model, time_limit_s: float = 60.0, max_states: int = 100_000,
                 order: Order | None = None, on_dead_end: OnDeadEnd | None = None,
                 bound_of: Callable[[object], float] | None = None, incumbent: float = 0.0) -> ExactResult:
    """Branch and bound over the orders of the allocation's poses with the robot in
    the loop (module docstring), from the model's current state.

    model: a search model with the env it steps and the allocation's action space
        (`sequencing.decide.search.EnvModel`: `.env`, `.space`, `.step`, `.snapshot`,
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
    search = _BranchAndBound(model, space, time_limit_s, deadline, max_states, order, on_dead_end, bound_of,
                             bound, max(env.coverage(), float(incumbent)))
    complete, reason, proof = search.run(root)
    return ExactResult(search.best, search.best_line, complete, bound, len(search.seen),
                       time.monotonic() - start_time, reason, proof)

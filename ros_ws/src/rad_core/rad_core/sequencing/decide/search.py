"""Test-time search on top of a Q-function: the paper's MCTS and sequential halving.

Both are pure functions over a `Model` (the environment interface a search needs:
allowed actions, Q-values, one real step, snapshot and restore) and an explicit
random generator, in the manner of mctx: the same model state and an equally
seeded generator give the same tree. One *simulation* is one real step of the
planning copy (with the robot: GAMP, execution and physics), so budgets compare
in what they cost.

`mcts` is the paper's search (Sec. IV-B, following the predecessor's budget-5
search; ../shared/PREDECESSOR.md): every iteration adds one not-yet-expanded child
of the root, chosen epsilon-greedily on Q(s, a) among the allowed actions plus
termination, by one real step; the leaf is valued r + gamma max_a' Q(s', a') (r
alone when the step ends the episode); a new child starts with one visit and
value Q(s, a), and the leaf value is backed up into it (so after the expansion
it has 2 visits and mean (Q(s, a) + leaf) / 2); the move is the child with the
best mean, a random expanded child with probability epsilon. With a budget of 5
the tree stays one level deep. When every allowed action has been expanded the
remaining budget is not spent (a one-level tree has nothing left to add, and the
planning copy is deterministic: expanding a child again would give the same leaf).

`halving` is rad's stronger small-budget search (the idea of Gumbel MuZero's
sequential halving, Danihelka et al. 2022, adapted to a deterministic planning
copy): the top-m candidates by Q are each simulated one step; then rounds halve
the survivors by their value and extend each survivor's line one more greedy
step, until the budget is spent. Because re-simulating a child of a deterministic
copy would teach nothing, a further "visit" deepens the line instead, by the step
a verified agent would take there (the best action by Q whose simulated step
succeeds; each try costs a simulation), so a move that leads into a dead end (no
buildable pose left) is seen before it is taken. Values are discounted returns
along the line plus the bootstrapped Q at its end (Q(s, terminate) where the line
stops).

`lookahead` is the search that serves a verified agent best when the network was
trained without the robot (measured: it knows what fills the target, not what the
arm can still reach): it keeps the network's order and spends the budget on vetoes.
Candidates are simulated in the order of Q; each one's line is extended by the
verified greedy step (horizon 2 by default); the first candidate that succeeds and
does not run into a dead end (every action worth more than stopping fails there) is
the move. So it is never worse than the verified greedy policy within its budget,
and a block that would leave the rest unbuildable is skipped while another order
exists.

`bnb` is the branch and bound of `sequencing.decide.exact` as a search: its budget is
seconds, not simulations; it searches the orders of the allocation's open poses
(children in the order of Q) for the line that fills the most of the target, and
the move is that line's first action. The whole line comes back (`SearchResult.line`)
so a caller can follow it without searching again (the sequencer does). It needs a
model with the env it steps and the allocation's action space (`EnvModel`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

from rad_core.env.mdp import TERMINATE, Action
from rad_core.sequencing.decide.exact import exact_search


class Model(Protocol):
    """What a search needs from the planning copy (see `EnvModel`)."""

    gamma: float

    def actions(self) -> list[Action]:
        """The allowed actions in the current state, termination excluded."""

    def q_values(self, actions: list[Action]) -> np.ndarray:
        """Q(s, a) for each action and Q(s, terminate) last (len(actions) + 1)."""

    def step(self, action: Action) -> tuple[float, bool, bool]:
        """One real step from the current state: (reward, episode done, action invalid)."""

    def snapshot(self) -> Any: ...

    def restore(self, snapshot: Any) -> None: ...

    # Optional: key(action) -> hashable, equal for actions with the same outcome (the
    # same block at the same cells, e.g. a cube under four rotations). A search then
    # simulates only the best-valued action of each key.


@dataclass
class Child:
    """One expanded (or, for halving, simulated) root action."""

    action: Action
    q: float                    # Q(s, a) of the network at the root
    visits: int = 0
    value_sum: float = 0.0
    reward: float = 0.0         # the first step's reward
    done: bool = False          # the first step ended the episode
    invalid: bool = False       # the first step failed (f_g, f_p, unstable, ...)
    depth: int = 0              # steps simulated along this line (halving)

    @property
    def value(self) -> float:
        return self.value_sum / self.visits if self.visits else -math.inf

    def to_dict(self) -> dict:
        return {'action': _action_doc(self.action), 'q': round(self.q, 9), 'visits': self.visits,
                'value': round(self.value, 9), 'reward': round(self.reward, 9), 'done': self.done,
                'invalid': self.invalid, 'depth': self.depth}


@dataclass
class SearchResult:
    action: Action                      # the move
    children: list[Child] = field(default_factory=list)   # in expansion order
    simulations: int = 0                # real steps spent
    root_q: np.ndarray | None = None    # the network's Q at the root: each of `actions`, then terminate
    actions: list[Action] = field(default_factory=list)   # every allowed root action
    line: list[Action] | None = None    # a search that plans whole lines (bnb): the best one, from the root
    info: dict = field(default_factory=dict)   # what the search reports beyond the tree (bnb: bound, states...)

    def ranking(self) -> list[tuple[Action, float]]:
        """Every root action (termination included) best first, for a verified caller
        that goes down the list: the move (unless it is to stop), the other searched
        children whose step succeeded by their value, then everything not simulated
        (other rotations of a searched pose included) and termination by Q, and last the
        children whose step failed. Ties keep the earlier order."""
        searched = {c.action: c for c in self.children if not c.action.is_terminate}
        good = sorted((c for c in searched.values() if not c.invalid), key=lambda c: -c.value)
        good.sort(key=lambda c: c.action != self.action)      # the move first, stable otherwise
        candidates = list(self.actions) + [TERMINATE]
        rest = [(a, float(self.root_q[i])) for i, a in enumerate(candidates) if a not in searched]
        rest.sort(key=lambda t: -t[1])
        failed = [(c.action, c.value) for c in self.children if c.invalid]
        return [(c.action, c.value) for c in good] + rest + failed

    def proposals(self, fallbacks: bool = False) -> list[tuple[Action, float]]:
        """The ranking down to termination: what a verified caller may try, best first
        (failed children rank after termination, so they are never among them). fallbacks:
        then the actions after termination that were not simulated (`policy.FALLBACKS`)."""
        out, failed = [], {c.action for c in self.children if c.invalid}
        past = False
        for action, value in self.ranking():
            if action.is_terminate:
                if not fallbacks:
                    break
                past = True
                continue
            if value > -math.inf and not (past and action in failed):   # -inf: ruled out (HEUR: unsupported)
                out.append((action, value))
        return out

    def to_dict(self) -> dict:
        return {'action': _action_doc(self.action), 'simulations': self.simulations,
                'children': [c.to_dict() for c in self.children], **self.info}


def _action_doc(a: Action) -> list:
    return [int(v) for v in a]


def _leaf(model: Model, reward: float, done: bool) -> float:
    """r, or r + gamma max Q(s') from the state the step led to."""
    if done:
        return reward
    return reward + model.gamma * float(np.max(model.q_values(model.actions())))


def _root(model: Model) -> tuple[list[Action], np.ndarray, list[Action], np.ndarray]:
    """(allowed actions, their Q and terminate's, candidates, Q of the candidates):
    candidates are the allowed actions, one per outcome key (the best by Q, the first of
    ties), plus termination. The search simulates candidates only; its ranking still
    lists every allowed action."""
    actions = model.actions()
    q_all = np.asarray(model.q_values(actions), dtype=float)
    key = getattr(model, 'key', None)
    keep = list(range(len(actions)))
    if key is not None:
        best: dict = {}
        for i, a in enumerate(actions):
            k = key(a)
            if k not in best or q_all[i] > q_all[best[k]]:
                best[k] = i
        keep = sorted(best.values())
    candidates = [actions[i] for i in keep] + [TERMINATE]
    return actions, q_all, candidates, np.concatenate([q_all[keep], q_all[-1:]])


def mcts(model: Model, rng: np.random.Generator, budget: int = 5, epsilon: float = 0.05) -> SearchResult:
    """The paper's MCTS from the model's current state (which it leaves unchanged)."""
    if budget < 1:
        raise ValueError(f'mcts: budget must be >= 1, got {budget}')
    if not 0.0 <= epsilon <= 1.0:
        raise ValueError(f'mcts: epsilon must be in [0, 1], got {epsilon}')
    actions, q_all, candidates, q = _root(model)
    result = SearchResult(TERMINATE, root_q=q_all, actions=list(actions))
    root = model.snapshot()
    open_ = list(range(len(candidates)))   # not yet expanded, in candidate order
    for _ in range(budget):
        if not open_:
            break
        if rng.random() < epsilon:
            k = open_[int(rng.integers(len(open_)))]
        else:
            k = max(open_, key=lambda i: (q[i], -i))   # argmax Q, the first of ties
        open_.remove(k)
        reward, done, invalid = model.step(candidates[k])
        leaf = _leaf(model, reward, done)
        model.restore(root)
        child = Child(candidates[k], float(q[k]), visits=1, value_sum=float(q[k]),
                      reward=float(reward), done=bool(done), invalid=bool(invalid), depth=1)
        child.visits += 1
        child.value_sum += leaf
        result.children.append(child)
        result.simulations += 1
    if rng.random() < epsilon:
        result.action = result.children[int(rng.integers(len(result.children)))].action
    else:
        result.action = max(result.children, key=lambda c: c.value).action   # first of ties
    return result


def halving(model: Model, rng: np.random.Generator, budget: int = 5, epsilon: float = 0.0) -> SearchResult:
    """Sequential halving with deepening lines (see the module doc), from the model's
    current state (left unchanged). epsilon: probability of replacing the move with a
    random simulated child (0 at test time)."""
    if budget < 1:
        raise ValueError(f'halving: budget must be >= 1, got {budget}')
    actions, q_all, candidates, q = _root(model)
    result = SearchResult(TERMINATE, root_q=q_all, actions=list(actions))
    root = model.snapshot()
    order = sorted(range(len(candidates)), key=lambda i: (-q[i], i))
    m = min(len(order), first_round(budget))
    lines: dict[int, _Line] = {}
    for k in order[:m]:
        lines[k] = _simulate_child(model, candidates[k], float(q[k]), result)
        model.restore(root)
    survivors = sorted(lines, key=lambda k: (-lines[k].child.value, k))
    while result.simulations < budget:
        survivors = survivors[:math.ceil(len(survivors) / 2)]
        live = [k for k in survivors if lines[k].snap is not None]
        if not live:
            break
        for k in live:
            if result.simulations >= budget:
                break
            result.simulations += _deepen(model, lines[k], budget - result.simulations)[0]
            model.restore(root)
        survivors.sort(key=lambda k: (-lines[k].child.value, k))
    if epsilon > 0 and rng.random() < epsilon:
        result.action = result.children[int(rng.integers(len(result.children)))].action
    else:
        result.action = lines[survivors[0]].child.action
    return result


@dataclass
class _Line:
    child: Child
    ret: float                 # discounted rewards along the line so far
    snap: Any = None           # the state at the line's end; None once the line has ended
    end_q: float = 0.0


def _end_line(model: Model, line: _Line, done: bool) -> None:
    """Value the line after a successful step: its return, plus gamma^depth max Q at its
    end unless the episode ended there (then the line is closed)."""
    child = line.child
    if done:
        child.value_sum, line.snap = line.ret, None
        return
    line.snap, line.end_q = model.snapshot(), float(np.max(model.q_values(model.actions())))
    child.value_sum = line.ret + model.gamma ** child.depth * line.end_q


def _simulate_child(model: Model, action: Action, q: float, result: SearchResult) -> _Line:
    """One simulation of a root candidate: its child (recorded in result) and its line.
    A failed step ends the line at its reward (-1)."""
    reward, done, invalid = model.step(action)
    result.simulations += 1
    child = Child(action, q, visits=1, reward=float(reward), done=bool(done), invalid=bool(invalid), depth=1)
    result.children.append(child)
    line = _Line(child, float(reward))
    if invalid:
        child.value_sum = line.ret
    else:
        _end_line(model, line, bool(done))
    return line


def _deepen(model: Model, line: _Line, budget: int) -> tuple[int, str]:
    """Extend a line by the step a verified greedy agent would take at its end: the best
    action by Q whose simulated step succeeds (each try is one simulation, at most
    `budget`). Returns (simulations spent, what happened): 'stepped'; 'stopped' (the
    network values terminating above every action there); 'dead' (every action it
    values above terminating failed); 'budget' (ran out before one succeeded). Except after 'stepped' the line ends,
    valued by Q(s, terminate) where it stopped: what the agent would get by stopping."""
    child, gamma = line.child, model.gamma
    model.restore(line.snap)
    _, _, candidates, iq = _root(model)
    discount = gamma ** child.depth
    spent, status = 0, 'dead'
    for k in sorted(range(len(candidates)), key=lambda i: (-iq[i], i)):
        action = candidates[k]
        if action.is_terminate:
            # Stopping is worth more than what is left: by choice, or because all that
            # was worth more failed.
            status = 'stopped' if spent == 0 else 'dead'
            break
        if spent >= budget:
            status = 'budget'
            break
        reward, done, invalid = model.step(action)
        spent += 1
        if invalid:
            model.restore(line.snap)
            continue
        child.depth += 1
        line.ret += discount * reward
        _end_line(model, line, done)
        return spent, 'stepped'
    child.value_sum = line.ret + discount * float(iq[-1])
    line.snap = None
    return spent, status


def lookahead(model: Model, rng: np.random.Generator, budget: int = 5, epsilon: float = 0.0,
              horizon: int = 2) -> SearchResult:
    """Verified greedy with a look-ahead veto (see the module doc): candidates in the
    order of Q; each is simulated, then its line extended by verified greedy steps up to
    `horizon` steps in all; the first whose step succeeds and whose line does not run
    into a dead end is the move. A dead end still beats stopping when nothing else
    works (its block adds coverage): then the best such child by value; termination
    only when every simulated candidate failed or the network prefers it. epsilon:
    probability of a random simulated, valid child instead (0 at test time)."""
    if budget < 1:
        raise ValueError(f'lookahead: budget must be >= 1, got {budget}')
    if horizon < 1:
        raise ValueError(f'lookahead: horizon must be >= 1, got {horizon}')
    actions, q_all, candidates, q = _root(model)
    result = SearchResult(TERMINATE, root_q=q_all, actions=list(actions))
    root = model.snapshot()
    chosen, dead = None, []
    for k in sorted(range(len(candidates)), key=lambda i: (-q[i], i)):
        action = candidates[k]
        if action.is_terminate or result.simulations >= budget:
            break
        line = _simulate_child(model, action, float(q[k]), result)
        child, status = line.child, 'stepped'
        while child.depth < horizon and line.snap is not None and result.simulations < budget:
            spent, status = _deepen(model, line, budget - result.simulations)
            result.simulations += spent
        model.restore(root)
        if child.invalid:
            continue
        if status == 'dead':
            dead.append(child)
            continue
        chosen = child
        break
    if chosen is None and dead:
        chosen = max(dead, key=lambda c: c.value)
    valid = [c for c in result.children if not c.invalid]
    if epsilon > 0 and valid and rng.random() < epsilon:
        chosen = valid[int(rng.integers(len(valid)))]
    result.action = chosen.action if chosen is not None else TERMINATE
    return result


def first_round(budget: int) -> int:
    """How many root candidates halving simulates first: the most that still leaves
    budget to deepen the better half one step (m + ceil(m / 2) <= budget)."""
    m = 1
    while (m + 1) + math.ceil((m + 1) / 2) <= budget:
        m += 1
    return m


def q_order(model: Model):
    """order(env, actions) for the branch and bound: best Q first (ties keep their order)."""
    def order(_env, actions: list[Action]) -> list[Action]:
        q = np.asarray(model.q_values(actions), dtype=float)[:-1]
        return [actions[i] for i in np.argsort(-q, kind='stable')]
    return order


def bnb(model: Model, rng: np.random.Generator, budget: float = 10.0, epsilon: float = 0.0,
        max_states: int = 100_000) -> SearchResult:
    """The branch and bound (`sequencing.decide.exact.exact_search`) within `budget` seconds,
    children in the order of Q (a scorer whose scores are no values, HEUR: most target
    cells first, then bottom-up, `exact.by_gain_then_height`): the move is the first action of the best line found
    (termination when no line fills more of the target than stopping here). The
    ranking lists that move, then the other allowed actions by Q as a verified caller's
    fallbacks; with no line it lists nothing. `line` is the whole line; `info` has the
    line's coverage, whether the search was complete and how it ended (`ExactResult.proof`), its
    bound, states and why it stopped short. rng and epsilon are unused (the search is deterministic)."""
    if not budget > 0:
        raise ValueError(f'bnb: budget must be a positive number of seconds, got {budget}')
    actions, q_all, _, _ = _root(model)
    by_value = getattr(getattr(model, 'policy', None), 'values', True)
    found = exact_search(model, float(budget), max_states=max_states, order=q_order(model) if by_value else None)
    info = {'coverage': found.coverage, 'complete': found.complete, 'proof': found.proof, 'bound': found.bound,
            'states': found.states, 'reason': found.reason}
    if not found.actions and not found.complete:
        # Cut before it found anything better than here: no verdict, so the ranking is Q's.
        return SearchResult(TERMINATE, [], found.states, root_q=q_all, actions=list(actions), info=info)
    return line_result(list(actions), q_all, list(found.actions), found.coverage, found.states, info)


def line_result(actions: list[Action], q_all: np.ndarray, line: list[Action], value: float,
                simulations: int = 0, info: dict | None = None) -> SearchResult:
    """The SearchResult of a line (bnb's, or one a caller kept from an earlier search):
    its first action the move, valued `value`; no line: terminate, nothing proposed."""
    if not line:
        return SearchResult(TERMINATE, [], simulations, root_q=q_all, actions=[], line=[], info=info or {})
    first = line[0]
    q = float(q_all[actions.index(first)]) if first in actions else value
    child = Child(first, q, visits=1, value_sum=float(value), depth=len(line))
    return SearchResult(first, [child], simulations, root_q=q_all, actions=actions, line=list(line),
                        info=info or {})


SEARCHES: dict[str, Callable[..., SearchResult]] = {'mcts': mcts, 'halving': halving, 'lookahead': lookahead,
                                                   'bnb': bnb}


class EnvModel:
    """A `Model` over an AssemblyEnv or RobotAssemblyEnv (anything with .env, .step,
    .snapshot, .restore) with a policy's scores as Q and an action space.

    robot_env: the env that steps (RobotAssemblyEnv, or the AssemblyEnv itself);
    policy: a sequencing Policy whose scores are Q-values (a QPolicy);
    space: an action space (`sequencing.decide.actions.action_space`) giving the allowed actions.
    """

    def __init__(self, robot_env, policy, space, rng_seed: int = 0):
        self.robot_env = robot_env
        self.env = getattr(robot_env, 'env', robot_env)
        self.policy, self.space = policy, space
        self.gamma = float(self.env.config.gamma)
        self._rng = np.random.default_rng(rng_seed)   # for policies that draw (HEUR); a QPolicy does not
        # (steps taken before, action) -> the motion plan its simulation used (robot env), for
        # steps from the state the model was made in: the move can be executed with it instead
        # of planning it again. Deeper steps are not kept (a branch and bound takes thousands).
        self.plans: dict = {}
        self._root_steps = self.env.state.steps

    def actions(self) -> list[Action]:
        return [] if self.env.state.done else list(self.space(self.env))

    def q_values(self, actions: list[Action]) -> np.ndarray:
        if not actions:
            # Only termination is allowed; its Q is what the policy says of stopping.
            return np.asarray(self.policy.scores(self.env, [], self._rng), dtype=float)[-1:]
        return np.asarray(self.policy.scores(self.env, actions, self._rng), dtype=float)

    def step(self, action: Action) -> tuple[float, bool, bool]:
        before = self.env.state.steps
        if hasattr(self.robot_env, 'last_plan'):
            self.robot_env.last_plan = None
        result = self.robot_env.step(action)
        plan = getattr(self.robot_env, 'last_plan', None)
        if plan is not None and before == self._root_steps:
            self.plans[(before, action)] = plan
        return float(result.reward), bool(result.done), bool(result.outcome.is_invalid)

    def key(self, action: Action):
        cells, _ = self.env.resulting_cells(action)
        return action.block, None if cells is None else tuple(sorted(int(c) for c in cells))

    def snapshot(self):
        return self.robot_env.snapshot()

    def restore(self, snapshot) -> None:
        self.robot_env.restore(snapshot)

"""The sequencer interface: a policy scores the candidate actions of a state.

Everything that chooses actions (the paper's HEUR baseline, the GNN's
Q-values, MCTS on top of either) goes through `Policy.scores`: higher is
better, -inf means "never". Scores are a function of the state, the candidate
actions and an explicit random generator the caller passes in, so a search that
asks twice with equally seeded generators gets the same answer; no policy keeps
hidden random state. The caller decides what to do with the ranking: take the
best, or the best that GAMP finds feasible (`ranked_actions` + a check).
"""

from __future__ import annotations

import dataclasses

from typing import Protocol

import numpy as np

from rad_core.domain import support
from rad_core.env.mdp import Action, AssemblyEnv


class Policy(Protocol):
    name: str

    def scores(self, env: AssemblyEnv, actions: list[Action], rng: np.random.Generator) -> np.ndarray:
        """len(actions) + 1 scores, higher is better: one per action, then the
        termination action's. -inf rules an action out; an action scoring at or
        below termination is not worth taking (HEUR scores termination -inf: it
        stops only when nothing else is allowed).
        """


def supported_actions(env: AssemblyEnv, actions: list[Action]) -> list[Action]:
    """HEUR's rule: the actions whose block would rest fully supported (every unit
    on the table, a placed block or its own block), in the given order."""
    occ = env.state.occupancy
    out = []
    for action in actions:
        cells, _ = env.resulting_cells(action)
        if cells is not None and support.fully_supported(env.grid, occ, cells):
            out.append(action)
    return out


class HeurPolicy:
    """The paper's heuristic (Sec. V-B): among the allocation's actions, only those
    whose block would rest fully supported (every cell below it filled, or the
    table), chosen uniformly at random; nothing left means terminate."""

    name = 'heur'
    why_none = 'their blocks would not rest fully supported'
    values = False   # its scores are random tie-breaks, not values: a search orders by its own rule

    def scores(self, env: AssemblyEnv, actions: list[Action], rng: np.random.Generator) -> np.ndarray:
        out = np.full(len(actions) + 1, -np.inf)
        allowed = set(supported_actions(env, actions))
        for n, action in enumerate(actions):
            if action in allowed:
                out[n] = rng.random()
        return out


class LinePolicy:
    """A line's poses in its order (a line the course planner built in the twin, `courses`): an
    action filling the line's k-th pose scores above the (k+1)-th, any other (a re-allocation's
    pose) below the line's but above stopping. It never stops while an allowed action is left,
    where a learned agent may value stopping more halfway along a line it did not choose."""

    name = 'line'
    values = False   # its scores are a line's ranks, not values

    def __init__(self, poses):
        self.rank = {tuple(sorted(int(c) for c in cells)): k for k, cells in enumerate(poses)}

    def scores(self, env: AssemblyEnv, actions: list[Action], rng: np.random.Generator) -> np.ndarray:
        out = np.zeros(len(actions) + 1)
        for n, action in enumerate(actions):
            cells, _ = env.resulting_cells(action)
            k = None if cells is None else self.rank.get(tuple(sorted(int(c) for c in cells)))
            out[n] = 1.0 if k is None else 2.0 + len(self.rank) - k
        return out


def ranked_actions(policy: Policy, env: AssemblyEnv, actions: list[Action],
                   rng: np.random.Generator, fallbacks: bool = False) -> list[Action]:
    """Actions the policy values above terminating, best first (ties keep the given order).
    fallbacks: instead, its fallbacks (`FALLBACKS`): the actions it values at or below
    terminating whose block would stand on its own (`standing_fallbacks`), best first."""
    if not actions:
        return []
    scores = np.asarray(policy.scores(env, actions, rng), dtype=float)
    if scores.shape != (len(actions) + 1,):
        raise ValueError(f'{policy.name}: {scores.shape[0]} scores for {len(actions)} actions + terminate')
    above = ranked_indices(scores)
    if not fallbacks:
        return [actions[i] for i in above]
    return standing_fallbacks(env, [actions[i] for i in ranked_indices(scores, True)[len(above):]])


def standing_fallbacks(env: AssemblyEnv, below: list) -> list:
    """Of the actions an agent values below stopping (`FALLBACKS`), in their order, those whose
    block would stand on its supports alone, its centre of mass FIRM_MARGIN units inside their
    footprint (`support.rests_on_its_own`); none while the structure is only balanced somewhere
    (`firm`). So a fallback never leaves the structure less firm than it found it. Studded bricks
    pressed home are locked, firm whatever their balance: there, those the MDP finds standing with
    their clutch (`AssemblyEnv.evaluate`)."""
    if below and env.grid.clutch is not None:
        return [action for action in below if env.evaluate(action)[0] is None]
    if not below or not firm(env):
        return []
    out = []
    for action in below:
        cells, _ = env.resulting_cells(action)
        if cells is not None and support.rests_on_its_own(env.grid, env.state.occupancy, cells, FIRM_MARGIN):
            out.append(action)
    return out


FIRM_MARGIN = 0.25
"""`firm`: how far (in units) inside its supports' footprint every placed block's centre of mass
must lie."""


def firm(env: AssemblyEnv) -> bool:
    """Whether every placed block would stand on its supports alone with its centre of mass
    FIRM_MARGIN units inside their footprint (`support.rests_on_its_own`): a structure that is
    not only balanced, wedged or hooked."""
    grid, state = env.grid, env.state
    return all(support.rests_on_its_own(grid, state.occupancy, np.asarray(cells), FIRM_MARGIN)
               for cells, _ in state.placed.values())


def ranked_indices(scores: np.ndarray, fallbacks: bool = False) -> list[int]:
    """Indices of the actions scoring above termination (the last score), best first
    (ties keep the given order). fallbacks: then those scoring at or below termination, best
    first, for a verified caller (`FALLBACKS`); an action scoring -inf is never among them."""
    stop, scores = scores[-1], scores[:-1]
    order = np.argsort(-scores, kind='stable')
    above = [int(i) for i in order if np.isfinite(scores[i]) and scores[i] > stop]
    if not fallbacks:
        return above
    return above + [int(i) for i in order if np.isfinite(scores[i]) and not scores[i] > stop]


FALLBACKS = True
"""Whether a verified agent goes on below its scorer's termination value, as a last resort: where
its plan would otherwise end with allocated poses open (every action it values above stopping
failed or there is none, and re-allocating, where it re-allocates, offers nothing new), it tries
the others whose block would stand on its supports alone (`standing_fallbacks`; its centre of
mass well inside the footprint of its units resting on the table or a placed block, as a lintel
on both ends has it and a cantilever does not), best first, and stops only when none is feasible;
unless the structure is only balanced somewhere (`firm`), where it stops as its scorer says
(`deciders.with_fallbacks`). Its check (GAMP and the stability check with the robot, the
stability check without) makes trying an action safe, and every allocated pose filled is target
covered. Last, not beside the others: taken as soon as the actions above stopping failed, a
fallback changed what the re-allocations then proposed (measured: g = 6, seed 18, 0.71 -> 0.61).
Not cantilevers or balanced blocks: the stability check judges blocks at their exact cells, and
a block the network values below stopping can stand there and still bring down the built
structure, whose blocks lie a little off their cells (measured: `overhang_edge`, 0.84 -> 0.37
built when a P5 balanced on one cube was taken as a fallback: the build lost three blocks).
docs/search.md has the figures."""


DROP_LOOKAHEAD = 8
"""A drop (GAMP lets the block go over its place: `gamp.planner.GampConfig.drop`) is taken only where none
of the next this many distinct actions ranked after it can be set down. The hand drops where it has no
other way in; taken as soon as GAMP offers them, drops let the sequencer into orders it was never
trained on (measured: generated g = 6 seeds 6, 7 and 19 fell from 1.0 to 0.94-0.95)."""


def _drops(result) -> bool:
    """Whether a check's answer (a GAMP result, a `MotionPlan`, or a check carrying one as .plan) drops."""
    return getattr(result, 'drop', 0.0) > 0 or getattr(getattr(result, 'plan', None), 'drop', 0.0) > 0


def refused(result):
    """A drop's answer as the refusal of a plan that takes no drops: GAMP's reason why no grasp sets the
    block down (a drop's `reason`), a placement failure."""
    plan = getattr(result, 'plan', None)
    reason = result.reason or getattr(plan, 'reason', '')
    if hasattr(result, '_replace'):       # a NamedTuple (`deciders.Check`)
        return result._replace(success=False, failure='placement', reason=reason)
    return dataclasses.replace(result, success=False, failure='placement', reason=reason)


def first_feasible(env: AssemblyEnv, ranked: list[Action], check, drops: bool = True,
                   lookahead: int = DROP_LOOKAHEAD):
    """Go down the ranking and return (action, result) of the first action whose
    check(action) answers with .success, plus the (action, result) pairs that failed
    before it; (None, None, failed) when none does. /plan_assembly and the
    heur-verified agent both choose this way (check = GAMP from the current state).
    An action GAMP can only drop in waits for the next `lookahead` actions: the
    first of those it sets down is taken instead; drops False: such an action counts as failed.

    Ranked actions that only differ in the unit or rotation naming the same final
    pose are one motion: checked once.
    """
    tried, failed = set(), []
    dropped, left = None, 0
    for action in ranked:
        cells, yaw = env.resulting_cells(action)
        key = (action.block, tuple(sorted(int(c) for c in cells)), yaw)
        if key in tried:
            continue
        tried.add(key)
        result = check(action)
        if result.success and not _drops(result):
            return action, result, failed
        if not result.success or not drops:
            failed.append((action, result if not result.success else refused(result)))
        elif dropped is None:
            dropped, left = (action, result), lookahead + 1
        if dropped is not None:
            left -= 1
            if left <= 0:
                break
    if dropped is not None:
        return dropped[0], dropped[1], failed
    return None, None, failed

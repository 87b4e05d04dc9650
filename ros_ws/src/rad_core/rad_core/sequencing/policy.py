"""The sequencer interface: a policy scores the allowed actions of a state.

Everything that chooses actions (the paper's HEUR baseline now, the GNN's
Q-values later, MCTS on top of either) goes through `Policy.scores`: higher is
better, -inf means "never". The caller decides what to do with the ranking: take
the best, or the best that GAMP finds feasible (`ranked_actions` + a check).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from rad_core import support
from rad_core.mdp import Action, AssemblyEnv


class Policy(Protocol):
    name: str

    def reset(self, seed: int) -> None:
        """Start a new episode with this seed (policies may be stochastic)."""

    def scores(self, env: AssemblyEnv, actions: list[Action]) -> np.ndarray:
        """One score per action, higher is better; -inf rules an action out."""


class HeurPolicy:
    """The paper's heuristic (Sec. V-B): among the allocation's actions, only those
    whose block would rest fully supported (every cell below it filled, or the
    table), chosen uniformly at random; nothing left means terminate."""

    name = 'heur'

    def __init__(self, seed: int = 0):
        self.reset(seed)

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def scores(self, env: AssemblyEnv, actions: list[Action]) -> np.ndarray:
        out = np.full(len(actions), -np.inf)
        for n, action in enumerate(actions):
            cells, _ = env.resulting_cells(action)
            if cells is not None and support.fully_supported(env.grid, env.state.occupancy, cells):
                out[n] = self.rng.random()
        return out


def ranked_actions(policy: Policy, env: AssemblyEnv, actions: list[Action]) -> list[Action]:
    """Actions the policy allows, best first (ties keep the given order)."""
    if not actions:
        return []
    scores = np.asarray(policy.scores(env, actions), dtype=float)
    order = np.argsort(-scores, kind='stable')
    return [actions[i] for i in order if np.isfinite(scores[i])]


def first_feasible(env: AssemblyEnv, ranked: list[Action], check):
    """Go down the ranking and return (action, result) of the first action whose
    check(action) answers with .success, plus the (action, result) pairs that failed
    before it; (None, None, failed) when none does. /plan_assembly and the
    heur-verified agent both choose this way (check = GAMP from the current state).

    Ranked actions that only differ in the unit or rotation naming the same final
    pose are one motion: checked once.
    """
    tried, failed = set(), []
    for action in ranked:
        cells, yaw = env.resulting_cells(action)
        key = (action.block, tuple(sorted(int(c) for c in cells)), yaw)
        if key in tried:
            continue
        tried.add(key)
        result = check(action)
        if result.success:
            return action, result, failed
        failed.append((action, result))
    return None, None, failed

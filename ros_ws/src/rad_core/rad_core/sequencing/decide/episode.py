"""One episode loop for evaluation, training rollouts and /plan_assembly.

The loop only knows the MDP: ask `decide` for the next action, let `act` carry
it out (by default the env's own step; with the robot, GAMP and the twin), add
the discounted reward, repeat until the episode is done. What differs between
callers is in the two callables and the `on_step` hook:

- evaluation: decide = rank by a policy (and GAMP-verify), act = env/robot step;
- training: decide = epsilon-greedy on Q-values, on_step = store the transition
  and take gradient steps;
- /plan_assembly: decide = rank and GAMP-verify in the planning copy,
  act = step the planning copy and record the motion.

A decision may carry a `plan` (e.g. the motion GAMP already found, so the robot
need not plan it again) and a `reason` (why it stops: shown to users).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from rad_core.env.mdp import TERMINATE, Action, AssemblyEnv, Outcome, StepResult


@dataclass
class Decision:
    action: Action
    plan: Any = None
    reason: str = ''


def stop(reason: str = '') -> Decision:
    return Decision(TERMINATE, None, reason)


@dataclass
class Episode:
    ret: float = 0.0
    outcome: Outcome | None = None
    steps: int = 0
    coverage: float = 0.0
    reason: str = ''          # why it stopped, when a decision or a failure said so
    timed_out: bool = False   # the deadline ended it before the MDP did

    def row(self) -> dict:
        return {'return': self.ret, 'outcome': self.outcome.value if self.outcome else None,
                'coverage': self.coverage, 'steps': self.steps}


Decide = Callable[[AssemblyEnv, np.random.Generator], Decision]
Act = Callable[[Decision], StepResult]


def run_episode(env: AssemblyEnv, decide: Decide, rng: np.random.Generator, act: Act | None = None,
                on_step: Callable[[Decision, StepResult], None] | None = None,
                max_steps: int = 10_000, deadline: float | None = None) -> Episode:
    """Play from the env's current state until the episode ends.

    deadline: a time.perf_counter() value; when it passes before a decision the
    episode stops there, not done, with timed_out set (a planner's time limit).
    """
    act = act if act is not None else (lambda d: env.step(d.action))
    ep, discount = Episode(), 1.0
    for _ in range(max_steps):
        if env.state.done:
            break
        if deadline is not None and time.perf_counter() > deadline:
            ep.timed_out = True
            break
        decision = decide(env, rng)
        result = act(decision)
        ep.ret += discount * result.reward
        discount *= env.config.gamma
        ep.outcome = result.outcome
        if result.outcome.is_invalid:
            ep.reason = result.reason
        elif decision.reason:
            ep.reason = decision.reason
        if on_step is not None:
            on_step(decision, result)
    ep.steps = env.state.steps
    ep.coverage = env.coverage()
    return ep

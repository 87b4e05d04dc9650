"""How a ranking becomes a decision of the episode loop (`sequencing.decide.episode`) without the
robot (`rad eval` without --robot, training's evaluations): the best-ranked action, the best
one a check finds feasible, or a test-time search's move. The checks: the physics stability
check, or a simulated step of the planning copy. With the robot, decisions are
/plan_assembly's (`sequencing.planning.plan`), whoever runs it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rad_core.env.mdp import AssemblyEnv, Outcome
from rad_core.sequencing.decide import policy as ranking_rules
from rad_core.sequencing.decide.actions import ActionSpace
from rad_core.sequencing.decide.episode import Decide, Decision, stop
from rad_core.sequencing.decide.policy import Policy, first_feasible, ranked_actions, standing_fallbacks
from rad_core.sequencing.decide.search import SEARCHES, EnvModel


class Check(NamedTuple):
    success: bool
    reason: str = ''
    plan: object = None     # the motion plan the check found, when it planned one
    failure: str = ''       # 'grasp' when the block cannot be picked where it lies (as GAMP says)


def stability_check(env: AssemblyEnv):
    """A verify() for no-robot agents: would the action be valid now (geometry and
    physics, on the env's own cached stability check)? Acting is left to the env."""
    def check(action) -> Check:
        outcome, reason, _, _ = env.evaluate(action)
        return Check(outcome is None, reason)
    return check


def policy_decider(policy: Policy, actions: ActionSpace, verify=None) -> Decide:
    """decide() for the episode loop: the best-ranked action, or with verify
    (a GAMP check, `RobotAssemblyEnv.plan`) the best one it finds feasible,
    carrying its motion plan; nothing ranked (or feasible) means terminate.
    decide(env, rng, fallbacks=True): among the policy's fallbacks instead (`with_fallbacks`)."""
    def decide(env: AssemblyEnv, rng: np.random.Generator, fallbacks: bool = False) -> Decision:
        ranked = ranked_actions(policy, env, actions(env), rng, fallbacks=fallbacks and verify is not None)
        if verify is None:
            return Decision(ranked[0]) if ranked and not fallbacks else stop()
        action, plan, _ = first_feasible(env, ranked, verify)
        return Decision(action, plan) if action is not None else stop()
    return decide


def search_decider(policy: Policy, actions: ActionSpace, stepper, search_name: str, budget: int,
                   epsilon: float | None = None, verify=None) -> Decide:
    """decide() that searches before every decision (`sequencing.decide.search.SEARCHES[search_name]`, with
    `budget` simulations and exploration `epsilon`, None: the search's default) on `stepper`, the env
    that acts (RobotAssemblyEnv with the robot, the AssemblyEnv without); the search
    leaves it as it was. Unverified: the search's move. Verified: the best of the
    search's ranking that is known to work: a searched child whose simulated step
    succeeded needs no further check (it was a real step of the planning copy, GAMP
    and physics included; its motion plan is reused), an unsearched one is checked by
    simulating it (`simulated_check`); failed children are never taken.
    decide(env, rng, fallbacks=True): among the search's fallbacks instead (`with_fallbacks`),
    from the search already run in this state with these actions."""
    search = SEARCHES[search_name]
    kwargs = {} if epsilon is None else {'epsilon': epsilon}
    check = simulated_check(stepper) if verify is not None else None
    last: dict = {}     # the last search: its state and actions, result and motion plans

    def decide(env: AssemblyEnv, rng: np.random.Generator, fallbacks: bool = False) -> Decision:
        allowed = actions(env)
        if not allowed or (fallbacks and verify is None):
            return stop()
        key = (env.state.steps, tuple(sorted(env.state.placed)), tuple(allowed))
        if last.get('key') != key:
            model = EnvModel(stepper, policy, actions)
            result = search(model, rng, budget=budget, **kwargs)
            plans = {a: plan for (steps, a), plan in model.plans.items() if steps == env.state.steps}
            last.update(key=key, result=result, plans=plans)
        result, plans = last['result'], last['plans']
        if verify is None:
            if result.action.is_terminate:
                return stop()
            return Decision(result.action, plans.get(result.action))
        worked = {c.action for c in result.children if not c.invalid}

        def known_or_simulated(action) -> Check:
            return Check(True, '', plans.get(action)) if action in worked else check(action)
        above = [a for a, _ in result.proposals()]
        proposed = standing_fallbacks(env, [a for a, _ in result.proposals(True)][len(above):]) if fallbacks \
            else above
        action, ok, _ = first_feasible(env, proposed, known_or_simulated)
        return Decision(action, ok.plan) if action is not None else stop()
    return decide


def with_fallbacks(decide: Decide, first: Decide | None = None) -> Decide:
    """A verified agent's fallbacks as a last resort (`policy.FALLBACKS`): first(env, rng) (default:
    decide itself; with re-allocation, decide wrapped in it), and where that stops,
    decide(env, rng, fallbacks=True), the best feasible of what the agent values below stopping.
    When that stops too, the first answer stands (its reason says why the plan ended)."""
    first = first or decide

    def wrapped(env: AssemblyEnv, rng: np.random.Generator) -> Decision:
        decision = first(env, rng)
        if decision.action.is_terminate and ranking_rules.FALLBACKS:
            late = decide(env, rng, fallbacks=True)
            if not late.action.is_terminate:
                return late
        return decision
    return wrapped


def simulated_check(stepper):
    """A check that steps the action in a snapshot of the planning copy and goes back:
    success when the step is valid (with the robot: GAMP, execution and physics)."""
    def check(action) -> Check:
        snap = stepper.snapshot()
        try:
            result = stepper.step(action)
            plan = getattr(stepper, 'last_plan', None)
        finally:
            stepper.restore(snap)
        return Check(not result.outcome.is_invalid, result.reason, plan,
                     'grasp' if result.outcome is Outcome.INVALID_GRASP else '')
    return check

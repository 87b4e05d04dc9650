"""Sequencing (the paper's medium level): which allocated action to take next, and the plan.

Sub-packages, each importing only those before it: `decide` (scoring and search), `planning`
(a plan from an allocation), `bounds` (ceilings), `agent` (an agent's planning as stages under
one deadline), `execution` (running a plan)."""

from rad_core.sequencing.decide.policy import HeurPolicy, Policy, first_feasible, ranked_actions, supported_actions

__all__ = ['HeurPolicy', 'Policy', 'first_feasible', 'ranked_actions', 'supported_actions']

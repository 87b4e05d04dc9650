"""Sequencing (the paper's medium level): which allocated action to take next."""

from rad_core.sequencing.policy import HeurPolicy, Policy, first_feasible, ranked_actions, supported_actions

__all__ = ['HeurPolicy', 'Policy', 'first_feasible', 'ranked_actions', 'supported_actions']

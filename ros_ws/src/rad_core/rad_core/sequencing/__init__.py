"""Sequencing (the paper's medium level): which allocated action to take next."""

from rad_core.sequencing.policy import HeurPolicy, Policy, ranked_actions

__all__ = ['HeurPolicy', 'Policy', 'ranked_actions']

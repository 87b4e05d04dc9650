"""Allocation (the paper's Sec. IV-A): which block types go to which poses."""

from rad_core.allocation.cpsat import AllocationParams, solve
from rad_core.allocation.placements import Placement
from rad_core.allocation.result import AllocationResult
from rad_core.allocation.validate import validate_allocation

__all__ = ['AllocationParams', 'AllocationResult', 'Placement', 'solve', 'validate_allocation']

"""The allocation result and its rad-allocation/1 JSON form."""

from __future__ import annotations

from dataclasses import dataclass, field

from rad_core.allocation.placements import Placement

FORMAT = 'rad-allocation/1'


@dataclass(frozen=True)
class AllocationResult:
    """What a solver returns: status, objective c^T g, best bound, and the poses.

    status is the solver's own word: OPTIMAL (proved), FEASIBLE (time limit hit,
    best found so far; bound says how far from optimal it can be), INFEASIBLE,
    MODEL_INVALID or UNKNOWN (nothing found in time).
    """

    status: str
    objective: float
    bound: float
    solve_time_s: float
    placements: tuple[Placement, ...] = ()
    solver: str = field(default='cp-sat', compare=False)
    arm: object = field(default=None, compare=False)
    """With support='arm': what the arm-aware filter ruled out (`allocation.arm.ArmFilter`)."""

    @property
    def has_solution(self) -> bool:
        return self.status in ('OPTIMAL', 'FEASIBLE')

    def to_dict(self) -> dict:
        return {
            'format': FORMAT,
            'status': self.status,
            'objective': self.objective,
            'bound': self.bound,
            'solve_time_s': self.solve_time_s,
            'placements': [p.to_dict() for p in self.placements],
            **({'arm': self.arm.to_dict()} if self.arm is not None else {}),
        }

    @classmethod
    def from_dict(cls, doc: dict) -> 'AllocationResult':
        placements = tuple(Placement(p['type'], p['target'], int(p['yaw']),
                                     tuple(tuple(int(v) for v in c) for c in p['cells']))
                           for p in doc['placements'])
        return cls(doc['status'], float(doc['objective']), float(doc['bound']),
                   float(doc['solve_time_s']), placements)

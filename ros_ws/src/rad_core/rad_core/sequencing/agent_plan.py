"""What /plan_assembly does for an agent (`rad_core.agents`), whoever supplies the parts.

`plan_for_agent` wires an agent's parts into `plan_assembly`: the first allocation with
its support rule, re-allocation when it re-allocates, verification with GAMP when it
verifies; the scorer and the search are the `rank` callable's (the sequencer's). The
assembly node passes DDS clients for allocate / plan_motion / rank; `AgentPlanner` holds
the same parts in process (CP-SAT, GAMP, a `Sequencer`) for benchmarks and evaluation,
so a figure measured with it is a statement about what the node graph does.
"""

from __future__ import annotations

from rad_core.agents import AgentSpec, label, parse
from rad_core.scene import Scene
from rad_core.sequencing.plan import AssemblyPlan, plan_assembly


def plan_for_agent(spec: AgentSpec, scene: Scene, allocate, plan_motion, rank, reallocate=None, *,
                   support: str | None = None, seed: int = 0, start=None, time_limit_s: float = 60.0,
                   max_reallocations: int = 10, reallocation=None) -> AssemblyPlan:
    """allocate(scene, support=S) and reallocate(scene, no-goods, time limit) -> AllocationResult;
    plan_motion and rank as `plan_assembly` takes them. support: the allocation support when
    the caller has resolved it (default: `spec.resolved_support()`, which reads a model file).
    reallocation: a `ReallocationConfig` (default: its defaults with max_reallocations)."""
    from rad_core.sequencing.reallocation import ReallocationConfig
    support = support or spec.resolved_support()
    if spec.realloc:
        reallocation = reallocation or ReallocationConfig(max_reallocations=max_reallocations)
        reallocation.validate()
    else:
        reallocation = None
    return plan_assembly(scene, lambda s: allocate(s, support=support), plan_motion, rank, seed=seed, start=start,
                         time_limit_s=time_limit_s, reallocate=reallocate if spec.realloc else None,
                         reallocation=reallocation, verify=spec.verify)


def reallocation_support(support: str) -> str:
    """The support rule of re-allocations: stable (every new block can rest on something), and
    arm-aware when the agent's first allocation is ('arm')."""
    return 'arm' if support == 'arm' else 'stable'


class AgentPlanner:
    """`plan_for_agent` with in-process parts: CP-SAT (10 s, one worker), GAMP and the agent's
    sequencer. planner(scene, start, seed) -> AssemblyPlan; `motion` and `gamp` for execution.

    allocation: the first allocation's CP-SAT settings (default: 10 s, one worker, the agent's
    support); reallocation: a `ReallocationConfig` for re-allocating agents (default: the
    assembly node's, the stable allocation; its params set the re-solves' CP-SAT settings);
    policy: the agent's scorer when the caller has already loaded it."""

    def __init__(self, agent: str | AgentSpec = 'default', allocation_time_limit_s: float = 10.0,
                 time_limit_s: float = 120.0, allocation=None, reallocation=None, policy=None):
        from rad_core.gamp.action import MotionPlanner
        from rad_core.sequencing.plan import local_motion_planner
        from rad_core.sequencing.sequencer import Sequencer, SequencerConfig
        self.spec = parse(agent) if isinstance(agent, str) else agent
        self.agent = label(self.spec)
        self.sequencer = Sequencer(SequencerConfig(agent=self.agent), policy)
        self.support = allocation.support if allocation is not None else self.spec.resolved_support(
            self.sequencer.policy)
        self.allocation, self.reallocation = allocation, reallocation
        self.allocation_time_limit_s, self.time_limit_s = allocation_time_limit_s, time_limit_s
        self.gamp = MotionPlanner()
        self.motion = local_motion_planner(self.gamp)

    def allocate(self, scene: Scene, exclude=(), time_limit_s: float | None = None, support: str | None = None,
                 params=None):
        from dataclasses import replace

        from rad_core.allocation.cpsat import AllocationParams, solve
        params = params or self.allocation or AllocationParams(time_limit_s=self.allocation_time_limit_s)
        cap = params.time_limit_s
        limit = cap if time_limit_s is None else max(1e-3, min(cap, float(time_limit_s)))
        return solve(scene, replace(params, time_limit_s=limit, support=support or self.support), exclude)

    def reallocate(self, scene: Scene, exclude, time_limit_s: float | None = None):
        """As the assembly node re-allocates: `reallocation_support` of the agent's (or the
        reallocation config's, when one was given)."""
        params = self.reallocation.params if self.reallocation is not None else None
        support = params.support if params is not None else reallocation_support(self.support)
        return self.allocate(scene, exclude, time_limit_s, support=support, params=params)

    def __call__(self, scene: Scene, start=None, seed: int = 0) -> AssemblyPlan:
        self.sequencer.forget()     # lines a branch and bound kept belong to the last scene's requests
        return plan_for_agent(self.spec, scene, self.allocate, self.motion, self.sequencer.rank, self.reallocate,
                              support=self.support, seed=seed, start=start, time_limit_s=self.time_limit_s,
                              reallocation=self.reallocation)

    def close(self) -> None:
        self.sequencer.close()
        self.gamp.close()

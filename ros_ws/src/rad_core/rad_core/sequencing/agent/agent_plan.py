"""What /plan_assembly does for an agent (`rad_core.sequencing.decide.agents`), whoever supplies the parts.

`plan_for_agent` plans a scene for an agent: a first plan, then the improvement stages the agent's
parts select (`stages`), all under one deadline. The assembly node passes DDS clients for allocate /
plan_motion / rank; `AgentPlanner` holds the same parts in process (CP-SAT, GAMP, a `Sequencer`)
for benchmarks and evaluation, so a figure measured with it is a statement about what the node
graph does.
"""

from __future__ import annotations

import inspect
import math
import time
from dataclasses import is_dataclass, replace
from functools import partial

import numpy as np

from rad_core.allocation.cpsat import AllocationParams, pose_key, solve
from rad_core.allocation.order import hand_order, ordered_cover
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.gamp.action import MotionPlanner
from rad_core.gamp.planner import GampConfig
from rad_core.sequencing.agent.stages import (COVER_TRIES, ORDERED_COVER_S, REPAIR_ROUNDS, Planning, Solvers, improve,
                                              stages_for)
from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling
from rad_core.sequencing.decide.agents import AgentSpec, label, parse
from rad_core.sequencing.decide.sequencer import Sequencer, SequencerConfig
from rad_core.sequencing.planning.courses import course_line, is_crowded
from rad_core.sequencing.planning.plan import AssemblyPlan, local_motion_planner
from rad_core.sequencing.planning.reallocation import ReallocationConfig, reallocation_support

__all__ = ['COVER_TRIES', 'IMPROVE_TIME_S', 'ORDERED_COVER_S', 'REPAIR_ROUNDS', 'AgentPlanner', 'plan_for_agent',
           'remembered_motion', 'remembered_rank', 'remembered_reallocation']

IMPROVE_TIME_S = 2.0
"""The search stage's least budget (s) after the first plan (at least as long as the first plan took;
within the deadline); 0: no improving but the ceiling's (`stages.stages_for`)."""


def plan_for_agent(spec: AgentSpec, scene: Scene, allocate, plan_motion, rank, reallocate=None, *,
                   support: str | None = None, seed: int = 0, start=None, time_limit_s: float = 60.0,
                   max_reallocations: int = 10, reallocation=None, quick_rank=None,
                   improve_time_s: float = IMPROVE_TIME_S, improve_until_s: float | None = None,
                   solvers: Solvers | None = None) -> AssemblyPlan:
    """The agent's plan of the scene, within `time_limit_s` of the call.

    A first plan (`plan_assembly` with the agent's allocation, ranking, verification and
    re-allocation), then the improvement stages the agent's parts select (`stages.stages_for`), in
    order, each given what is left of the one deadline; the answer is the best plan (it fills most
    target cells and did not end on a refused action) when a plan fills the target, the stages are
    done or the deadline has passed. `AssemblyPlan.anytime` records, after the first plan and each
    stage that planned, the time, the best coverage so far and the stage that made the best plan
    ('scorer', or 'search' for an agent that searches, for the first plan); `timings` sums the stages
    of every plan made.

    allocate(scene, support=S[, time_limit_s=T]) and reallocate(scene, no-goods, time limit) ->
    AllocationResult; plan_motion and rank as `plan_assembly` takes them. support: the allocation
    support when the caller has resolved it (default: `spec.resolved_support()`, which reads a model
    file). reallocation: a `ReallocationConfig` (default: its defaults with max_reallocations).
    quick_rank: the scorer alone (`Sequencer.rank(..., scorer_only=True)`): for a verified agent with
    a search, the first plan is ranked by it and the search stage plans with `rank`.
    improve_time_s: the search stage's least budget; 0: no stage but the ceiling's.
    improve_until_s: no stage runs past this many seconds from the call (default: `time_limit_s`);
    the first plan still has `time_limit_s`, so a slow machine gets a complete plan, late.
    solvers: the searches the stages call (default: `stages.Solvers` of this module's names)."""
    support = support or spec.resolved_support()
    if spec.realloc:
        reallocation = reallocation or ReallocationConfig(max_reallocations=max_reallocations)
        reallocation.validate()
    else:
        reallocation = None
    if not (math.isfinite(improve_time_s) and improve_time_s >= 0):
        raise RadError(f'improve_time_s must be finite and >= 0, got {improve_time_s}')
    t0 = time.perf_counter()
    anytime_search = quick_rank is not None and bool(spec.search) and spec.verify
    first_rank = quick_rank if anytime_search else rank
    if spec.repair and spec.verify:
        # A repair plan follows the plan before it until a precedence first changes a choice: the
        # motions and rankings of the worlds both plans pass through are asked for once.
        plan_motion = remembered_motion(plan_motion)
        if not hasattr(first_rank, 'scores'):      # (a Policy ranks in process, at no such cost)
            first_rank = remembered_rank(first_rank)
    if reallocate is not None:
        reallocate = remembered_reallocation(reallocate)
    planning = Planning(spec, scene, support, allocate, plan_motion, rank, first_rank, reallocate, reallocation,
                        seed, start, t0=t0, deadline=t0 + time_limit_s, improve_time_s=improve_time_s,
                        solvers=solvers or effector_solvers('hand'))
    # Plans set every block down, but those of allocations made counting on drops and every plan where
    # the effector is crowded (`Planning.plan`): taken as GAMP offered them, drops led the sequencer
    # into orders it was never trained on (measured: generated g = 6 seeds 6, 7, 12 and 19 fell from
    # 1.0 to 0.93-0.95).
    best = planning.first = planning.plan(first_rank, planning.deadline)
    if improve_until_s is not None:
        planning.deadline = min(planning.deadline, t0 + improve_until_s)
    made_by = 'search' if spec.search and not anytime_search else 'scorer'
    now = time.perf_counter()
    anytime = [{'t': now - t0, 'coverage': best.predicted_coverage, 'plan': made_by}]
    planning.improve_until = min(planning.deadline, now + max(improve_time_s, now - t0)) if improve_time_s > 0 else now
    best, _ = improve(planning, stages_for(spec, support, anytime_search, improve_time_s), best, made_by,
                      planning.deadline, anytime)
    best.anytime = anytime
    if len(planning.plans) > 1:      # the stages of every plan made for it, so they add up to the total
        best.timings = summed_timings(planning.plans)
    best.timings['total'] = time.perf_counter() - t0
    return best


def summed_timings(plans) -> dict:
    """The plans' `timings`, stage by stage."""
    summed: dict = {}
    for plan in plans:
        for stage, seconds in plan.timings.items():
            summed[stage] = summed.get(stage, 0.0) + seconds
    return summed


def _world_key(scene: Scene, q) -> tuple:
    return scene.dumps(), None if q is None else np.asarray(q, dtype=float).tobytes()


def remembered_motion(plan_motion):
    """plan_motion (scene, action, start[, move_aside]) answering a world, action and start it was
    asked before from memory, as it answered then (with `seconds` 0: no planning time was spent).
    GAMP's answer depends on nothing else (its IK restarts are seeded per call)."""
    params = inspect.signature(plan_motion).parameters
    takes_aside, takes_set_down = 'move_aside' in params, 'set_down' in params
    memo: dict = {}

    def remembered(scene: Scene, action, start, move_aside: bool = False, set_down: bool = False):
        key = (*_world_key(scene, start), action, move_aside and takes_aside, set_down and takes_set_down)
        if key in memo:
            return replace(memo[key], seconds=0.0)
        kwargs = {'move_aside': move_aside} if takes_aside else {}
        if takes_set_down:
            kwargs['set_down'] = set_down
        memo[key] = plan_motion(scene, action, start, **kwargs)
        return memo[key]
    return remembered


def remembered_rank(rank):
    """rank (scene, placements, start) answering what it was asked before from memory (with no
    timings: no time was spent)."""
    memo: dict = {}

    def remembered(scene: Scene, placements, start):
        key = (*_world_key(scene, start), tuple(placements))
        if key in memo:
            hit = memo[key]
            return replace(hit, timings={}) if is_dataclass(hit) else hit
        memo[key] = rank(scene, placements, start)
        return memo[key]
    return remembered


def remembered_reallocation(reallocate):
    """reallocate (scene, no-goods, time limit) answering a question it was asked before from memory,
    where that answer is as good as asking again: proven (OPTIMAL, INFEASIBLE), or found with at least
    the time asked for now (a `None` limit: the caller's own, the most). An episode that stalls twice in
    one state asks the same question twice (the second answer shows nothing new), and plans that share
    a prefix of steps reach the same states; at a 2 cm unit a hand-ordered re-solve takes seconds."""
    memo: dict = {}

    def remembered(scene: Scene, exclude, time_limit_s: float | None = None):
        key = (scene.dumps(), frozenset(pose_key(p.type, p.target, p.cells) for p in exclude))
        asked = math.inf if time_limit_s is None else float(time_limit_s)
        if key in memo:
            answer, had = memo[key]
            if answer.status in ('OPTIMAL', 'INFEASIBLE') or had >= asked:
                return replace(answer, solve_time_s=0.0)
        answer = reallocate(scene, exclude, time_limit_s)
        memo[key] = (answer, asked)
        return answer
    return remembered


def effector_solvers(effector: str) -> Solvers:
    """The stages' searches (`stages.Solvers`) counting on this effector's grasps and the cells it needs
    free (`allocation.arm.HandBlocked`). The hand's set blocks down, and where it drops (`GampConfig.drop`)
    the cover stage's last tries count on drops (`Solvers.drop_covers`): a cover, then, where its plans
    leave cells, one that puts each pose before those over it (`order_model`'s way_down). The second
    built the solid 3 x 3 x 2 box whole, where the first put a block under one placed before it; as
    the only try it lost g = 5 seeds 0 and 17 (1.0 -> 0.93), which the first fills. The course line
    sets blocks down (counting on drops at a 5 cm unit, the 72-block wall_openings built 0.51 where
    setting down built 0.97), except where the fingers crowd a unit's neighbours
    (`courses.is_crowded`: 2 cm units), where it counts on drops and its plan takes them; there the
    design stage steps aside (`Solvers.crowded`)."""
    if effector == 'hand':
        set_down, drops = GampConfig(drop=False), GampConfig()
        return Solvers(partial(course_line, gamp=set_down, crowded=drops if drops.drop else None),
                       partial(hand_order, gamp=set_down),
                       partial(ordered_cover, gamp=set_down), robot_ceiling,
                       (partial(ordered_cover, gamp=drops), partial(ordered_cover, gamp=drops, way_down=True))
                       if drops.drop else (), is_crowded)
    gamp = GampConfig(effector=effector)
    return Solvers(partial(course_line, gamp=gamp), partial(hand_order, gamp=gamp), partial(ordered_cover, gamp=gamp),
                   robot_ceiling)


class AgentPlanner:
    """`plan_for_agent` with in-process parts: CP-SAT (10 s, one worker), GAMP and the agent's
    sequencer. planner(scene, start, seed) -> AssemblyPlan; `motion` and `gamp` for execution.

    allocation: the first allocation's CP-SAT settings (default: 10 s, one worker, the agent's
    support); reallocation: a `ReallocationConfig` for re-allocating agents (default: the
    assembly node's, the stable allocation; its params set the re-solves' CP-SAT settings);
    policy: the agent's scorer when the caller has already loaded it; improve_time_s: the search
    stage's least budget (`plan_for_agent`; the assembly node's parameter of the same name)."""

    def __init__(self, agent: str | AgentSpec = 'default', allocation_time_limit_s: float = 10.0,
                 time_limit_s: float = 120.0, allocation=None, reallocation=None, policy=None,
                 improve_time_s: float = IMPROVE_TIME_S, effector: str = 'hand'):
        self.spec = parse(agent) if isinstance(agent, str) else agent
        self.agent = label(self.spec)
        self.sequencer = Sequencer(SequencerConfig(agent=self.agent), policy)
        self.support = allocation.support if allocation is not None else self.spec.resolved_support(
            self.sequencer.policy)
        self.allocation, self.reallocation = allocation, reallocation
        self.allocation_time_limit_s, self.time_limit_s = allocation_time_limit_s, time_limit_s
        self.improve_time_s = improve_time_s
        self.effector = effector
        self.gamp = MotionPlanner(GampConfig(effector=effector))
        self.motion = local_motion_planner(self.gamp)
        self.solvers = effector_solvers(effector)

    def allocate(self, scene: Scene, exclude=(), time_limit_s: float | None = None, support: str | None = None,
                 params=None):

        params = params or self.allocation or AllocationParams(time_limit_s=self.allocation_time_limit_s)
        params = replace(params, effector=self.effector)
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
                              reallocation=self.reallocation, quick_rank=self.quick_rank,
                              improve_time_s=self.improve_time_s, solvers=self.solvers)

    def quick_rank(self, scene: Scene, placements, start=None):
        """The agent's scorer alone (the first plan of an agent that searches)."""
        return self.sequencer.rank(scene, placements, start, scorer_only=True)

    def close(self) -> None:
        self.sequencer.close()
        self.gamp.close()

"""What /plan_assembly does for an agent (`rad_core.sequencing.decide.agents`), whoever supplies the parts.

`plan_for_agent` wires an agent's parts into `plan_assembly`: the first allocation with
its support rule, re-allocation when it re-allocates, verification with GAMP when it
verifies; the scorer and the search are the `rank` callable's (the sequencer's). The
assembly node passes DDS clients for allocate / plan_motion / rank; `AgentPlanner` holds
the same parts in process (CP-SAT, GAMP, a `Sequencer`) for benchmarks and evaluation,
so a figure measured with it is a statement about what the node graph does.
"""

from __future__ import annotations

import inspect
import math
import time
from dataclasses import is_dataclass, replace

import numpy as np

from rad_core.allocation.cpsat import AllocationParams, solve
from rad_core.allocation.order import Precedence, hand_order, ordered_cover
from rad_core.allocation.placements import Placement
from rad_core.allocation.result import AllocationResult
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.env.mdp import AssemblyEnv
from rad_core.gamp.action import MotionPlanner
from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling
from rad_core.sequencing.decide.agents import AgentSpec, label, parse
from rad_core.sequencing.decide.policy import LinePolicy
from rad_core.sequencing.decide.sequencer import Sequencer, SequencerConfig
from rad_core.sequencing.planning.courses import course_line
from rad_core.sequencing.planning.plan import AssemblyPlan, local_motion_planner, plan_assembly
from rad_core.sequencing.planning.reallocation import ReallocationConfig, reallocation_support

IMPROVE_TIME_S = 2.0
"""Anytime planning's least budget (s) for improving on the first plan with the search (`plan_for_agent`:
as long again as the first plan took, and at least this; order repair has the time limit; 0: no
improving at all)."""


def plan_for_agent(spec: AgentSpec, scene: Scene, allocate, plan_motion, rank, reallocate=None, *,
                   support: str | None = None, seed: int = 0, start=None, time_limit_s: float = 60.0,
                   max_reallocations: int = 10, reallocation=None, quick_rank=None,
                   improve_time_s: float = IMPROVE_TIME_S) -> AssemblyPlan:
    """allocate(scene, support=S) and reallocate(scene, no-goods, time limit) -> AllocationResult;
    plan_motion and rank as `plan_assembly` takes them. support: the allocation support when
    the caller has resolved it (default: `spec.resolved_support()`, which reads a model file).
    reallocation: a `ReallocationConfig` (default: its defaults with max_reallocations).

    Anytime planning, for a verified agent with a search and a `quick_rank` (its scorer alone,
    `Sequencer.rank(..., scorer_only=True)`): a first complete plan ranked by the scorer (about a
    second at the paper's sizes); when it leaves target cells unfilled, the agent's own plan (with
    its search) within the improvement budget (and the time limit), kept only where it fills more.
    The improvement budget: as long again as the first plan took, and at least `improve_time_s`;
    none when `improve_time_s` is 0.
    A large structure first (more candidate poses than one ordered cover takes,
    `courses.COURSES_ABOVE`), for agents with order repair and an arm-aware support ('arm',
    'hand'), where the first plan leaves cells: the line built course by course in the planning
    twin (`courses.course_line`), planned as the allocation with its order (ranked by
    `LinePolicy`); where it fills more than the first plan, what follows re-plans the first
    allocation and is skipped, and the fourth chain below is skipped on large structures either way.
    Order repair (`spec.repair`) comes first, within the time limit (its rounds bound it, not the
    budget): while the best plan leaves cells unfilled and the latest plan's refusals taught
    precedences not known before (`AssemblyPlan.conflicts`), at most `REPAIR_ROUNDS` more plans
    with the same allocation and ranking that keep to all of them (`plan.precedences_last`), each
    kept only where it fills more; where cells are still left and the hand's own order of the
    allocation (`hand_order`) places more, a second chain from that order (one plan keeping to its
    precedences, then rounds as before), for at most as long again as everything before took;
    with support 'hand', where cells are still left, a third chain from the arm's allocation (one
    plan and its rounds), for at most as long again. With `spec.ceiling` (S seconds), where cells
    are still left: the robot-feasible ceiling's search for up to S seconds (within the time limit)
    and a plan of the line it finds (`ceiling_line`), kept where it fills more. The search then
    gets what is left of the budget. Last, with order repair and an arm-aware support ('arm',
    'hand'), where cells are still left: order repair's fourth chain, the allocation and its order
    found together (`hand_order.ordered_cover`) where they place more than the best plan, planned
    with that order's precedences and repair rounds after it, then another cover where those fall
    short (at most `COVER_TRIES`); for at most as long again as everything before took, and at
    least `ORDERED_COVER_S` and the improvement budget (within the time limit).
    `AssemblyPlan.anytime` records each plan's time and coverage, and the answer's `timings` the
    stages of all of them. Otherwise one plan, the agent's own (its one entry in `anytime`:
    'scorer', or 'search' for an agent that searches)."""
    support = support or spec.resolved_support()
    if spec.realloc:
        reallocation = reallocation or ReallocationConfig(max_reallocations=max_reallocations)
        reallocation.validate()
    else:
        reallocation = None
    if not (math.isfinite(improve_time_s) and improve_time_s >= 0):
        raise RadError(f'improve_time_s must be finite and >= 0, got {improve_time_s}')

    def plan_with(ranker, limit: float, allocate_first=None, precedences=()) -> AssemblyPlan:
        return plan_assembly(scene, allocate_first or (lambda s: allocate(s, support=support)), plan_motion,
                             ranker, seed=seed, start=start, time_limit_s=limit,
                             reallocate=reallocate if spec.realloc else None, reallocation=reallocation,
                             verify=spec.verify, precedences=precedences)

    t0 = time.perf_counter()
    large = False       # a structure planned course by course (`courses`)
    anytime_search = quick_rank is not None and bool(spec.search) and spec.verify
    first_rank = quick_rank if anytime_search else rank
    if spec.repair and spec.verify:
        # A repair plan follows the plan before it until a precedence first changes a choice: the
        # motions and rankings of the worlds both plans pass through are asked for once.
        plan_motion = remembered_motion(plan_motion)
        if not hasattr(first_rank, 'scores'):      # (a Policy ranks in process, at no such cost)
            first_rank = remembered_rank(first_rank)
    best = plan_with(first_rank, time_limit_s)
    plans = [best]
    kind = 'search' if spec.search and not anytime_search else 'scorer'
    anytime = [{'t': time.perf_counter() - t0, 'coverage': best.predicted_coverage, 'plan': kind}]

    def keep(plan: AssemblyPlan, made_by: str) -> None:
        """Record a further plan; it becomes the best (made by `made_by`) where it fills more."""
        nonlocal best, kind
        plans.append(plan)
        if plan.predicted_coverage > best.predicted_coverage + 1e-9 and not _invalid(plan):
            best, kind = plan, made_by
        anytime.append({'t': time.perf_counter() - t0, 'coverage': best.predicted_coverage, 'plan': kind})

    # Improving may take as long again as the first plan did, and at least improve_time_s (0: not at
    # all): a large structure's first plan takes minutes, and a plan in another order about as long.
    first_s = time.perf_counter() - t0
    budget = max(improve_time_s, first_s) if improve_time_s > 0 else 0.0
    improve_until = min(t0 + time_limit_s, time.perf_counter() + budget)
    if spec.repair and spec.verify:
        # Repair is bounded by its rounds, not by the budget: each round may take the time left
        # before the time limit (a large structure's third repair plan is often the one that fills it).
        repair_until = t0 + time_limit_s if improve_time_s > 0 else t0
        first_allocation = best.allocation

        def repair(latest: AssemblyPlan, known: dict, until: float, allocation=None) -> None:
            """Rounds of order repair after `latest` (of `allocation`, default the first), keeping to
            `known` and what its refusals teach."""
            allocation = allocation or first_allocation
            for _ in range(REPAIR_ROUNDS):
                left = until - time.perf_counter()
                new = [p for p in latest.conflicts if p not in known]
                if best.predicted_coverage >= 1.0 - 1e-9 or left <= 0 or not new or best.allocation is None:
                    break
                known.update(dict.fromkeys(new))
                latest = plan_with(first_rank, left, lambda s: allocation, tuple(known))
                keep(latest, 'repair')

        def chain(allocation, precedences, until: float) -> None:
            """A chain from known precedences: one plan of `allocation` keeping to them, then
            repair rounds after it."""
            known = dict.fromkeys(precedences)
            latest = plan_with(first_rank, until - time.perf_counter(), lambda s: allocation, tuple(known))
            keep(latest, 'repair')
            repair(latest, known, until, allocation)

        # A large structure (more candidate poses than one ordered cover takes), where the first
        # plan leaves cells: the line built course by course in the planning twin (`courses`), as
        # the allocation with its order, ranked in that order (`LinePolicy`: the agent's network may
        # value stopping more halfway along it), before any repair round (each takes long at this size).
        first = best
        if support in ('arm', 'hand') and best.predicted_coverage < 1.0 - 1e-9 and repair_until > t0:
            line = course_line(scene, repair_until - time.perf_counter())
            large = line is not None
            left = repair_until - time.perf_counter()
            if large and line.actions and line.coverage > best.predicted_coverage + 1e-9 and left > 0:
                allocation, order, poses = line_allocation(scene, line.actions, 'courses', 'the course line',
                                                           line.seconds)
                keep(plan_with(LinePolicy(poses), left, lambda s: allocation, order), 'courses')
                if kind == 'courses':
                    # The rounds and chains below re-plan the first allocation, which the line has
                    # beaten; at this size each takes as long as the line (measured: on the flush
                    # walls they found nothing better in the time left), so they end here.
                    repair_until = time.perf_counter()
        repair(first, {}, repair_until)
        # Where refusals alone left cells unfilled: the hand's own order of the allocation
        # (`hand_order`) as the known precedences, and repair rounds after it, for at most as long
        # again as everything before took (and within the time limit); only where that order
        # places more than the best plan.
        now = time.perf_counter()
        until = min(repair_until, now + (now - t0))
        if best.predicted_coverage < 1.0 - 1e-9 and until > now and first_allocation is not None:
            guess = hand_order(scene, first_allocation.placements)
            if guess.precedences and guess.coverage > best.predicted_coverage + 1e-9:
                chain(first_allocation, guess.precedences, until)
        # With the hand's allocation (support 'hand'), where cells are still left: a plan from the
        # arm's allocation, which the hand's order may have traded away (a pair of blocks the order
        # cannot place both of, where a re-allocation on the way would have found a way round), and
        # its repair rounds, for at most as long again as everything before took.
        now = time.perf_counter()
        until = min(repair_until, now + (now - t0))
        if support == 'hand' and best.predicted_coverage < 1.0 - 1e-9 and until > now:
            latest = plan_with(first_rank, until - now, lambda s: allocate(s, support='arm'))
            keep(latest, 'repair')
            if latest.allocation is not None:
                repair(latest, {}, until, latest.allocation)
    if spec.ceiling and spec.verify and best.predicted_coverage < 1.0 - 1e-9:
        # The ceiling's search from the best plan's coverage, for up to spec.ceiling seconds, and a
        # plan of the line it finds (its poses as the allocation, its order as precedences).
        seconds = min(spec.ceiling, t0 + time_limit_s - time.perf_counter())
        line = ceiling_line(scene, best.predicted_coverage, seconds) if seconds > 0 else None
        left = t0 + time_limit_s - time.perf_counter()
        if line is not None and left > 0:
            allocation, order = line
            keep(plan_with(first_rank, left, lambda s: allocation, order), 'ceiling')
    left = improve_until - time.perf_counter()
    if anytime_search and best.predicted_coverage < 1.0 - 1e-9 and left > 0:
        keep(plan_with(rank, left), 'search')
    # Last, where cells are still left: the cover and its order at once (`ordered_cover`, the robot
    # ceiling's ordered bound as a plan), where it places more than the best plan, as the
    # allocation with its order's precedences, and repair rounds after it; where those fall
    # short, another cover (at most COVER_TRIES), all for at most as long again as everything
    # before took, and at least one CP-SAT time and the improvement budget.
    if spec.repair and spec.verify and support in ('arm', 'hand') and not large:
        now = time.perf_counter()
        until = min(repair_until, now + max(now - t0, ORDERED_COVER_S + improve_time_s))
        avoid: list = []
        for _ in range(COVER_TRIES):
            now = time.perf_counter()
            if best.predicted_coverage >= 1.0 - 1e-9 or now >= until:
                break
            cover = ordered_cover(scene, min(ORDERED_COVER_S, until - now), avoid=avoid)
            if cover.coverage <= best.predicted_coverage + 1e-9 or time.perf_counter() >= until:
                break
            avoid.append(cover.order)    # the next try, where this one's plans fall short, another cover
            chain(cover_allocation(cover, time.perf_counter() - now), cover.precedences, until)
    best.anytime = anytime
    if len(plans) > 1:      # the stages of every plan made for it, so they add up to the total
        summed: dict = {}
        for plan in plans:
            for stage, seconds in plan.timings.items():
                summed[stage] = summed.get(stage, 0.0) + seconds
        best.timings = summed
    best.timings['total'] = time.perf_counter() - t0
    return best


COVER_TRIES = 2
"""Order repair's fourth chain: the most covers it plans (`ordered_cover`, each avoiding those before)."""

ORDERED_COVER_S = 5.0
"""Order repair's fourth chain: CP-SAT's most seconds (deterministic time) for the cover and its
order (`ordered_cover`)."""


def cover_allocation(cover, seconds: float):
    """An `AllocationResult` of an `ordered_cover`'s poses (FEASIBLE, its c^T g), solved in `seconds`."""
    return AllocationResult('FEASIBLE', float(cover.value), float(cover.value), seconds, tuple(cover.placements),
                            solver='ordered cover')


def ceiling_line(scene: Scene, incumbent: float, seconds: float):
    """The line of the robot-feasible ceiling's search (`sequencing.exact.robot_ceiling`, at most
    `seconds`) from the scene's state, where it beats `incumbent`: (an `AllocationResult` of its
    poses, the `Precedence`s that put them in its order); None where it found nothing better."""
    t0 = time.perf_counter()
    found = robot_ceiling(scene, seconds, incumbent=incumbent)
    if not found.actions or found.coverage <= incumbent + 1e-9:
        return None
    return line_allocation(scene, found.actions, 'ceiling', 'the ceiling\'s line', time.perf_counter() - t0)[:2]


def line_allocation(scene: Scene, actions, solver: str, why: str, seconds: float):
    """A line of actions from the scene's state as (an `AllocationResult` of its poses, named
    `solver`, the `Precedence`s (`why`) that put them in the line's order, the poses (cells) in
    that order)."""
    env = AssemblyEnv(scene)
    env.reset()
    placements, poses = [], []
    for action in actions:    # each block once: its cells and yaw follow from where it lies now
        cells, yaw = env.resulting_cells(action)
        region, ijk = env.grid.region_cells(cells)
        placements.append(Placement(scene.blocks[action.block].type, scene.targets[region].name, int(yaw),
                                    tuple(tuple(c) for c in ijk)))
        poses.append(tuple(sorted(int(c) for c in cells)))
    order = tuple(Precedence(a, b, why) for i, a in enumerate(poses) for b in poses[i + 1:])
    value = float(sum(int(env.grid.weights[list(c)].sum()) for c in poses))
    return AllocationResult('FEASIBLE', value, value, seconds, tuple(placements), solver=solver), order, poses


def _world_key(scene: Scene, q) -> tuple:
    return scene.dumps(), None if q is None else np.asarray(q, dtype=float).tobytes()


def remembered_motion(plan_motion):
    """plan_motion (scene, action, start[, move_aside]) answering a world, action and start it was
    asked before from memory, as it answered then (with `seconds` 0: no planning time was spent).
    GAMP's answer depends on nothing else (its IK restarts are seeded per call)."""
    takes_aside = 'move_aside' in inspect.signature(plan_motion).parameters
    memo: dict = {}

    def remembered(scene: Scene, action, start, move_aside: bool = False):
        key = (*_world_key(scene, start), action, move_aside and takes_aside)
        if key in memo:
            return replace(memo[key], seconds=0.0)
        memo[key] = plan_motion(scene, action, start, **({'move_aside': move_aside} if takes_aside else {}))
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


REPAIR_ROUNDS = 3
"""Order repair's most plans after the first (`plan_for_agent`)."""


def _invalid(plan: AssemblyPlan) -> bool:
    """A plan whose episode ended on a refused action (a plan the time limit ended before its first
    step has no outcome)."""
    return plan.episode is not None and plan.episode.outcome is not None and plan.episode.outcome.is_invalid


class AgentPlanner:
    """`plan_for_agent` with in-process parts: CP-SAT (10 s, one worker), GAMP and the agent's
    sequencer. planner(scene, start, seed) -> AssemblyPlan; `motion` and `gamp` for execution.

    allocation: the first allocation's CP-SAT settings (default: 10 s, one worker, the agent's
    support); reallocation: a `ReallocationConfig` for re-allocating agents (default: the
    assembly node's, the stable allocation; its params set the re-solves' CP-SAT settings);
    policy: the agent's scorer when the caller has already loaded it; improve_time_s: anytime
    planning's least budget after the first plan (`plan_for_agent`; the assembly node's parameter
    of the same name)."""

    def __init__(self, agent: str | AgentSpec = 'default', allocation_time_limit_s: float = 10.0,
                 time_limit_s: float = 120.0, allocation=None, reallocation=None, policy=None,
                 improve_time_s: float = IMPROVE_TIME_S):
        self.spec = parse(agent) if isinstance(agent, str) else agent
        self.agent = label(self.spec)
        self.sequencer = Sequencer(SequencerConfig(agent=self.agent), policy)
        self.support = allocation.support if allocation is not None else self.spec.resolved_support(
            self.sequencer.policy)
        self.allocation, self.reallocation = allocation, reallocation
        self.allocation_time_limit_s, self.time_limit_s = allocation_time_limit_s, time_limit_s
        self.improve_time_s = improve_time_s
        self.gamp = MotionPlanner()
        self.motion = local_motion_planner(self.gamp)

    def allocate(self, scene: Scene, exclude=(), time_limit_s: float | None = None, support: str | None = None,
                 params=None):

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
                              reallocation=self.reallocation, quick_rank=self.quick_rank,
                              improve_time_s=self.improve_time_s)

    def quick_rank(self, scene: Scene, placements, start=None):
        """The agent's scorer alone (anytime planning's first plan)."""
        return self.sequencer.rank(scene, placements, start, scorer_only=True)

    def close(self) -> None:
        self.sequencer.close()
        self.gamp.close()

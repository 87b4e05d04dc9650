"""An agent's planning as stages under one deadline (what `agent_plan.plan_for_agent` runs).

After a first plan, improvement stages. A stage is a callable

    stage(planning, best, deadline) -> AssemblyPlan | None

that plans what the best plan so far leaves (each plan through `Planning.plan`, within the time left
before `deadline`) and answers the plan it would have kept: the best of its plans where one fills
more than `best`, else its last one; None where it made none. `improve` runs the stages in order,
keeps the better plan (`kept`: it fills more target cells and its episode did not end on a refused
action) and stops near the deadline (`RESERVE`) or once a plan fills every target cell.

The agent's text (`AgentSpec`) selects the stages (`stages_for`); they run in this order:

    stage        selected by                 what it plans
    design       repair                      the scene's design (`Scene.design`, written by the command
                                             that made the scene) as the allocation, in the hand's own
                                             order of it (`hand_order`), then rounds
    courses      repair, support arm|hand    a large structure's line, built course by course
                                             (`courses.course_line`); where it wins on more than
                                             `REPLAN_BLOCKS` blocks, the stages below that re-plan
                                             the first allocation are skipped
    repair       repair                      rounds of order repair after the first plan: what its
                                             refusals taught as precedences (`AssemblyPlan.conflicts`)
    hand-order   repair                      the hand's own order of the first allocation
                                             (`allocation.order.hand_order`) as precedences, then rounds
    arm          repair, support hand        the arm's allocation, then rounds
    ceiling      ceiling:S                   the line of the robot-feasible ceiling's search
                                             (`robot_ceiling`, S seconds at most)
    search       a search, anytime           the agent's own plan, its search ranking every step
    cover        repair, support arm|hand    the cover and its order at once (`ordered_cover`), then
                                             rounds; another cover where those fall short

A time rule of a stage's own (the design stage's order: `HAND_ORDER_S`; the hand-order and arm
stages: as long again as everything before took; the search: `improve_time_s`, at least as long as
the first plan took; the cover: that and at least one CP-SAT time) only caps it within the deadline,
and every solver a stage calls gets at most the time left before the deadline.
"""

from __future__ import annotations

import inspect
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from rad_core.allocation.order import Precedence, hand_order, ordered_cover, scene_state
from rad_core.allocation.placements import Placement
from rad_core.allocation.result import AllocationResult
from rad_core.domain.grid import blocks_on_grid
from rad_core.domain.scene import Scene
from rad_core.env.mdp import AssemblyEnv
from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling
from rad_core.sequencing.decide.agents import AgentSpec
from rad_core.sequencing.decide.policy import LinePolicy
from rad_core.sequencing.planning.courses import course_line
from rad_core.sequencing.planning.plan import AssemblyPlan, new_pace, plan_assembly

EPS = 1e-9

REPAIR_ROUNDS = 3
"""Order repair's most plans after the one it starts from (`repair_rounds`)."""

COVER_TRIES = 2
"""The cover stage's most covers (`ordered_cover`, each avoiding those before)."""

ORDERED_COVER_S = 5.0
"""The cover stage's most CP-SAT seconds (deterministic time) for a cover and its order (`ordered_cover`)."""

RESERVE = 0.05
"""A stage starts only while more than this share of the time limit (at most `RESERVE_MAX_S`) is
left: a solver's set-up before its own time limit counts (CP-SAT's models, about 0.1 s at g = 5),
and what a stage started late overruns by must fit in the answer's margin."""

RESERVE_MAX_S = 1.0

REPLAN_BLOCKS = 20
"""Where the course line beats the first plan of a scene of more blocks, the first allocation is not
planned again (`courses_stage`). On fewer (a dense design of 11 blocks at 3 cm, whose many block types
make it "large" by candidate poses), the line takes a second and order repair of the first allocation
finishes what the line leaves (bricks10-s1 of `benchmarks/bench_dense.py`: 0.977 -> 1.0). At 32 blocks
(g = 10 seed 7000 of `benchmarks/bench_large.py`) the re-plans took 38 s more and gained nothing."""

HAND_ORDER_S = 1.0
"""The hand-order stage's most CP-SAT seconds for the hand's order of the first allocation (`hand_order`)."""


def never_crowded(scene: Scene) -> bool:
    """`Solvers.crowded` of an effector that sets blocks down beside built ones at every unit."""
    return False


@dataclass
class Solvers:
    """The searches stages call, each (scene, seconds, ...) as its module has it; a caller may
    pass others (a test, a slow one to make a deadline bind)."""

    course_line: Callable = course_line
    hand_order: Callable = hand_order
    ordered_cover: Callable = ordered_cover
    robot_ceiling: Callable = robot_ceiling
    drop_covers: tuple[Callable, ...] = ()
    """Ordered covers counting on GAMP's drops (`GampConfig.drop`), the cover stage's last tries, in turn
    while the plans before (a hand that sets blocks down) leave cells; none: no such try."""
    crowded: Callable = never_crowded
    """crowded(scene): whether the effector sets no block down beside a built one at the scene's unit
    (the parallel hand's fingers at 2 cm, `courses.is_crowded`). There every plan takes drops
    (`Planning.plan`), and the design stage steps aside for the course line: a plan that keeps to a
    design's order from above is refused at step after step."""


@dataclass
class Planning:
    """What the stages of one agent's planning share: the scene, the agent and its parts (as
    `plan_for_agent` takes them), the one deadline, the first plan and every plan made."""

    spec: AgentSpec
    scene: Scene
    support: str
    allocate: Callable            # (scene, support=S[, time_limit_s=T]) -> AllocationResult
    plan_motion: Callable
    rank: Any                     # the agent's own ranking (with its search)
    first_rank: Any               # the first plan's (the scorer alone, for an anytime search)
    reallocate: Callable | None = None
    reallocation: Any = None
    seed: int = 0
    start: Any = None
    t0: float = field(default_factory=time.perf_counter)
    deadline: float = float('inf')
    improve_time_s: float = 0.0
    improve_until: float = 0.0    # the search stage's cap (`plan_for_agent`)
    solvers: Solvers = field(default_factory=Solvers)
    first: AssemblyPlan | None = None
    plans: list = field(default_factory=list)
    pace: dict = field(default_factory=new_pace)    # how long rankings and motions take (`plan_assembly`)
    large: bool = False           # the courses stage found a large structure
    line_won: bool = False        # ... and its line beat the first plan

    def plan(self, ranker, until: float, allocation: AllocationResult | None = None, precedences=(),
             support: str | None = None, drops: bool = False) -> AssemblyPlan:
        """A plan ranked by `ranker`, ending by `until`: of `allocation` where given, else of a new
        allocation (the agent's support, or `support`) given at most the time left before the
        deadline; keeping to `precedences` where the ranking allows; drops: taking actions GAMP can
        only drop in (`plan_assembly`), for the allocations made counting on them (the ceiling's line,
        a cover of the drops' order), and every plan where the effector is crowded (`Solvers.crowded`:
        setting down, bench_large's thin letters T and H at 2 cm stopped at 3 and 9 steps after 117 and
        86 s of refusals and re-allocations; with drops they reached 0.73 and 0.99). Recorded in `plans`."""
        if allocation is not None:
            def first(s):
                return allocation
        else:
            def first(s):
                return self._allocate(s, support or self.support)
        made = plan_assembly(self.scene, first, self.plan_motion, ranker, seed=self.seed, start=self.start,
                             time_limit_s=until - time.perf_counter(),
                             reallocate=self.reallocate if self.spec.realloc else None,
                             reallocation=self.reallocation, verify=self.spec.verify, precedences=precedences,
                             pace=self.pace, drops=drops or self.solvers.crowded(self.scene))
        self.plans.append(made)
        return made

    def _allocate(self, scene: Scene, support: str) -> AllocationResult:
        if 'time_limit_s' not in inspect.signature(self.allocate).parameters:
            return self.allocate(scene, support=support)
        return self.allocate(scene, support=support, time_limit_s=max(1e-3, self.deadline - time.perf_counter()))

    def as_long_again(self, deadline: float) -> float:
        """Now plus as long as everything so far took, within `deadline`."""
        now = time.perf_counter()
        return min(deadline, now + (now - self.t0))


Stage = Callable[[Planning, AssemblyPlan, float], 'AssemblyPlan | None']


def invalid(plan: AssemblyPlan) -> bool:
    """A plan whose episode ended on a refused action (a plan the time limit ended before its first
    step has no outcome)."""
    return plan.episode is not None and plan.episode.outcome is not None and plan.episode.outcome.is_invalid


def kept(plan: AssemblyPlan, best: AssemblyPlan) -> bool:
    """Whether `plan` replaces `best`: it fills more, and it is valid."""
    return plan.predicted_coverage > best.predicted_coverage + EPS and not invalid(plan)


def full(plan: AssemblyPlan) -> bool:
    return plan.predicted_coverage >= 1.0 - EPS


def improve(planning: Planning, stages, best: AssemblyPlan, made_by: str, deadline: float,
            anytime: list) -> tuple[AssemblyPlan, str]:
    """Run `stages` ((name, stage) pairs) in order from `best` (made by `made_by`) until the
    deadline is near (`RESERVE`) or a plan fills the target: (the best plan, the name of the stage
    that made it). After each stage that planned, `anytime` gets {'t', 'coverage', 'plan'} of the
    best so far."""
    reserve = min(RESERVE * (deadline - planning.t0), RESERVE_MAX_S)
    for name, stage in stages:
        if full(best) or time.perf_counter() >= deadline - reserve:
            break
        plan = stage(planning, best, deadline)
        if plan is None:
            continue
        if kept(plan, best):
            best, made_by = plan, name
        anytime.append({'t': time.perf_counter() - planning.t0, 'coverage': best.predicted_coverage,
                        'plan': made_by})
    return best, made_by


def stages_for(spec: AgentSpec, support: str, anytime_search: bool, improve_time_s: float) -> list[tuple[str, Stage]]:
    """The agent's stages in the order they run (module docstring). anytime_search: the first plan
    was the scorer's alone, and the search stage plans with the agent's search. improve_time_s 0:
    no improving but the ceiling's."""
    repair = spec.repair and spec.verify and improve_time_s > 0
    arm_aware = support in ('arm', 'hand')
    selected = {'design': repair, 'courses': repair and arm_aware, 'repair': repair, 'hand-order': repair,
                'arm': repair and support == 'hand', 'ceiling': bool(spec.ceiling and spec.verify),
                'search': anytime_search and improve_time_s > 0, 'cover': repair and arm_aware}
    return [(name, stage) for name, stage in STAGES.items() if selected[name]]


# ---- the stages -------------------------------------------------------------------------------

def design_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """The scene's design as the allocation (`design_allocation`), keeping to the hand's own order of
    it (`hand_order`, at most `HAND_ORDER_S`), and rounds after it, where that order places more than
    the best plan. A design is a cover some order model, or the design's author, knew how to build:
    supply's ordered cover of a flush design (blocks only a suction cup lays whole, all from above)
    is one the planner's own ordered cover, bound to the scene's exact blocks, does not find again.
    Not where the effector is crowded (`Solvers.crowded`): the car of bench_large's designs at 2 cm
    planned 0.075 of its cells in 330 s this way, where the course line reaches 0.30."""
    if planning.solvers.crowded(planning.scene):
        return None
    allocation = design_allocation(planning.scene)
    if allocation is None or deadline <= time.perf_counter():
        return None
    seconds = max(1e-3, min(HAND_ORDER_S, deadline - time.perf_counter()))
    guess = planning.solvers.hand_order(planning.scene, allocation.placements, seconds)
    if guess.coverage <= best.predicted_coverage + EPS:
        return None
    return _answer(best, *chain(planning, allocation, guess.precedences, best, deadline))


def courses_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """A large structure's line (more candidate poses than one ordered cover takes), built course by
    course in the planning twin, planned as the allocation with its order (ranked by `LinePolicy`)
    where it fills more than the best plan. Where that plan wins, the first allocation is beaten: at
    this size each re-plan of it takes as long as the line did; on a scene of at most `REPLAN_BLOCKS`
    blocks it is planned again all the same."""
    line = planning.solvers.course_line(planning.scene, deadline - time.perf_counter())
    planning.large = line is not None
    if not (planning.large and line.actions and line.coverage > best.predicted_coverage + EPS
            and deadline > time.perf_counter()):
        return None
    allocation, order, poses = line_allocation(planning.scene, line.actions, 'courses', 'the course line',
                                               line.seconds)
    made = planning.plan(LinePolicy(poses), deadline, allocation, order, drops=line.drops)
    planning.line_won = kept(made, best) and len(planning.scene.blocks) > REPLAN_BLOCKS
    return made


def repair_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """Rounds of order repair after the first plan, of its allocation."""
    if planning.line_won:
        return None
    first = planning.first
    return _answer(best, *repair_rounds(planning, first, {}, best, None, deadline, first.allocation))


def hand_order_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """The hand's own order of the first allocation as the known precedences, and rounds after it,
    where that order places more than the best plan; for at most as long again as everything before."""
    allocation = planning.first.allocation
    until = planning.as_long_again(deadline)
    if planning.line_won or allocation is None or until <= time.perf_counter():
        return None
    seconds = max(1e-3, min(HAND_ORDER_S, deadline - time.perf_counter()))
    guess = planning.solvers.hand_order(planning.scene, allocation.placements, seconds)
    if not guess.precedences or guess.coverage <= best.predicted_coverage + EPS:
        return None
    return _answer(best, *chain(planning, allocation, guess.precedences, best, until))


def arm_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """A plan of the arm's allocation, which the hand's order may have traded away (a pair of blocks
    the order cannot place both of, where a re-allocation on the way finds a way round), and rounds
    after it; for at most as long again as everything before."""
    until = planning.as_long_again(deadline)
    if planning.line_won or until <= time.perf_counter():
        return None
    latest = planning.plan(planning.first_rank, until, support='arm')
    running = latest if kept(latest, best) else best
    if latest.allocation is not None:
        running, latest = repair_rounds(planning, latest, {}, running, latest, until, latest.allocation)
    return _answer(best, running, latest)


def ceiling_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """The robot-feasible ceiling's search from the best plan's coverage, for up to the agent's
    ceiling seconds, and a plan of the line it finds (its poses as the allocation, its order as
    precedences)."""
    seconds = min(planning.spec.ceiling, deadline - time.perf_counter())
    line = ceiling_line(planning, best.predicted_coverage, seconds) if seconds > 0 else None
    if line is None or deadline <= time.perf_counter():
        return None
    allocation, order = line
    return planning.plan(planning.first_rank, deadline, allocation, order, drops=True)


def search_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """The agent's own plan, its search ranking every step, within the improvement budget."""
    until = min(deadline, planning.improve_until)
    if until <= time.perf_counter():
        return None
    return planning.plan(planning.rank, until)


def cover_stage(planning: Planning, best: AssemblyPlan, deadline: float) -> AssemblyPlan | None:
    """The cover and its order at once (`ordered_cover`, the robot ceiling's ordered bound as a plan)
    where it places more than the best plan, as the allocation with its order's precedences, and
    rounds after it; where those fall short, another cover (at most `COVER_TRIES`). For at most as
    long again as everything before, and at least one CP-SAT time and the improvement budget. Not on
    a large structure (its cover takes longer than its line)."""
    if planning.large:
        return None
    now = time.perf_counter()
    until = min(deadline, now + max(now - planning.t0, ORDERED_COVER_S + planning.improve_time_s))
    running, latest, avoid = best, None, []
    for _ in range(COVER_TRIES):
        now = time.perf_counter()
        if full(running) or now >= until:
            break
        # CP-SAT's deterministic seconds; its wall-clock backstop (three times those) within the deadline.
        cover = planning.solvers.ordered_cover(planning.scene, min(ORDERED_COVER_S, until - now, (deadline - now) / 3),
                                               avoid=avoid)
        if cover.coverage <= running.predicted_coverage + EPS or time.perf_counter() >= until:
            break
        avoid.append(cover.order)
        allocation = cover_allocation(cover, time.perf_counter() - now)
        running, latest = chain(planning, allocation, cover.precedences, running, until, cover.drops)
    for drop_cover in planning.solvers.drop_covers:
        # The drops' cover: the last cell of a flush course, the last block of a solid box.
        now = time.perf_counter()
        if full(running) or now >= deadline:
            break
        cover = drop_cover(planning.scene, min(ORDERED_COVER_S, (deadline - now) / 3))
        if cover.coverage > running.predicted_coverage + EPS and time.perf_counter() < deadline:
            allocation = cover_allocation(cover, time.perf_counter() - now)
            running, latest = chain(planning, allocation, cover.precedences, running,
                                    max(until, min(deadline, time.perf_counter() + planning.improve_time_s)), True)
    return _answer(best, running, latest)


STAGES: dict[str, Stage] = {'design': design_stage, 'courses': courses_stage, 'repair': repair_stage,
                            'hand-order': hand_order_stage, 'arm': arm_stage, 'ceiling': ceiling_stage,
                            'search': search_stage, 'cover': cover_stage}
"""Every stage by name, in the order they run."""


# ---- order repair's rounds and chains -----------------------------------------------------------

def repair_rounds(planning: Planning, latest: AssemblyPlan, known: dict, best: AssemblyPlan, last,
                  until: float, allocation, drops: bool = False) -> tuple[AssemblyPlan, AssemblyPlan | None]:
    """At most `REPAIR_ROUNDS` plans of `allocation` after `latest`, each keeping to `known` and what
    the refusals of the plan before taught (`AssemblyPlan.conflicts`), while the best plan leaves
    cells, time is left and the refusals teach something new: (the best plan, the last made, `last`
    where none)."""
    for _ in range(REPAIR_ROUNDS):
        new = [p for p in latest.conflicts if p not in known]
        if full(best) or until <= time.perf_counter() or not new or best.allocation is None:
            break
        known.update(dict.fromkeys(new))
        latest = last = planning.plan(planning.first_rank, until, allocation, tuple(known), drops=drops)
        best = latest if kept(latest, best) else best
    return best, last


def chain(planning: Planning, allocation, precedences, best: AssemblyPlan,
          until: float, drops: bool = False) -> tuple[AssemblyPlan, AssemblyPlan]:
    """A plan of `allocation` keeping to known `precedences`, then repair rounds after it (drops: as
    `Planning.plan`)."""
    known = dict.fromkeys(precedences)
    latest = planning.plan(planning.first_rank, until, allocation, tuple(known), drops=drops)
    return repair_rounds(planning, latest, known, latest if kept(latest, best) else best, latest, until, allocation,
                         drops)


def _answer(best: AssemblyPlan, running: AssemblyPlan, last: AssemblyPlan | None) -> AssemblyPlan | None:
    """What a stage that started from `best` answers: the better plan it found, else its last."""
    return running if running is not best else last


# ---- lines as allocations -------------------------------------------------------------------------

def cover_allocation(cover, seconds: float) -> AllocationResult:
    """An `AllocationResult` of an `ordered_cover`'s poses (FEASIBLE, its c^T g), solved in `seconds`."""
    return AllocationResult('FEASIBLE', float(cover.value), float(cover.value), seconds, tuple(cover.placements),
                            solver='ordered cover')


def design_allocation(scene: Scene) -> AllocationResult | None:
    """The scene's design (`Scene.design`) as an `AllocationResult` (FEASIBLE, its c^T g; solver
    'design'): its poses in its order, but those on a cell filled already and those beyond the blocks
    of their type not in a target yet; None where no pose is left."""
    if not scene.design:
        return None
    grid, occupied = scene_state(scene)
    on_grid = blocks_on_grid(scene, grid)
    left = {name: 0 for name in scene.block_types}
    for n, block in enumerate(scene.blocks):
        left[block.type] += n not in on_grid
    regions = [t.name for t in scene.targets]
    placements, value = [], 0
    for pose in scene.design:
        ids = [grid.index(regions.index(pose.target), c) for c in pose.cells]
        if left[pose.type] == 0 or None in ids or occupied[ids].any():
            continue
        left[pose.type] -= 1
        occupied[ids] = True
        placements.append(pose)
        value += int(grid.weights[ids].sum())
    if not placements:
        return None
    return AllocationResult('FEASIBLE', float(value), float(value), 0.0, tuple(placements), solver='design')


def ceiling_line(planning: Planning, incumbent: float, seconds: float):
    """The line of the robot-feasible ceiling's search (`robot_ceiling`, at most `seconds`) from the
    scene's state, where it beats `incumbent`: (an `AllocationResult` of its poses, the `Precedence`s
    that put them in its order); None where it found nothing better."""
    t0 = time.perf_counter()
    found = planning.solvers.robot_ceiling(planning.scene, seconds, incumbent=incumbent)
    if not found.actions or found.coverage <= incumbent + EPS:
        return None
    return line_allocation(planning.scene, found.actions, 'ceiling', 'the ceiling\'s line',
                           time.perf_counter() - t0)[:2]


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
    # Each pose after the one before it: as soft as every pair (a pose after an open one waits, and so do
    # those after it), in as many precedences as poses, not their square (20,000 for a 200-block line).
    order = tuple(Precedence(a, b, why) for a, b in zip(poses, poses[1:]))
    value = float(sum(int(env.grid.weights[list(c)].sum()) for c in poses))
    return AllocationResult('FEASIBLE', value, value, seconds, tuple(placements), solver=solver), order, poses

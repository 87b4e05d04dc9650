"""A line built course by course, for structures too large for one ordered cover.

The 'cover' stage (`sequencing.agent.stages`) asks CP-SAT for the allocation and its hand order
at once over every candidate pose (`allocation.order.ordered_cover`). On a 72-block wall that
is 590 poses and CP-SAT finds no cover in its 5 s; its plans' refusals then cost a re-allocation
each. A mason builds such a
wall a course at a time, and so does `course_line`:

1. the poses whose lowest cells lie in the next two courses (`COURSE_WINDOW`), with what is built
   below as built, get an ordered cover (`allocation.order.order_model` with the cover's rules: the
   allocation's 'stable' support, a way of being held that no pose before it is in the way of,
   the most target cells, then the fewest fillers); so does the next course alone, which CP-SAT
   proves at once, and the two-course cover is taken where it places at least as many cells (in
   its time CP-SAT may stop at a poor first answer: one pose of a 100-block wall's 208);
2. the cover's poses of the lower course are stepped in its order in the planning twin
   (`RobotAssemblyEnv`, teleporting: GAMP's plan, then physics), each with the first of at most
   `COURSE_ACTIONS` actions (blocks of its type, rotations) that places it;
3. a pose the twin refuses (GAMP: out of reach, the hand hits a neighbour; physics: it did not
   stay) is left out of the course's later covers, and the course is covered again from what is
   built (at most `COURSE_TRIES` covers a course);
4. then the next course.

Looking one course ahead keeps a course from leaving a hole under a block the next one needs.
The line is the twin's successful steps; the agent plans it as an allocation with its order
(`agent.stages.line_allocation`), so GAMP checks every step again from the robot's own start.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from rad_core.allocation.bounds import blocks_left
from rad_core.allocation.constraints import cp_solver
from rad_core.allocation.guide import AllocationGuide
from rad_core.allocation.order import candidate_poses, cover_candidates, order_model, scene_state, solve_order
from rad_core.domain.scene import Scene
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
from rad_core.gamp.grasps import beside_blocks

COURSES_ABOVE = 200
"""`course_line` plans where a scene has more candidate poses than this (`allocation.order.candidate_poses`):
generated g = 5 scenes (seeds 0..39) have 17-163, g = 6 (seeds 0..19) 17-274 (two above 200), the
hand-made held-out shapes 18-130, g = 8 230-310, g = 10 310-430, the 45- to 100-block walls and
tower 280-1190."""

COURSE_WINDOW = 2
"""Courses covered together; only the lowest is stepped before the next cover."""

COURSE_S = 0.6
"""CP-SAT's deterministic seconds per course of a cover (wall time at most three times that)."""

COURSE_TRIES = 8
"""Covers of one course at most (each after the twin refused a pose of the one before)."""

COURSE_ACTIONS = 4
"""Actions (blocks of the type, rotations of a symmetric one) tried for a pose before it is refused."""


@dataclass
class CourseLine:
    """What `course_line` built: the twin's successful actions in order, the coverage they reach,
    the poses it refused ('type cells: reason') and how many covers it solved."""

    actions: list = field(default_factory=list)
    coverage: float = 0.0
    refused: list[str] = field(default_factory=list)
    covers: int = 0
    seconds: float = 0.0
    drops: bool = False
    """Whether the line counts on the hand dropping blocks (`GampConfig.drop`): its plan must take drops."""


def course_line(scene: Scene, time_limit_s: float, least_poses: int | None = None, gamp=None,
                crowded=None) -> CourseLine | None:
    """The line built course by course in the planning twin (module docstring) within
    `time_limit_s` (the line so far where it ends first); None where the scene has at most
    `least_poses` candidate poses (default `COURSES_ABOVE`: one ordered cover takes those; 0 where the
    fingers crowd and `crowded` is given: there the line, counting on drops, is how the hand fills a
    course of any size, where plans that set blocks down stop at one block of each pair: a 2 x 2
    tower of 16 O4_up at 2 cm planned 8), and
    where a queue feeder dictates the blocks' order (the line chooses its blocks). gamp: GAMP's
    settings (`GampConfig`; default the defaults), its effector's among them. crowded: GAMP's settings
    instead where the fingers crowd a unit's neighbours (`crowded`: at a 2 cm unit the hand can set a
    block down beside no built one), e.g. the hand that drops (`GampConfig.drop`).

    Where the fingers crowd, the cover's hand model is the planner's own (`HandBlocked` near: the cells
    within its collision margin), so that the twin refuses few of the poses the covers order. At larger
    units the bound's model (the cells the hand enters) ordered better: g = 8 seed 7001 of
    `benchmarks/bench_large.py` built 0.97 with the planner's, 1.0 with it."""
    if scene.feeder is not None and scene.feeder.order == 'queue':
        return None
    t0 = time.perf_counter()
    deadline = t0 + time_limit_s
    near = is_crowded(scene)
    if crowded is not None and near:
        gamp = crowded
    config = RobotEnvConfig(execution='teleport', **({'gamp': gamp} if gamp is not None else {}))
    grid, occupied = scene_state(scene)
    candidates, counts, hand, unpickable = cover_candidates(scene, grid, config.gamp, near=near)
    least = (0 if near and crowded is not None else COURSES_ABOVE) if least_poses is None else least_poses
    if len(candidate_poses(grid, hand, occupied, candidates, counts)[0]) <= least:
        return None
    with RobotAssemblyEnv(scene, config) as renv:
        renv.reset()
        env = renv.env
        height = heights(grid)
        courses: dict[float, list] = {}
        for c in candidates:
            courses.setdefault(float(height[list(c.cell_ids)].min()), []).append(c)
        zs = sorted(courses)
        g = config.gamp
        line = CourseLine(drops=g.drop and g.effector == 'hand' and scene.studs is None)
        guide_of = lambda placement: AllocationGuide(scene, [placement], grid)    # noqa: E731
        refused: set[tuple] = set()
        for i, z in enumerate(zs):
            for _ in range(COURSE_TRIES):
                if time.perf_counter() >= deadline:
                    break
                occupied = env.state.occupancy >= 0
                counts = blocks_left(scene, env, unpickable)
                cover = None
                for window in dict.fromkeys((1, COURSE_WINDOW)):
                    kept = [c for zz in zs[i:i + window] for c in courses[zz]
                            if (c.placement.type, tuple(sorted(c.cell_ids))) not in refused]
                    poses, items = candidate_poses(grid, hand, occupied, kept, counts)
                    seconds = min(COURSE_S * window, max(1e-3, (deadline - time.perf_counter()) / 3))
                    found = solve_order(grid, occupied, poses, items, counts, seconds, cover=True)
                    line.covers += 1
                    if cover is None or found.coverage >= cover.coverage:
                        cover = found
                here = [(cells, p) for cells, p in zip(cover.order, cover.placements)
                        if float(height[list(cells)].min()) == z]
                if not here or _step_all(renv, guide_of, here, refused, line, deadline):
                    break           # the course is done (or its cover has nothing for it): the next
        line.coverage = env.coverage()
        line.seconds = time.perf_counter() - t0
        return line


def is_crowded(scene: Scene) -> bool:
    """Whether the parallel hand's fingers crowd a unit's neighbours: at the scene's unit and clearance
    its fingertips, closed on a unit, come within the planner's margin of the blocks beside it
    (`grasps.beside_blocks`: units under about 21.5 mm), so it can set a block down beside no built one."""
    return beside_blocks(0, scene.unit, scene.clearance)


def heights(grid) -> np.ndarray:
    """Each cell's course: the height of its centre (m, rounded to a micrometre so that a course's
    cells compare equal)."""
    return np.round(grid.centres[:, 2], 6)


def _step_all(renv, guide_of, poses, refused: set, line: CourseLine, deadline: float) -> bool:
    """Step the poses ((cells, placement)) in order in the twin, each with the first action that
    places it (guide_of(placement): an `AllocationGuide` of the one pose). False at the
    first pose the twin refuses (recorded in `refused` and `line.refused`) or when time is up."""
    env = renv.env
    for cells, placement in poses:
        if time.perf_counter() >= deadline:
            return False
        snapshot, reason = renv.snapshot(), 'no block left to fill it'
        for action in guide_of(placement).pose_actions(0, env.state)[:COURSE_ACTIONS]:
            result = renv.step(action)
            if result.outcome is None or not result.outcome.is_invalid:
                line.actions.append(action)
                break
            reason = result.reason
            renv.restore(snapshot)
        else:
            refused.add((placement.type, tuple(cells)))
            line.refused.append(f'{placement.type} {list(cells)}: {reason}')
            return False
    return True


def course_bound(scene: Scene, time_limit_s: float = 10.0) -> float:
    """An upper bound on the coverage any top-down build of the scene reaches, course by course,
    for structures too large for the robot ceiling's ordered bound (`ArmCoverageBound`, not
    proven on a 72-block wall in 120 s): the sum over the courses of the most target cells of the
    course that poses touching it can fill in an order the hand can keep (`allocation.order.order_model`
    over those poses alone, a pose's cells of the course counted, with no rest rule), over the
    target cells. A build restricted to the poses touching a course is such an order, so each
    course's maximum bounds what any build fills of it. CP-SAT's proven bound per course within
    an equal share of `time_limit_s`. On the flush walls it says what `large_shapes.FLUSH_LIMIT`
    says (each full course loses a cell) and no more."""

    grid, occupied = scene_state(scene)
    candidates, counts, hand, _ = cover_candidates(scene, grid)
    poses, _ = candidate_poses(grid, hand, occupied, candidates, counts)
    total = int(grid.is_target.sum())
    height = heights(grid)
    free = grid.is_target & ~occupied
    filled = int((grid.is_target & occupied).sum())
    zs = sorted(set(height[free].tolist()))
    for z in zs:
        here = [(cells, ways, int((free[list(cells)] & (height[list(cells)] == z)).sum()), name)
                for cells, ways, _, name in poses if (height[list(cells)] == z).any()]
        if not here:
            continue
        model, *_ = order_model(grid, occupied, here, counts, rest=False)
        solver = cp_solver(time_limit_s / len(zs))
        solver.solve(model)
        filled += min(int(free[height == z].sum()), math.floor(float(solver.best_objective_bound) + 1e-9))
    return filled / total if total else 1.0

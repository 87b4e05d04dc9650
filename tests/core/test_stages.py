"""An agent's planning as stages under one deadline (`sequencing.agent.stages`, `plan_for_agent`)."""

from __future__ import annotations

import time
from dataclasses import replace

import pytest
from rad_core.allocation import solve
from rad_core.allocation.result import AllocationResult
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import Outcome
from rad_core.sequencing import HeurPolicy
from rad_core.sequencing.agent.agent_plan import AgentPlanner
from rad_core.domain.scene import Scene
from rad_core.sequencing.agent.stages import (STAGES, Planning, Solvers, design_allocation, design_stage, improve,
                                              stages_for)
from rad_core.sequencing.decide.agents import parse
from rad_core.sequencing.decide.episode import Episode
from rad_core.sequencing.planning.plan import AssemblyPlan, MotionPlan, plan_assembly

from scenes import U, doc, scene


def made(coverage: float, refused: bool = False) -> AssemblyPlan:
    episode = Episode(outcome=Outcome.INVALID_PLACEMENT if refused else None)
    return AssemblyPlan(False, '', None, predicted_coverage=coverage, episode=episode)


def planning(t0: float) -> Planning:
    return Planning(parse('default'), None, 'hand', None, None, None, None, t0=t0)


def test_the_loop_keeps_the_better_valid_plan_and_stops_at_the_deadline():
    ran = []

    def returns(name, plan, sleep_until_deadline=False):
        def stage(_planning, best, deadline):
            ran.append((name, best.predicted_coverage))
            if sleep_until_deadline:    # a slow stage: it takes all the time it is given
                time.sleep(max(0.0, deadline - time.perf_counter()))
            return plan
        return name, stage
    t0 = time.perf_counter()
    deadline = t0 + 0.3
    stages = [returns('a', made(0.5)), returns('b', made(0.4)), returns('c', None),
              returns('d', made(0.9, refused=True)), returns('slow', made(0.6), sleep_until_deadline=True),
              returns('late', made(1.0))]
    anytime: list = []
    best, by = improve(planning(t0), stages, made(0.2), 'scorer', deadline, anytime)
    # Fills more and is valid: a's 0.5 beat the first plan, b's 0.4 and d's refused 0.9 did not; the
    # slow stage's 0.6 came back at the deadline and was kept; the stage after it never ran.
    assert (best.predicted_coverage, by) == (0.6, 'slow')
    assert ran == [('a', 0.2), ('b', 0.5), ('c', 0.5), ('d', 0.5), ('slow', 0.5)]
    assert [(a['plan'], a['coverage']) for a in anytime] == [('a', 0.5), ('a', 0.5), ('a', 0.5), ('slow', 0.6)]
    assert time.perf_counter() - t0 < 0.3 + 0.1
    # A plan that fills the target ends the loop.
    ran.clear()
    best, by = improve(planning(time.perf_counter()), [returns('a', made(1.0)), returns('b', made(0.5))],
                       made(0.2), 'scorer', time.perf_counter() + 10, [])
    assert by == 'a' and ran == [('a', 0.2)]


def test_the_agent_text_selects_the_stages_and_their_order_is_fixed():
    def names(text, support=None, anytime=False, improve_s=2.0):
        spec = parse(text)
        return [n for n, _ in stages_for(spec, support or spec.support, anytime, improve_s)]
    order = list(STAGES)
    assert order == ['design', 'courses', 'repair', 'hand-order', 'arm', 'ceiling', 'search', 'cover']
    assert names('default') == ['design', 'courses', 'repair', 'hand-order', 'arm', 'cover']
    assert names('milp-dqn-mixed+verify+realloc+repair+support:arm') == ['design', 'courses', 'repair', 'hand-order',
                                                                        'cover']
    assert names('heur+verify+repair', 'none') == ['design', 'repair', 'hand-order']
    assert names('default+ceiling:30') == ['design', 'courses', 'repair', 'hand-order', 'arm', 'ceiling', 'cover']
    assert names('greedy') == [] and names('paper') == []
    assert names('milp-dqn-mixed+lookahead:5+verify+support:arm', anytime=True) == ['search']
    assert names('milp-dqn-mixed+lookahead:5+verify+support:arm', anytime=False) == []
    # improve_time_s 0: no improving but the ceiling's search.
    assert names('default+ceiling:30', improve_s=0.0) == ['ceiling']


def test_plan_assembly_stops_at_its_deadline_with_the_plan_so_far(motion):
    scene = generate_scene(GeneratorConfig(grid=3), 2)
    asked, started = [], []

    def slow(scene_now, action, start, move_aside=False):
        """A motion planner that takes 0.2 s per answer and refuses the first block's first pose."""
        asked.append(action)
        started.append(time.perf_counter())
        time.sleep(0.2)
        if len(asked) == 1:
            return MotionPlan(False, 'placement', 'refused on purpose')
        return motion(scene_now, action, start, move_aside=move_aside)
    allocation = solve(scene)
    plan = plan_assembly(scene, lambda s: allocation, slow, HeurPolicy(), seed=1, time_limit_s=10.0)
    assert plan.success and len(plan.steps) == 2 and len(asked) == 3
    # With 0.5 s: the refusal and the first step take 0.4 s; a third motion, as long as those took,
    # would end past the deadline, and is not asked for (within the step, before its first motion).
    asked.clear()
    started.clear()
    t0 = time.perf_counter()
    plan = plan_assembly(scene, lambda s: allocation, slow, HeurPolicy(), seed=1, time_limit_s=0.5)
    assert plan.episode.timed_out and plan.reason == 'time limit of 0.5 s reached after 1 steps'
    assert len(asked) == 2 and len(plan.steps) == 1 and not plan.success and plan.predicted_coverage > 0
    # Every motion it asked for began before the deadline. How long the real motion planning and the
    # step around it take depends on the machine's load, so the test counts motions, not seconds.
    assert all(t - t0 < 0.5 for t in started), [t - t0 for t in started]


def test_an_empty_allocation_cut_by_the_time_limit_says_the_limit_ended_it(motion):
    """CP-SAT stopped early answers FEASIBLE with its first solution, which may place nothing."""
    scene = generate_scene(GeneratorConfig(grid=3), 2)

    def cut(_scene):
        time.sleep(0.02)
        return AllocationResult('FEASIBLE', 0.0, 4.0, 0.02)
    plan = plan_assembly(scene, cut, motion, HeurPolicy(), time_limit_s=0.01)
    assert not plan.success and plan.reason.startswith('time limit of 0.01 s reached'), plan.reason
    plan = plan_assembly(scene, cut, motion, HeurPolicy(), time_limit_s=10.0)
    assert plan.reason == 'the allocation places no block', plan.reason


@pytest.fixture(scope='module')
def default_planner():
    planner = AgentPlanner('default', time_limit_s=2.0)
    yield planner
    planner.close()


def test_plan_for_agent_answers_within_its_time_limit_with_the_best_plan_and_its_stage(default_planner):
    # g = 5 seed 0: the default agent's first plan leaves cells, so its stages run. A course line
    # search that takes all the time it is given makes the deadline bind whatever the machine's speed.
    scene = generate_scene(GeneratorConfig(grid=5, sides=2), 0)
    seen = []

    def slow_courses(scene_now, seconds, least_poses=None):
        seen.append(seconds)
        time.sleep(max(0.0, seconds))
        return None
    planner = default_planner
    from rad_core.sequencing.agent.agent_plan import plan_for_agent
    t0 = time.perf_counter()
    plan = plan_for_agent(planner.spec, scene, planner.allocate, planner.motion, planner.sequencer.rank,
                          planner.reallocate, support=planner.support, time_limit_s=2.0,
                          reallocation=planner.reallocation, quick_rank=planner.quick_rank,
                          solvers=Solvers(course_line=slow_courses))
    seconds = time.perf_counter() - t0
    assert seconds < 2.2, seconds
    assert plan.steps and plan.anytime and plan.anytime[-1]['plan'] in ('scorer', *STAGES)
    assert plan.anytime[-1]['coverage'] == plan.predicted_coverage
    assert all(0 < s < 2.0 for s in seen)     # the courses stage had what was left of the 2 s
    if plan.anytime[0]['coverage'] < 1.0 and plan.anytime[0]['t'] < 1.9:    # (the first plan may take them all)
        assert seen
    # The in-process planner as evaluation and the node run it: the same deadline holds.
    t0 = time.perf_counter()
    plan = planner(scene)
    assert time.perf_counter() - t0 < 2.2 and plan.steps and plan.anytime[-1]['plan'] in ('scorer', *STAGES)


def test_with_an_anytime_deadline_the_first_plan_completes_and_no_stage_starts_after_it(default_planner):
    # What /plan_assembly does when a request asks for no time limit: the first plan keeps the long
    # limit (a slow machine still gets a complete plan), the stages stop at the short deadline.
    scene = generate_scene(GeneratorConfig(grid=5, sides=2), 0)
    seen = []

    def courses(scene_now, seconds, least_poses=None):
        seen.append(seconds)
        return None
    planner = default_planner
    from rad_core.sequencing.agent.agent_plan import plan_for_agent
    plan = plan_for_agent(planner.spec, scene, planner.allocate, planner.motion, planner.sequencer.rank,
                          planner.reallocate, support=planner.support, time_limit_s=60.0,
                          reallocation=planner.reallocation, quick_rank=planner.quick_rank,
                          improve_until_s=1e-3, solvers=Solvers(course_line=courses))
    assert plan.steps and not plan.episode.timed_out and "time limit" not in plan.reason
    assert [a['plan'] for a in plan.anytime] == ['scorer'] and not seen


def designed(*poses, blocks=None) -> Scene:
    """The default test scene (a row of three and one on its end; two cubes and an I2) with a design of
    (type, cells) poses at yaw 0."""
    d = doc(blocks=blocks)
    d['design'] = [{'type': t, 'target': 'front', 'yaw': 0, 'cells': [list(c) for c in cells]} for t, cells in poses]
    return Scene.from_dict(d)


def test_the_design_as_an_allocation_keeps_the_poses_the_blocks_left_can_fill():
    cube, bar = ('cube', [(0, 0, 1)]), ('I2', [(1, 0, 0), (2, 0, 0)])
    found = design_allocation(designed(cube, bar, ('cube', [(0, 0, 0)]), ('cube', [(1, 0, 1)])))
    # The scene has two cubes: the third cube pose is left out; its order is the design's.
    assert found.solver == 'design' and found.objective == 4.0
    assert [(p.type, p.cells) for p in found.placements] == [('cube', ((0, 0, 1),)), ('I2', ((1, 0, 0), (2, 0, 0))),
                                                             ('cube', ((0, 0, 0),))]
    # A cube already on the row's last cell: the bar's pose over it is left out, and so is one cube.
    blocks = doc()['blocks']
    blocks[1] = {**blocks[1], 'position': [0.45 + 2 * U, 0.1, U / 2]}
    found = design_allocation(designed(cube, bar, ('cube', [(0, 0, 0)]), blocks=blocks))
    assert [(p.type, p.cells) for p in found.placements] == [('cube', ((0, 0, 1),))]
    assert design_allocation(scene()) is None


def test_the_design_stage_plans_the_design_in_the_hands_order(default_planner):
    # Listed top first: the stage's order puts the cube on its end after the one under it.
    s = designed(('cube', [(0, 0, 1)]), ('cube', [(0, 0, 0)]), ('I2', [(1, 0, 0), (2, 0, 0)]))
    p = default_planner
    planning = Planning(p.spec, s, p.support, p.allocate, p.motion, p.sequencer.rank, p.sequencer.rank,
                        solvers=p.solvers)
    plan = design_stage(planning, made(0.0), time.perf_counter() + 30)
    assert plan.allocation.solver == 'design' and plan.predicted_coverage == 1.0 and len(plan.steps) == 3
    assert design_stage(replace(planning, scene=scene()), made(0.0), time.perf_counter() + 30) is None
    assert design_stage(planning, made(1.0), time.perf_counter() + 30) is None     # nothing to gain
    # Where the hand's fingers crowd the unit (2 cm), the design stage leaves the structure to the course line.
    assert not p.solvers.crowded(s) and p.solvers.crowded(replace(s, unit=0.02))
    crowded = replace(planning, solvers=replace(p.solvers, crowded=lambda scene: True))
    assert design_stage(crowded, made(0.0), time.perf_counter() + 30) is None

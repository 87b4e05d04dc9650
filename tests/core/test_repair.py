"""Order repair (agents' `repair` part): a plan that stalls because the arm hits a block the plan
placed earlier is planned again with that block's cells after the cells it kept the arm from."""

from __future__ import annotations

import time

import numpy as np
import pytest
from rad_core.allocation import solve
from rad_core.allocation.order import Precedence
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import Action, AssemblyEnv, EnvConfig
from rad_core.sequencing import HeurPolicy
from rad_core.allocation.result import AllocationResult
from rad_core.sequencing.agent.agent_plan import (plan_for_agent, remembered_motion, remembered_rank,
                                                remembered_reallocation)
from rad_core.sequencing.decide.actions import AllocationActions
from rad_core.sequencing.decide.agents import label, parse
from rad_core.sequencing.planning.plan import MotionPlan, conflicts_of, plan_assembly, precedences_last


def test_repair_is_an_agent_part_that_needs_verification():
    spec = parse('milp-dqn-mixed+verify+realloc+repair+support:arm')
    assert spec.repair and label(spec) == 'milp-dqn-mixed+verify+realloc+repair+support:arm'
    assert parse(label(spec)) == spec
    assert parse('greedy+repair').repair and not parse('greedy').repair
    with pytest.raises(RadError, match='add \\+verify'):
        parse('heur+repair')


def _cells(env, step) -> tuple[int, ...]:
    region = [t.name for t in env.scene.targets].index(step.target)
    return tuple(sorted(int(env.grid.index(region, c)) for c in step.cells))


def _action(env, step) -> Action:
    """The MDP action of a plan step."""
    region = [t.name for t in env.scene.targets].index(step.target)
    return Action([b.id for b in env.scene.blocks].index(step.block), step.unit,
                  env.grid.index(region, step.cell), step.rotation)


def test_a_refusal_that_names_a_placed_block_teaches_a_precedence_and_a_table_block_does_not(motion):
    scene = generate_scene(GeneratorConfig(grid=3), 2)
    plan = plan_assembly(scene, solve, motion, HeurPolicy(), seed=1)
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    first, second = plan.steps[0], plan.steps[1]       # b0 on the left, then b2 on the right
    action = _action(env, first)
    env.step(action)
    placed = env.state.placed[action.block][0]
    later = _action(env, second)
    cells, _ = env.resulting_cells(later)
    got = conflicts_of(env, later, f'at the placement: hand hits block {first.block}; link7 hits block b9')
    assert got == [Precedence(tuple(sorted(int(c) for c in cells)), tuple(sorted(int(c) for c in placed)))]
    assert conflicts_of(env, later, f'grasp: hand hits block {second.block}') == []   # on the table: no order
    assert conflicts_of(env, later, 'target is 1.02 m from the shoulder') == []


def test_precedences_put_the_blocking_actions_last_only_while_the_cells_they_guard_are_open():
    scene = generate_scene(GeneratorConfig(grid=3), 2)
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    ranked = sorted(AllocationActions(env, solve(scene).placements)(env))
    cells = [tuple(int(c) for c in env.resulting_cells(a)[0]) for a in ranked]
    blocker = ranked[0]
    guarded = next(c for c in cells if not set(c) & set(cells[0]))
    rule = Precedence(guarded, cells[0])
    reordered = precedences_last(env, ranked, [rule])
    breaking = [a for a, c in zip(ranked, cells) if set(c) & set(cells[0]) and not set(guarded) <= set(c)]
    assert blocker in breaking and reordered != ranked
    assert reordered == [a for a in ranked if a not in breaking] + breaking
    env.state.occupancy[list(guarded)] = 99          # the guarded cells are built: no longer held back
    assert precedences_last(env, ranked, [rule]) == ranked


def test_remembered_motion_asks_once_per_world_and_books_no_time_for_an_answer_from_memory():
    scene = generate_scene(GeneratorConfig(grid=3), 2)
    asked = []

    def planner(scene_now, action, start, move_aside=False):
        asked.append((action, move_aside))
        return MotionPlan(False, 'placement', f'refused {len(asked)}', seconds=0.25)
    remembered = remembered_motion(planner)
    action = object()
    a = remembered(scene, action, np.zeros(9), move_aside=True)
    b = remembered(scene, action, np.zeros(9), move_aside=True)
    assert (a.reason, b.reason, a.seconds, b.seconds) == ('refused 1', 'refused 1', 0.25, 0.0)
    remembered(scene, action, np.ones(9), move_aside=True)      # another start: asked again
    remembered(scene, action, None, move_aside=False)
    assert len(asked) == 3
    ranks = []

    def rank(scene_now, placements, start):
        ranks.append(1)
        return len(ranks)
    remembered = remembered_rank(rank)
    assert remembered(scene, [], None) == remembered(scene, [], None) == 1 and len(ranks) == 1


def test_remembered_reallocation_reuses_an_answer_only_where_asking_again_could_not_do_better():
    scene = generate_scene(GeneratorConfig(grid=3), 2)
    placements = solve(scene).placements
    asked = []

    def reallocate(scene_now, exclude, time_limit_s=None):
        asked.append(time_limit_s)
        status = 'OPTIMAL' if time_limit_s is None or time_limit_s >= 5 else 'FEASIBLE'
        return AllocationResult(status, 4.0, 4.0, 0.5, placements[:1])
    remembered = remembered_reallocation(reallocate)
    a = remembered(scene, [placements[1]], 1.0)
    b = remembered(scene, [placements[1]], 0.5)            # less time than before: the same answer
    assert (a.status, b.status, a.solve_time_s, b.solve_time_s, len(asked)) == ('FEASIBLE', 'FEASIBLE', 0.5, 0.0, 1)
    assert remembered(scene, [placements[1]], 2.0).status == 'FEASIBLE' and asked == [1.0, 2.0]   # more time: again
    remembered(scene, [placements[0]], 2.0)                # other no-goods: another question
    remembered(scene, [], 9.0)
    assert remembered(scene, [], 20.0).solve_time_s == 0.0 and len(asked) == 4      # proven: never again
    moved = generate_scene(GeneratorConfig(grid=3), 3)     # another state of the world
    remembered(moved, [], 9.0)
    assert len(asked) == 5


def test_order_repair_builds_what_the_first_order_walled_off(motion):
    """The motion planner refuses every placement on the right once b0 stands on the left (as GAMP
    refuses a hand that would hit it; here made to happen on demand). The verified plan places b0
    first and stalls; order repair plans again with b0 after the right and fills both."""
    scene = generate_scene(GeneratorConfig(grid=3), 2)
    clean = plan_assembly(scene, solve, motion, HeurPolicy(), seed=1)
    assert clean.predicted_coverage == 1.0 and clean.steps[0].block == 'b0' and clean.steps[1].target == 'right'
    where = {b.id: b.position for b in scene.blocks}

    def walled(scene_now, action, start, move_aside=False):
        b0 = next(b for b in scene_now.blocks if b.id == 'b0')
        if action.target == 'right' and b0.position != where['b0']:
            return MotionPlan(False, 'placement', 'at the placement: hand hits block b0')
        return motion(scene_now, action, start, move_aside=move_aside)

    def allocate(s, support):
        return solve(s)
    stalled = plan_for_agent(parse('heur+verify'), scene, allocate, walled, HeurPolicy(), seed=1)
    assert stalled.predicted_coverage < 1.0 and 'hand hits block b0' in stalled.reason
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    b0_cells = _cells(env, clean.steps[0])
    assert stalled.conflicts and all(p.then == b0_cells for p in stalled.conflicts)

    repaired = plan_for_agent(parse('heur+verify+repair'), scene, allocate, walled, HeurPolicy(), seed=1,
                              improve_time_s=60.0)
    assert repaired.predicted_coverage == 1.0 and repaired.success
    assert [s.target for s in repaired.steps][-1] == 'left'       # b0's side last
    assert [a['plan'] for a in repaired.anytime] == ['scorer', 'repair']
    assert [a['coverage'] for a in repaired.anytime] == [stalled.predicted_coverage, 1.0]
    # Repair is bounded by its rounds, not by the anytime budget: with improve_time_s 1 ms after a
    # first plan of about half a second (a slow allocation, which the repair plans reuse), a repair
    # plan that needs a second more (the motion planner slow on the right while b0 is still on the
    # table) still runs to its end within the time limit. improve_time_s 0 turns improving off.
    def slow_allocate(s, support):
        time.sleep(0.5)
        return solve(s)

    def slow_right(scene_now, action, start, move_aside=False):
        b0 = next(b for b in scene_now.blocks if b.id == 'b0')
        if action.target == 'right' and b0.position == where['b0']:
            time.sleep(1.0)
        return walled(scene_now, action, start, move_aside=move_aside)
    hurried = plan_for_agent(parse('heur+verify+repair'), scene, slow_allocate, slow_right, HeurPolicy(), seed=1,
                             improve_time_s=1e-3)
    assert hurried.predicted_coverage == 1.0 and [a['plan'] for a in hurried.anytime] == ['scorer', 'repair']
    assert hurried.anytime[1]['t'] >= 1.5
    # Its timings are those of both plans: the first plan's slow allocation is in them.
    assert hurried.timings['allocation'] >= 0.5 and hurried.timings['motion'] <= hurried.timings['total']
    off = plan_for_agent(parse('heur+verify+repair'), scene, allocate, walled, HeurPolicy(), seed=1,
                         improve_time_s=0.0)
    assert off.predicted_coverage == stalled.predicted_coverage and len(off.anytime) == 1

"""An order of an allocation's poses in which a top-down hand can place each one: order repair's
second chain.

Order repair (`agent_plan.plan_for_agent`) learns precedences from GAMP's refusals: a pose refused
because the hand hit a placed block is tried before that block's pose next time. A refusal names
one block, the first the planner found in the way of the last grasp it tried, while a pose needs
only one way of being held to be free. So repair can learn that a comes before b in one plan and
that b comes before a in the next (held-out spire_cup: two tall blocks side by side, each taken
from above only while the other is not yet there, or from the side the other region's wall is
built against). Where its rounds leave cells unfilled, a second chain starts from this order
(`agent_plan.plan_for_agent`).

`hand_order` asks the whole question at once, for the allocation's poses: an order in which each
pose, when its turn comes, has a way of being held (a grasp at a hand yaw, as
`allocation.arm.HandBlocked.cells` gives them) none of whose blocking cells is built, and rests
on something (the table, a built cell or a pose before it under one of its units: the MDP
refuses a block that would rest on nothing). CP-SAT finds the order placing the most target
cells (all of them where it can). Its answer as precedences: each placed pose before every pose
that fills a blocking cell of the way it is held. The blocking cells are those the hand, its
fingers or panda_link7 always enter (`gamp.hand_cells`); the arm's other links, the carried
block and the pick are left to GAMP, so the order is a guess that a plan still checks step by
step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rad_core.grid import Grid, blocks_on_grid
from rad_core.scene import Scene
from rad_core.sequencing.plan import Precedence


@dataclass
class HandOrder:
    """What `hand_order` found: the poses it can place (grid cells, sorted), in its order, and the
    precedences that order keeps to (`plan.Precedence`: each pose before the poses filling the
    blocking cells of the way it is held). Both empty where CP-SAT found no order in time."""

    order: list[tuple[int, ...]] = field(default_factory=list)
    precedences: list[Precedence] = field(default_factory=list)
    coverage: float = 0.0
    """The target's coverage once the order is placed (cells built before it included)."""


def hand_order(scene: Scene, placements, time_limit_s: float = 1.0, gamp=None) -> HandOrder:
    """An order in which the hand can place the most target cells of `placements` (the allocation's
    poses of the scene's free cells; module docstring), with its precedences."""
    from ortools.sat.python import cp_model
    from rad_core.allocation.arm import HandBlocked
    grid = Grid(scene)
    occupied = np.zeros(grid.num_cells, dtype=bool)
    for cells in blocks_on_grid(scene, grid).values():
        occupied[cells] = True
    regions = [t.name for t in scene.targets]
    hand = HandBlocked(scene, grid, gamp)
    poses = []
    for p in placements:
        ids = [grid.index(regions.index(p.target), c) for c in p.cells]
        if None in ids or occupied[ids].any() or hand.blocked(p.type, p.yaw, ids, occupied):
            continue                      # taken, or every way of holding it is blocked already
        ways = [w for pair in hand.cells(p.type, p.yaw, ids) for w in pair if not occupied[w].any()]
        poses.append((tuple(sorted(int(c) for c in ids)), ways, int(grid.is_target[ids].sum())))
    if not poses:
        return HandOrder()
    owner = {c: n for n, (cells, *_) in enumerate(poses) for c in cells}
    model = cp_model.CpModel()
    placed = [model.new_bool_var(f'x{n}') for n in range(len(poses))]
    order = [model.new_int_var(0, len(poses) - 1, f't{n}') for n in range(len(poses))]
    held_by: list[list] = []
    for n, (cells, ways, _) in enumerate(poses):
        used = []
        for w, blocking in enumerate(ways):
            var = model.new_bool_var(f'w{n}_{w}')
            model.add_implication(var, placed[n])
            for m in sorted({owner[c] for c in blocking.tolist() if c in owner} - {n}):
                model.add(order[n] < order[m]).only_enforce_if([var, placed[m]])
            used.append((var, blocking))
        if used:          # none for a type without a top-down grasp: GAMP says why
            model.add_bool_or([v for v, _ in used]).only_enforce_if(placed[n])
        held_by.append(used)
        # Resting on something: the table, a built cell, or a pose placed before it.
        ids = np.asarray(cells)
        if grid.on_table[ids].any():
            continue
        below = grid.below_idx[ids]
        below = below[(below >= 0) & ~np.isin(below, ids)]
        if occupied[below].any():
            continue
        under = sorted({owner[int(c)] for c in below if int(c) in owner})
        if not under:
            model.add(placed[n] == 0)
            continue
        rests = [model.new_bool_var(f's{n}_{m}') for m in under]
        model.add_bool_or(rests).only_enforce_if(placed[n])
        for var, m in zip(rests, under):
            model.add_implication(var, placed[m])
            model.add(order[m] < order[n]).only_enforce_if(var)
    model.maximize(sum(k * placed[n] for n, (_, _, k) in enumerate(poses)))
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = float(time_limit_s)
    solver.parameters.num_workers = 1
    solver.parameters.catch_sigint_signal = False
    if solver.solve(model) not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        return HandOrder()
    chosen = sorted((n for n in range(len(poses)) if solver.boolean_value(placed[n])),
                    key=lambda n: (solver.value(order[n]), n))
    out = []
    for n in chosen:
        for var, blocking in held_by[n]:
            if solver.boolean_value(var):
                for m in sorted({owner[c] for c in blocking.tolist() if c in owner} - {n}):
                    if solver.boolean_value(placed[m]):
                        out.append(Precedence(poses[n][0], poses[m][0], 'hand order'))
                break
    total = int(grid.is_target.sum())
    filled = int((grid.is_target & occupied).sum()) + sum(poses[n][2] for n in chosen)
    return HandOrder([poses[n][0] for n in chosen], out, filled / total if total else 1.0)


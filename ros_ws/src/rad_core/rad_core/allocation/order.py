"""An order of an allocation's poses in which a top-down hand can place each one: order repair's
'hand-order' stage; the same model over every candidate pose, for the 'cover' stage
(`ordered_cover`) and the robot ceiling's bound (`allocation.bounds.ArmCoverageBound`, `ordered`).

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
cells (all of them where it can). The order is then walked with what is built taken as a whole
(`domain.statics.order_statics`): a pose whose load would tip what holds it waits until a pose
after it holds it down, or is left out. Its answer as precedences: each placed pose before every pose
that fills a blocking cell of the way it is held. The blocking cells are those the hand, its
fingers or panda_link7 always enter (`gamp.hand_cells`); the arm's other links, the carried
block and the pick are left to GAMP, so the order is a guess that a plan still checks step by
step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from ortools.sat.python import cp_model

from rad_core.allocation.arm import HandBlocked, arm_filter
from rad_core.allocation.constraints import cp_solver, rests_now, support_options
from rad_core.allocation.placements import enumerate_candidates
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Scene
from rad_core.domain.statics import order_statics
from rad_core.gamp.planner import GampConfig

LARGE_POSES = 400
"""Above this many poses (a large structure's courses: 2,000-4,000, where CP-SAT found no order at all
in its time), `solve_order` starts CP-SAT from `greedy_order`, answers with it where CP-SAT finds none,
and `order_model` holds each way against when its cells are filled. Below, a hint would only steer
which of equal orders CP-SAT returns (generated and hand-made scenes have 17-274 poses), so those
models stay as they were."""


@dataclass(frozen=True)
class Precedence:
    """Fill the grid cells `first` before putting a block on any of the cells `then`: a plan's
    action on `first` was refused because the arm or the held block hit the block that plan had
    placed on `then`, and `first` stayed unfilled."""

    first: tuple[int, ...]
    then: tuple[int, ...]
    reason: str = field(default='', compare=False)


@dataclass
class HandOrder:
    """What `hand_order` found: the poses it can place (grid cells, sorted), in its order, and the
    precedences that order keeps to (`plan.Precedence`: each pose before the poses filling the
    blocking cells of the way it is held). Both empty where CP-SAT found no order in time."""

    order: list[tuple[int, ...]] = field(default_factory=list)
    precedences: list[Precedence] = field(default_factory=list)
    coverage: float = 0.0
    """The target's coverage once the order is placed (cells built before it included)."""
    placements: list = field(default_factory=list)
    """The poses of `order` as the allocation's `Placement`s, in the same order."""
    value: int = 0
    """c^T g of those poses: target cells less non-target ones (fillers)."""
    tipping: list[tuple[int, ...]] = field(default_factory=list)
    """Poses CP-SAT's order placed that would tip what holds them, in every walk tried
    (`domain.statics.order_statics`): left out of `order`."""
    drops: bool = False
    """Whether the order counts on GAMP's drops (`GampConfig.drop`; `ordered_cover`): a plan of it takes them."""

    def left_out(self, poses) -> list[int]:
        """Indices of `poses` (grid cells, sorted) this order does not place: those CP-SAT's order
        leaves out; where it leaves none out, those that would tip. Most tipping poses lean on a
        pose left out, and stand again once that one is replaced."""
        placed, tipping = set(self.order), set(self.tipping)
        left = [k for k, key in enumerate(poses) if key not in placed and key not in tipping]
        return left or [k for k, key in enumerate(poses) if key in tipping]


def hand_ways(grid: Grid, hand, occupied: np.ndarray, type_name: str, yaw: int, ids) -> list[np.ndarray] | None:
    """The ways a pose can still be held (the blocking cells of each grasp at each hand yaw, none
    of them built), or None where every way is blocked already (`HandBlocked.blocked`) or a cell over
    the pose is built (the carried block comes down through its columns); [] for a type without a
    top-down grasp (GAMP says why)."""
    if hand.blocked(type_name, yaw, ids, occupied) or occupied[grid.columns_above(ids)].any():
        return None
    return [w for pair in hand.cells(type_name, yaw, ids) for w in pair if not occupied[w].any()]


def order_model(grid: Grid, occupied: np.ndarray, poses: list[tuple], counts: dict[str, int] | None = None,
                cover: bool = False, rest: bool = True, way_down: bool = False):
    """The CP-SAT model of an order of poses: which are placed (`placed[n]`), their positions
    (`order[n]`), and per pose the ways it is held (`held_by[n]`: (variable, blocking cells)).

    poses: (cells sorted, ways from `hand_ways`, target cells it fills, type name) of free poses.
    Each placed pose, when its turn comes, has a way of being held none of whose blocking cells a
    pose before it fills, and rests on the table, a built cell or a pose before it under one of its
    units (the MDP refuses a block that would rest on nothing). way_down: and comes before every pose
    with a cell in the columns over its cells (the carried block comes down through them:
    `path_precedences`); supply asks for it, since a cover without such an order (four stepped pieces
    in a pinwheel, each over the next) can never be built. The planner's stages do not: there the
    rule changed which cover CP-SAT picks and lost 4 of the 78 scenes of `benchmarks/bench_eval.py` to
    the hand model's other misses, while GAMP refuses such a placement and order repair learns the
    precedence from the refusal. The one exception is the cover stage's last try, a second drops' cover
    (`agent_plan.effector_solvers`): without the rule, the solid 3 x 3 x 2 box's drop cover put a block
    under one placed before it, and the repair rounds after it built less than the set-down plan.
    A pose under a built cell has no way in either way (`hand_ways`).
    Where poses overlap (candidates, not an allocation), at most one fills a cell, and counts caps the
    poses of each type.
    Maximizes the target cells placed.

    cover: `ordered_cover`'s stricter rules for a plan (the bound keeps the MDP's): each pose
    stands as the allocation's support='stable' asks (`allocation.constraints.support_options`: its
    centre of mass over units resting on the table, built cells or poses placed before it), and
    among the best, the fewest cells outside the target (fillers), as c^T g would. rest=False: no
    rule on what a pose rests on (`courses.course_bound`'s relaxation)."""
    owners: dict[int, list[int]] = {}
    for n, (cells, *_) in enumerate(poses):
        for c in cells:
            owners.setdefault(c, []).append(n)
    model = cp_model.CpModel()
    placed = [model.new_bool_var(f'x{n}') for n in range(len(poses))]
    order = [model.new_int_var(0, len(poses) - 1, f't{n}') for n in range(len(poses))]
    for ns in owners.values():
        if len(ns) > 1:
            model.add_at_most_one([placed[n] for n in ns])
    if counts is not None:
        by_type: dict[str, list] = {}
        for n, pose in enumerate(poses):
            by_type.setdefault(pose[3], []).append(placed[n])
        for name, vars_ in by_type.items():
            if counts.get(name, 0) < len(vars_):
                model.add(sum(vars_) <= counts.get(name, 0))
    # Where there are thousands of poses (a large structure's course), each way is held against when
    # its blocking cells are filled (`filled_at`), not against every pose that may fill them: the same
    # rule in a tenth of the constraints (a 4,000-pose window: a million of them the other way).
    filled_at: dict[int, cp_model.IntVar] | None = {} if len(poses) > LARGE_POSES else None

    def when_filled(c: int):
        var = filled_at.get(c)
        if var is None:          # the position of the pose that fills c; past the last where none does
            var = filled_at[c] = model.new_int_var(0, len(poses), f'c{c}')
            for m in owners[c]:
                model.add(var == order[m]).only_enforce_if(placed[m])
        return var

    held_by: list[list] = []
    for n, (cells, ways, *_) in enumerate(poses):
        used = []
        for w, blocking in enumerate(ways):
            var = model.new_bool_var(f'w{n}_{w}')
            model.add_implication(var, placed[n])
            if filled_at is not None:
                for c in sorted({c for c in blocking.tolist() if c in owners} - set(cells)):
                    model.add(order[n] < when_filled(c)).only_enforce_if(var)
            else:
                for m in sorted({m for c in blocking.tolist() for m in owners.get(c, ())} - {n}):
                    model.add(order[n] < order[m]).only_enforce_if([var, placed[m]])
            used.append((var, blocking))
        if used:          # none for a type without a top-down grasp: GAMP says why
            model.add_bool_or([v for v, _ in used]).only_enforce_if(placed[n])
        held_by.append(used)
        if way_down:
            for m in path_precedences(grid, cells, owners, n):
                model.add(order[n] < order[m]).only_enforce_if([placed[n], placed[m]])
        if cover:
            _stands(model, grid, occupied, cells, n, placed, order, owners)
            continue
        if rest:
            _rests(model, grid, occupied, cells, n, placed, order, owners)
    filled = sum(pose[2] * placed[n] for n, pose in enumerate(poses))
    if cover:
        outside = [len(pose[0]) - pose[2] for pose in poses]
        model.maximize((sum(outside) + 1) * filled - sum(k * placed[n] for n, k in enumerate(outside) if k))
    else:
        model.maximize(filled)
    return model, placed, order, held_by


def _rests(model, grid: Grid, occupied: np.ndarray, cells, n: int, placed, order, owners) -> None:
    """Pose n, where placed, rests on something: the table, a built cell, or a pose placed before it
    under one of its units."""
    ids = np.asarray(cells)
    below = _cells_below(grid, ids)
    if below is None or occupied[below].any():
        return
    under = sorted({m for c in below.tolist() for m in owners.get(int(c), ())})
    if not under:
        model.add(placed[n] == 0)
        return
    rests = [model.new_bool_var(f's{n}_{m}') for m in under]
    model.add_bool_or(rests).only_enforce_if(placed[n])
    for var, m in zip(rests, under):
        model.add_implication(var, placed[m])
        model.add(order[m] < order[n]).only_enforce_if(var)


def path_precedences(grid: Grid, cells, owners: dict[int, list[int]], n: int) -> list[int]:
    """The poses (indices into `owners`' lists) with a cell over pose n's cells, in their columns: n is
    placed before them, or its carried block would come down onto them."""
    return sorted({m for c in grid.columns_above(cells).tolist() for m in owners.get(c, ())} - {n})


def _stands(model, grid: Grid, occupied: np.ndarray, cells, n: int, placed, order, owners) -> None:
    """Pose n, where placed, stands on one of its sufficient support sets
    (`allocation.constraints.support_options`): every unit of the set on the table, a built cell, or a
    pose placed before it."""
    sets = support_options(grid, list(cells), occupied, owners)
    if sets is None:
        return                                   # stands whatever else is placed
    options = []
    for unders in sets:
        z = model.new_bool_var(f'z{n}_{len(options)}')
        for under in unders:
            rests = [model.new_bool_var(f'r{n}_{len(options)}_{m}') for m in under]
            for var, m in zip(rests, under):
                model.add_implication(var, placed[m])
                model.add(order[m] < order[n]).only_enforce_if(var)
            model.add_bool_or(rests).only_enforce_if(z)
        options.append(z)
    if options:
        model.add_bool_or(options).only_enforce_if(placed[n])
    else:
        model.add(placed[n] == 0)


def hand_order(scene: Scene, placements, time_limit_s: float = 1.0, gamp=None, way_down: bool = False) -> HandOrder:
    """An order in which the hand can place the most target cells of `placements` (the allocation's
    poses of the scene's free cells; module docstring), with its precedences (way_down: `order_model`'s)."""
    grid, occupied = scene_state(scene)
    regions = [t.name for t in scene.targets]
    hand = HandBlocked(scene, grid, gamp)
    poses, items = [], []
    for p in placements:
        ids = [grid.index(regions.index(p.target), c) for c in p.cells]
        if None in ids or occupied[ids].any():
            continue
        ways = hand_ways(grid, hand, occupied, p.type, p.yaw, ids)
        if ways is None:
            continue                      # every way of holding it is blocked already
        poses.append((tuple(sorted(int(c) for c in ids)), ways, int(grid.is_target[ids].sum()), p.type))
        items.append(p)
    return solve_order(grid, occupied, poses, items, None, time_limit_s, way_down=way_down)


def ordered_cover(scene: Scene, time_limit_s: float = 2.0, gamp=None, avoid=(), way_down: bool = False) -> HandOrder:
    """The allocation and its order at once: among every pose an arm-aware allocation may propose
    (`allocation.bounds.ArmCoverageBound.candidates`: fillers worth 0 included, the arm's filter
    applied) and the blocks the arm can pick, the disjoint ones with an order in which the hand
    can place the most target cells (`order_model` with counts), with that order's precedences
    and the poses as `placements`. What the robot ceiling's ordered bound solves, kept as a plan:
    where an allocation's cover has no such order (a cantilever's end the hand can only reach
    before its neighbour is there, which needs another block below it), this one picks a cover
    that has. CP-SAT's best within `time_limit_s` (deterministic time); empty where it found none.
    avoid: covers found before (their `order`s), not to be found again as they were. Where the hand
    drops (`GampConfig.drop`), the order counts on drops (`HandOrder.drops`). way_down: `order_model`'s."""
    gamp = gamp or GampConfig()
    grid, occupied = scene_state(scene)
    candidates, counts, hand, _ = cover_candidates(scene, grid, gamp)
    poses, items = candidate_poses(grid, hand, occupied, candidates, counts)
    found = solve_order(grid, occupied, poses, items, counts, time_limit_s, cover=True, avoid=avoid,
                        way_down=way_down)
    found.drops = gamp.drop and gamp.effector == 'hand' and scene.studs is None
    return found


def cover_candidates(scene: Scene, grid: Grid, gamp=None, near: bool = False):
    """What an ordered cover chooses from: every pose an arm-aware allocation may propose
    (`allocation.bounds.ArmCoverageBound.candidates`: fillers worth 0 included, the arm's filter
    applied), the blocks per type the arm can pick, the hand's blocking cells (`HandBlocked`, near:
    its) and the indices of the blocks it cannot pick where they lie."""
    fillers = [c for c in enumerate_candidates(scene, grid, positive_only=False) if c.value >= 0]
    candidates, counts, report = arm_filter(scene, grid, fillers, gamp)
    unpickable = {b for b, block in enumerate(scene.blocks) if block.id in report.blocks}
    return candidates, counts, HandBlocked(scene, grid, gamp, near), unpickable


def candidate_poses(grid: Grid, hand, occupied: np.ndarray, candidates, counts: dict[str, int]):
    """`order_model`'s poses of free candidates (`allocation.placements.Candidate`) that fill a
    target cell, have a block of their type left and a way of being held; and their placements."""
    poses, items = [], []
    for c in candidates:
        ids = list(c.cell_ids)
        k = int(grid.is_target[ids].sum())
        if k and counts.get(c.placement.type, 0) and not occupied[ids].any():
            ways = hand_ways(grid, hand, occupied, c.placement.type, c.placement.yaw, ids)
            if ways is not None:
                poses.append((tuple(sorted(ids)), ways, k, c.placement.type))
                items.append(c.placement)
    return poses, items


def scene_state(scene: Scene) -> tuple[Grid, np.ndarray]:
    """The scene's grid and the cells its blocks fill now."""
    grid = Grid(scene)
    occupied = np.zeros(grid.num_cells, dtype=bool)
    for cells in blocks_on_grid(scene, grid).values():
        occupied[cells] = True
    return grid, occupied


def solve_order(grid: Grid, occupied: np.ndarray, poses: list[tuple], items: list, counts, time_limit_s: float,
                cover: bool = False, avoid=(), way_down: bool = False) -> HandOrder:
    """`order_model` solved: the poses it places in its order, their precedences (each before the
    poses filling the blocking cells of the way it is held), the coverage, the items of those poses.
    cover: `ordered_cover`'s solve: `order_model`'s cover rules, and CP-SAT's deterministic time
    (about seconds of one core), so that the answer does not depend on how busy the machine is
    (wall time only as a backstop). avoid: sets of poses (cells sorted) not to be placed all together.
    way_down: `order_model`'s, and its precedences among those of the answer."""

    if not poses:
        return HandOrder()
    model, placed, order, held_by = order_model(grid, occupied, poses, counts, cover=cover, way_down=way_down)
    index = {pose[0]: n for n, pose in enumerate(poses)}
    avoided = []                 # the poses of each cover found before, where all of them are here
    for before in avoid:
        ns = [index[cells] for cells in before if cells in index]
        if ns and len(ns) == len(before):
            avoided.append(ns)
    for ns in avoided:
        model.add(sum(placed[n] for n in ns) <= len(ns) - 1)
    large = len(poses) > LARGE_POSES
    first = greedy_order(grid, occupied, poses, counts, cover=cover, way_down=way_down) if large else []
    ways_of = {n: way for n, way in first}
    for k, (n, way) in enumerate(first):
        model.add_hint(placed[n], True)
        model.add_hint(order[n], k)
        for w, (var, _) in enumerate(held_by[n]):
            model.add_hint(var, w == way)
    for n in (range(len(poses)) if large else ()):
        if n not in ways_of:
            model.add_hint(placed[n], False)
            for var, _ in held_by[n]:
                model.add_hint(var, False)
    solver = cp_solver(3.0 * time_limit_s if cover else time_limit_s)
    if cover:
        solver.parameters.max_deterministic_time = float(time_limit_s)
    if solver.solve(model) in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        chosen = sorted((n for n in range(len(poses)) if solver.boolean_value(placed[n])),
                        key=lambda n: (solver.value(order[n]), n))
        held = {n: next((w for w, (var, _) in enumerate(held_by[n]) if solver.boolean_value(var)), None)
                for n in chosen}
        if large and sum(poses[n][2] for n in chosen) < sum(poses[n][2] for n, _ in first):
            chosen, held = [n for n, _ in first], ways_of       # CP-SAT did not get as far as its hint
    elif not large:
        return HandOrder()
    else:
        # CP-SAT found nothing in its time (presolve of thousands of poses can take all of it): the
        # greedy order, which it would have started from, where it keeps out of `avoid`. Not on fewer
        # poses: there the course line's one-course cover is better than a greedy two-course one (g = 8
        # seed 7000 of `benchmarks/bench_large.py` fell from 1.0 to 0.94).
        chosen, held = [n for n, _ in first], ways_of
        if not chosen or any(set(ns) <= set(chosen) for ns in avoided):
            return HandOrder()
    walk, waiting = order_statics(grid, [poses[n][0] for n in chosen], occupied, clutch=grid.clutch)
    tipping = [poses[chosen[k]][0] for k in waiting]
    chosen = [chosen[k] for k in walk]          # the structure stands as a whole after each pose
    owner = {c: n for n in chosen for c in poses[n][0]}
    owners = {c: [n] for c, n in owner.items()}
    out = []
    for n in chosen:
        if way_down:
            out += [Precedence(poses[n][0], poses[m][0], "the carried block's way down")
                    for m in path_precedences(grid, poses[n][0], owners, n)]
        if held[n] is not None:
            blocking = held_by[n][held[n]][1]
            for m in sorted({owner[c] for c in blocking.tolist() if c in owner} - {n}):
                out.append(Precedence(poses[n][0], poses[m][0], 'hand order'))
    total = int(grid.is_target.sum())
    filled = int((grid.is_target & occupied).sum()) + sum(poses[n][2] for n in chosen)
    value = sum(2 * poses[n][2] - len(poses[n][0]) for n in chosen)
    return HandOrder([poses[n][0] for n in chosen], out, filled / total if total else 1.0,
                     [items[n] for n in chosen], value, tipping)


def greedy_order(grid: Grid, occupied: np.ndarray, poses: list[tuple], counts=None, cover: bool = False,
                 way_down: bool = False) -> list[tuple[int, int | None]]:
    """A first answer to `order_model` in one sweep, feasible by construction: (pose index, the way it
    is held, None for a type without a top-down grasp) in order. Poses are taken lowest first, then
    those filling the most target cells with the fewest fillers; each where its cells are free, a block
    of its type is left, one of its ways has no blocking cell filled before it, no pose before it lies
    in the columns over it (way_down) and it rests as the model asks (cover: the 'stable' rule on what
    is there; else a bottom unit on the table, a built cell or a pose before it). Sweeps again while a
    sweep adds a pose (a pose may rest only on one taken after it in the sweep before)."""
    if not poses:
        return []
    filled = occupied.copy()
    left = dict(counts) if counts is not None else None
    low = [float(grid.centres[list(cells), 2].min()) for cells, *_ in poses]
    rank = sorted(range(len(poses)), key=lambda n: (low[n], -poses[n][2], len(poses[n][0]) - poses[n][2], n))
    out: list[tuple[int, int | None]] = []
    taken = np.zeros(len(poses), dtype=bool)
    added = True
    while added:
        added = False
        for n in rank:
            cells, ways, _, name = poses[n][:4]
            ids = list(cells)
            if taken[n] or filled[ids].any() or (left is not None and left.get(name, 0) <= 0):
                continue
            way = next((w for w, blocking in enumerate(ways) if not filled[blocking].any()), None)
            if ways and way is None:
                continue
            if way_down and filled[grid.columns_above(ids)].any():
                continue
            if cover:
                if not rests_now(grid, ids, filled):
                    continue
            elif not _rests_on(grid, ids, filled):
                continue
            taken[n] = True
            filled[ids] = True
            if left is not None:
                left[name] -= 1
            out.append((n, way))
            added = True
    return out


def _cells_below(grid: Grid, ids: np.ndarray) -> np.ndarray | None:
    """The cells under a pose's bottom units (not its own), or None where a unit stands on the table."""
    if grid.on_table[ids].any():
        return None
    below = grid.below_idx[ids]
    return below[(below >= 0) & ~np.isin(below, ids)]


def _rests_on(grid: Grid, ids: list[int], filled: np.ndarray) -> bool:
    """`order_model`'s rest rule: a unit on the table or over a filled cell not its own."""
    below = _cells_below(grid, np.asarray(ids))
    return below is None or bool(filled[below].any())

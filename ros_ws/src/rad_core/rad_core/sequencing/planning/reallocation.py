"""Re-allocation when sequencing stalls: the levels inform each other.

The paper solves the allocation once; when no allocated pose can be built next
its agents stop. Here, when the episode would stop while allocated poses are
still open, the `Reallocator`:

1. checks every open pose from the state as it is (each block still on the table
   that could fill it, one motion per distinct final pose) with the caller's
   check: GAMP, and with the robot in the loop execution and physics too;
2. turns the poses that fail although they would rest on what is already there
   into no-goods (type, region, cells): more blocks around only add obstacles,
   so they stay excluded for the rest of the episode. A pose that fails only
   because what should hold it up is not built yet is not a no-good; the
   re-solved allocation must give it new support or drop it;
   no-goods are kept at the level the failure belongs to: a block that cannot be
   picked where it lies (GAMP's failure 'grasp': every grasp blocked, by its
   neighbours on the table or the arm's reach) is excluded as a block, whatever
   pose it was asked for, and the pose is not blamed when every block of its type
   failed that way. The table only loses blocks, so such a block is excluded
   until a block leaves the table (its neighbour may have been what blocked it);
3. solves the allocation again (also when the allocation is used up while target
   cells are still free: what is built now may hold up poses it could not) (CP-SAT, proven optimal for each problem it
   solves, or the anytime bound) over the cells still free, with the placed
   blocks fixed, the blocks still on the table available and the no-goods
   excluded, by default with the 'stable' support constraints whatever the first
   allocation was (every re-allocated block can rest on something);
4. hands the new poses to the action space, so the sequencer continues from the
   new allocation, and records the event (`Reallocation`, shown in the plan,
   /plan_assembly's response, result.json rows and Rerun).

Bounded by `ReallocationConfig.max_reallocations` per episode and by the
caller's deadline; a re-allocation that proposes the same open poses ends the
episode as before (nothing new to try).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from rad_core.allocation import AllocationParams, AllocationResult, Placement, solve
from rad_core.allocation.constraints import rests_now
from rad_core.allocation.cpsat import pose_key
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Block, Scene
from rad_core.env.mdp import AssemblyEnv
from rad_core.sequencing.decide.episode import Decide, Decision
from rad_core.sequencing.decide.policy import first_feasible

Check = Callable[[object], object]   # action -> a result with .success and .reason
# (scene state, no-goods, time limit in s or None) -> the allocation of the cells still free
Allocate = Callable[[Scene, list, 'float | None'], AllocationResult]


@dataclass(frozen=True)
class ReallocationConfig:
    """When and how to re-solve the allocation.

    max_reallocations: per episode (each re-solve is one CP-SAT call within the
        remaining time).
    params: the re-solve's CP-SAT settings; support='stable' by default.
    """

    max_reallocations: int = 10
    params: AllocationParams = AllocationParams(support='stable')

    def validate(self) -> None:
        if not (isinstance(self.max_reallocations, int) and self.max_reallocations >= 0):
            raise RadError(f'max_reallocations must be a non-negative integer, got {self.max_reallocations!r}')
        self.params.validate()


@dataclass
class Reallocation:
    """One re-allocation: when (placements made before it), why, what was excluded, what came out."""

    step: int
    reason: str
    no_goods: list[dict] = field(default_factory=list)   # {type, target, cells, reason}
    status: str = ''
    objective: float = 0.0
    bound: float = 0.0
    solve_time_s: float = 0.0
    placements: list[Placement] = field(default_factory=list)
    changed: bool = False          # the new allocation offers poses the old one did not
    blocks: list[dict] = field(default_factory=list)     # blocks excluded: {block, type, reason}

    def to_dict(self) -> dict:
        return {'step': self.step, 'reason': self.reason, 'no_goods': self.no_goods, 'blocks': self.blocks,
                'status': self.status,
                'objective': self.objective, 'bound': self.bound, 'solve_time_s': self.solve_time_s,
                'placements': [p.to_dict() for p in self.placements], 'changed': self.changed}

    def summary(self) -> str:
        verdict = (f'{len(self.placements)} poses ({self.status}, objective {self.objective:g}, '
                   f'bound {self.bound:g})' if self.changed else 'nothing new')
        blocks = f' and {len(self.blocks)} blocks that cannot be picked' if self.blocks else ''
        return (f're-allocation after {self.step} placements: {self.reason}; excluded {len(self.no_goods)} '
                f'poses{blocks}; {verdict}')


def placed_scene(env: AssemblyEnv) -> Scene:
    """The env's scene with every placed block at its exact grid pose (the others where
    they started), the form a re-allocation reads: placed blocks are fixed by their cells."""
    moved = {}
    for b, (cells, yaw) in env.state.placed.items():
        anchor = env.grid.centres[cells[0]]   # cells are in unit order: the first is the anchor's
        moved[b] = (tuple(round(float(v), 6) for v in anchor), int(yaw) % 360)
    blocks = tuple(Block(blk.id, blk.type, *moved[b]) if b in moved else blk for b, blk in enumerate(env.scene.blocks))
    return replace(env.scene, blocks=blocks)


def local_allocate(params: AllocationParams) -> Callable[..., AllocationResult]:
    """The in-process re-solve: (scene, no-goods, time_limit_s) -> CP-SAT's allocation."""
    def allocate(scene: Scene, exclude, time_limit_s: float | None = None) -> AllocationResult:
        p = params if time_limit_s is None else replace(params, time_limit_s=max(1e-3, time_limit_s))
        return solve(scene, p, exclude)
    return allocate


class Reallocator:
    """Re-solves an episode's allocation when its sequencing stalls (see the module docstring).

    space: the episode's `AllocationActions`; its guide is replaced by each changed
        re-allocation, so every decider built on it sees the new poses.
    check: action -> result with .success and .reason (the verifier of the episode).
    scene_of: the scene state to re-allocate from (default: `placed_scene(env)`).
    allocate: (scene, no-goods, time limit) -> AllocationResult (default: in-process CP-SAT).
    """

    def __init__(self, space, check: Check, config: ReallocationConfig = ReallocationConfig(),
                 scene_of: Callable[[AssemblyEnv], Scene] | None = None, allocate: Allocate | None = None,
                 deadline: float | None = None):
        config.validate()
        self.space, self.check, self.config = space, check, config
        self.scene_of = scene_of or placed_scene
        self.allocate = allocate or local_allocate(config.params)
        self.deadline = deadline
        self.events: list[Reallocation] = []
        self.no_goods: dict[tuple, dict] = {}
        self.blocked: dict[int, dict] = {}    # block index -> {block, type, reason, table}: not pickable
        self.seconds = 0.0

    def can_retry(self, env: AssemblyEnv) -> bool:
        """Whether to re-allocate instead of stopping: blocks are left, and allocated poses
        are open or target cells are still free (the allocation is used up, but what is
        built now may hold up poses the first one could not have), within the limits."""
        free_targets = bool((env.grid.is_target & (env.state.occupancy < 0)).any())
        return (len(self.events) < self.config.max_reallocations and bool(env.unplaced())
                and (bool(self.space.guide.open_poses(env.state)) or free_targets)
                and (self.deadline is None or time.perf_counter() < self.deadline))

    def stalled(self, env: AssemblyEnv, reason: str) -> Reallocation:
        """Check the open poses, add the no-goods, re-solve; the event (also in `events`)."""
        t0 = time.perf_counter()
        guide: AllocationGuide = self.space.guide
        occupied = env.state.occupancy >= 0
        default = ('no allocated pose can be built next' if guide.open_poses(env.state)
                   else 'the allocation is built and target cells are still free')
        event = Reallocation(len(env.state.placed), reason or default)
        table = frozenset(env.unplaced())
        # A block excluded while the table held more blocks may be free now: check it again.
        self.blocked = {b: d for b, d in self.blocked.items() if d['table'] == table}
        for k in guide.open_poses(env.state):
            failure = self._pose_failure(env, guide, k, table, event)
            if failure is None or not rests_now(env.grid, guide.pose_cells[k], occupied):
                continue
            p = guide.placements[k]
            key = pose_key(p.type, p.target, p.cells)
            if key not in self.no_goods:
                self.no_goods[key] = {'type': p.type, 'target': p.target, 'cells': [list(c) for c in p.cells],
                                      'reason': failure}
                event.no_goods.append(self.no_goods[key])
        exclude = [Placement(d['type'], d['target'], 0, tuple(tuple(c) for c in d['cells']))
                   for d in self.no_goods.values()]
        left = None if self.deadline is None else self.deadline - time.perf_counter()
        if left is not None and left <= 0:
            event.status = 'SKIPPED'
            event.reason += '; no time left to re-allocate'
        else:
            limit = self.config.params.time_limit_s if left is None else min(self.config.params.time_limit_s, left)
            result = self.allocate(self._without_blocked(self.scene_of(env)), exclude, limit)
            event.status, event.objective, event.bound = result.status, result.objective, result.bound
            event.solve_time_s = result.solve_time_s
            event.placements = list(result.placements)
            before = {pose_key(guide.placements[k].type, guide.placements[k].target, guide.placements[k].cells)
                      for k in guide.open_poses(env.state)}
            after = {pose_key(p.type, p.target, p.cells) for p in result.placements}
            event.changed = result.has_solution and after != before and bool(after)
            if event.changed:
                self.space.guide = AllocationGuide(env.scene, result.placements, env.grid)
        self.events.append(event)
        self.seconds += time.perf_counter() - t0
        return event

    def _pose_failure(self, env: AssemblyEnv, guide: AllocationGuide, k: int, table: frozenset,
                      event: Reallocation) -> str | None:
        """None when pose k is not to blame: some block can fill it now, or every block of its
        type failed to be picked (those blocks are excluded instead, see the module docstring);
        else the first failure's reason (each distinct motion checked once, as a verified agent
        goes down its ranking). Blocks already excluded are not tried again."""
        candidates = guide.pose_actions(k, env.state)
        actions = [a for a in candidates if a.block not in self.blocked]
        action, _, failed = first_feasible(env, actions, self.check)
        if action is not None:
            return None
        if not failed:      # nothing left to try: its blocks are excluded, or there are none
            return None if len(actions) < len(candidates) else 'no block of its type is left'
        placing = []
        for a, r in failed:
            if getattr(r, 'failure', '') != 'grasp':
                placing.append((a, r))
            elif a.block not in self.blocked:
                block = env.scene.blocks[a.block]
                self.blocked[a.block] = {'block': block.id, 'type': block.type, 'reason': r.reason, 'table': table}
                event.blocks.append({'block': block.id, 'type': block.type, 'reason': r.reason})
        if not placing:
            return None
        first, result = placing[0]
        return f'{env.scene.blocks[first.block].id}: {result.reason}'

    def _without_blocked(self, scene: Scene) -> Scene:
        """The scene to re-allocate from, without the table blocks that cannot be picked."""
        if not self.blocked:
            return scene
        gone = {d['block'] for d in self.blocked.values()}
        return replace(scene, blocks=tuple(b for b in scene.blocks if b.id not in gone))


def with_reallocation(decide: Decide, reallocator: Reallocator) -> Decide:
    """decide() that re-allocates instead of stopping while allocated poses remain open,
    and asks `decide` again after each re-allocation that offers something new."""
    def wrapped(env: AssemblyEnv, rng: np.random.Generator) -> Decision:
        decision = decide(env, rng)
        while decision.action.is_terminate and reallocator.can_retry(env):
            if not reallocator.stalled(env, decision.reason).changed:
                break
            decision = decide(env, rng)
        return decision
    return wrapped


def reallocation_support(support: str) -> str:
    """The support rule of re-allocations: stable (every new block can rest on something), and
    arm-aware (and hand-ordered) when the agent's first allocation is ('arm', 'hand')."""
    return support if support in ('arm', 'hand') else 'stable'

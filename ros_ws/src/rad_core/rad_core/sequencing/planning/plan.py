"""Plan a whole assembly: allocate, sequence, plan every motion.

`plan_assembly` knows nothing of ROS or of where its parts run: it takes the
allocation and the motion planner as callables, so the /plan_assembly node passes
DDS service clients and tests or `rad eval` pass the in-process functions.

Each step: the sequencer ranks the allocation's allowed actions; the best one
whose motion GAMP finds feasible from the current state is taken (so a plan never
commands an action that fails in the planning copy); the planning copy of the
scene then has that block at its allocated pose, and the next step starts from
where the last step's motion left the arm and the hand.

The sequencer is either a `Policy` scoring the MDP state in-process, or a `Rank`
callable asked with the planning copy's scene, the allocation and the start joints
(`Sequencer(...).rank` in-process, the sequencer node's service over DDS). A
ranked action outside the allocation's allowed actions is never taken.

With `reallocate` (an allocation callable that takes the scene state, no-goods and a
time limit), a step where nothing can be built while allocated poses remain does not
end the plan: the open poses are checked with GAMP from the planning copy, those
that fail become no-goods, the allocation is solved again over the free cells
(`sequencing.planning.reallocation`) and sequencing goes on; each event is in
`AssemblyPlan.reallocations`.
"""

from __future__ import annotations

import inspect
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from rad_core.allocation.order import Precedence
from rad_core.allocation.result import AllocationResult
from rad_core.cell.motion import Motion
from rad_core.domain.scene import Block, Scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig, Outcome
from rad_core.gamp.action import SceneAction, blocks_named
from rad_core.gamp.grasps import beside_blocks
from rad_core.sequencing.decide.actions import AllocationActions, mdp_actions, scene_action
from rad_core.sequencing.decide.deciders import with_fallbacks
from rad_core.sequencing.decide.episode import Decision, Episode, run_episode, stop
from rad_core.sequencing.decide.policy import DROP_LOOKAHEAD, Policy, first_feasible, ranked_actions, refused
from rad_core.sequencing.planning.reallocation import ReallocationConfig, Reallocator, with_reallocation
from rad_core.sim.physics import PhysicsStability


@dataclass
class MotionPlan:
    """What a motion planner (in-process GAMP or the gamp node) answers."""

    success: bool
    failure: str = ''
    reason: str = ''
    grasp: tuple[int, ...] = (0, 0, 1)   # unit, yaw, span (1: a unit grasp; `gamp.grasps.Grasp`)
    motion: dict | None = None        # rad_core.cell.motion.Motion.to_dict(): {"trajectories", "gripper"}
    moved_aside: list = field(default_factory=list)   # blocks moved out of the way first (GampResult.moved_aside)
    seconds: float = 0.0              # the planner's own time (the gamp node's planning_time_s), transport left out
    drop: float = 0.0                 # how far over its place the block is let go (GampResult.drop); 0: set down


def _span(grasp) -> int:
    """A grasp tuple's span: 1 (a unit grasp) where it has none."""
    return int(grasp[2]) if len(grasp) > 2 else 1


@dataclass
class PlanStep:
    """One step of a plan: a block, the allocated pose it goes to (type, target region, yaw,
    region-local cells) and how (MDP unit, cell and rotation, grasp, anchor position, and the motion:
    arm trajectories and gripper commands in order, `rad_core.cell.motion.Motion.to_dict()`).

    Its `to_dict` form is a step of rad-result/1 and of the plan_json topic (there without the
    motion); the motion's "trajectories" (exactly as sent to the arm controller) and "gripper"
    commands are keys of the step. `from_dict` reads it back. Only block to cells are required: a
    step read from a document that lacks the rest has the defaults (0, empty, None for the motion).

    moved_aside: blocks on the table in the way of the grasp that the motion first moves to free
    places, in order: {'block', 'position' (anchor, m), 'yaw' (deg)} (`MotionPlanner`'s move aside);
    in the dict form only when there are any.
    """

    block: str
    type: str
    target: str
    yaw: int
    cells: list[list[int]]
    unit: int = 0
    cell: list[int] = field(default_factory=list)
    rotation: int = 0
    grasp: tuple[int, ...] = (0, 0, 1)
    """(unit, yaw, span) of the grasp, as `MotionPlan.grasp`."""
    position: list[float] = field(default_factory=list)
    motion: dict | None = None
    moved_aside: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {'block': self.block, 'type': self.type, 'target': self.target, 'yaw': self.yaw,
                'cells': self.cells, 'unit': self.unit, 'cell': self.cell, 'rotation': self.rotation,
                'grasp': {'unit': self.grasp[0], 'yaw': self.grasp[1], 'span': _span(self.grasp)},
                'position': self.position,
                **({'moved_aside': self.moved_aside} if self.moved_aside else {}),
                **(self.motion or {'trajectories': [], 'gripper': []})}

    def scene_after(self, scene: Scene) -> Scene:
        """The scene once this step is done: the blocks it moved aside, then its block, at their new poses."""
        for d in self.moved_aside:
            scene = moved(scene, d['block'], d['position'], d['yaw'])
        return moved(scene, self.block, self.position, self.yaw)

    @classmethod
    def from_dict(cls, d: dict) -> PlanStep:
        """The step of a `to_dict` form (the inverse: from_dict(s.to_dict()) == s).

        Converts, does not validate: a missing required key raises KeyError, a value of the
        wrong kind TypeError, ValueError or AttributeError (rad_core.view.viz.parse_plan checks
        plan_json first and names what is wrong).
        """
        grasp = d.get('grasp') or {}
        return cls(str(d['block']), str(d['type']), str(d['target']), int(d['yaw']),
                   [[int(v) for v in c] for c in d['cells']], int(d.get('unit', 0)),
                   [int(v) for v in d.get('cell', ())], int(d.get('rotation', 0)),
                   (int(grasp.get('unit', 0)), int(grasp.get('yaw', 0)), int(grasp.get('span', 1))),
                   [float(v) for v in d.get('position', ())],
                   {'trajectories': d['trajectories'], 'gripper': d.get('gripper') or []}
                   if d.get('trajectories') else None,
                   [{'block': str(s['block']), 'position': [float(v) for v in s['position']], 'yaw': int(s['yaw'])}
                    for s in d.get('moved_aside') or []])

    def final_joints(self) -> np.ndarray:
        """The 9 joints (arm, fingers) where this step's motion leaves the robot."""
        return Motion.from_dict(self.motion).final_joints()


@dataclass
class AssemblyPlan:
    success: bool
    reason: str
    scene: Scene
    allocation: AllocationResult | None = None
    steps: list[PlanStep] = field(default_factory=list)
    predicted_coverage: float = 0.0
    final_scene: Scene | None = None
    timings: dict = field(default_factory=dict)
    reallocations: list = field(default_factory=list)   # sequencing.planning.reallocation.Reallocation, in order
    episode: Episode | None = None
    """The planning copy's MDP episode: discounted return, outcome (an unverified agent's
    first action that GAMP or the stability check refuses ends it invalid: f_g / f_p), steps."""
    anytime: list = field(default_factory=list)
    """An agent's planning (`agent_plan.plan_for_agent`): after the first plan and after each
    stage that planned, {'t': seconds since the start, 'coverage': the best predicted coverage so
    far, 'plan': the stage that made the best plan so far: 'scorer' or 'search' (the first plan),
    or a stage's name (`agent.stages.STAGES`)}; one entry for an agent that plans once, none from
    `plan_assembly` called directly."""
    conflicts: list = field(default_factory=list)
    """`Precedence`s this plan's failures teach: an action GAMP refused because the arm hit a
    block the plan had placed, on cells the plan left unfilled (order repair reads them)."""


Allocate = Callable[[Scene], AllocationResult]
PlanMotion = Callable[[Scene, SceneAction, 'np.ndarray | None'], MotionPlan]
# (scene state, allocation placements, start joints or None) -> a sequencing.decide.sequencer.Ranking
Rank = Callable[[Scene, list, 'np.ndarray | None'], Any]


def moved(scene: Scene, block_id: str, position, yaw: int) -> Scene:
    """The scene with one block at a new pose (validated like any scene); its measured offset, if it
    had one, is gone (it is where it was put now, as far as anyone knows)."""
    blocks = tuple(Block(b.id, b.type, tuple(round(float(v), 6) for v in position), int(yaw) % 360)
                   if b.id == block_id else b for b in scene.blocks)
    offsets = {k: v for k, v in scene.measured_offsets.items() if k != block_id}
    feeder = scene.feeder.without(block_id) if scene.in_feeder(block_id) else scene.feeder
    return Scene.from_dict(replace(scene, blocks=blocks, measured_offsets=offsets, feeder=feeder).to_dict())


def plan_assembly(scene: Scene, allocate: Allocate, plan_motion: PlanMotion, sequencer: Policy | Rank,
                  seed: int = 0, start=None, time_limit_s: float = 60.0, reallocate=None,
                  reallocation=None, verify: bool = True, precedences=(), pace: dict | None = None,
                  drops: bool = False) -> AssemblyPlan:
    """sequencer: a Policy (in-process scores of the MDP state) or a Rank callable.
    A Rank callable's RadError (say, the sequencer node is down) propagates.
    reallocate: (scene state, no-goods, time limit) -> AllocationResult, to re-allocate on
    stall (None: never); reallocation: its `ReallocationConfig` (default: the defaults).
    verify: take the best-ranked action GAMP finds feasible (the default); False: the
    best-ranked one only, and the plan stops where it cannot be done (the paper's agents).
    precedences: `Precedence`s a verified plan keeps to where the ranking allows
    (`precedences_last`; order repair passes what an earlier plan's `conflicts` taught).
    time_limit_s: a deadline from the call: no ranking or motion is asked for that would end after
    it (as long as such calls took on average), nor a re-allocation once it has passed; the plan so
    far comes back, its `reason` saying the limit ended it (the allocation is the caller's to bound:
    `allocate` is called first, as it is). pace: {'rank': [seconds, count], 'motion': [...]} of the
    calls made so far, updated here (plans of one agent's planning share it; default: this plan's).
    drops: whether the plan may take an action GAMP can only drop in (`GampConfig.drop`); False (the
    default): GAMP is asked to set blocks down (`set_down`), and a drop it answers anyway counts as
    infeasible (`policy.first_feasible`)."""
    t0 = time.perf_counter()
    if not drops:
        plan_motion = set_down(plan_motion)
    timings = {'allocation': 0.0, 'sequencing': 0.0, 'motion': 0.0}
    allocation = allocate(scene)
    timings['allocation'] = time.perf_counter() - t0
    plan = AssemblyPlan(False, '', scene, allocation, final_scene=scene, timings=timings)
    if not allocation.has_solution:
        plan.reason = f'allocation failed: {allocation.status}' + (
            ' (CP-SAT found none within its time limit)' if allocation.status == 'UNKNOWN' else '')
        return _done(plan, t0)
    # The plan's MDP judges stability as the learned agents' does (physics, after a prune of blocks
    # resting on nothing): the sequencer and its search judge the actions they checked, but a ranking
    # goes on below them, and an action taken from there must not put a block where it tips or falls.
    env = AssemblyEnv(scene, EnvConfig(stability='physics'), stability=_STABILITY)
    if not allocation.placements and (env.grid.is_target & (env.state.occupancy < 0)).any():
        arm = getattr(allocation, 'arm', None)
        plan.reason = 'the allocation places no block' + (f' (what the arm cannot do: {arm.summary()})'
                                                          if arm is not None else '')
        if allocation.status != 'OPTIMAL' and time.perf_counter() - t0 >= time_limit_s:
            # CP-SAT cut short answers with its first solution, which may be the empty one.
            plan.reason = (f'time limit of {time_limit_s:g} s reached: the allocation placed no block '
                           f'within it ({allocation.status})')
        return _done(plan, t0)
    run = _Planning(plan, env, plan_motion, sequencer, start, verify, precedences, t0 + time_limit_s, pace, drops)
    reallocator = None
    if reallocate is not None:
        reallocator = Reallocator(run.allowed, run.pose_check, reallocation or ReallocationConfig(),
                                  scene_of=lambda _: run.world['scene'], allocate=reallocate, deadline=run.deadline)
    episode = plan.episode = run.episode(reallocator, seed)
    if reallocator is not None:
        plan.reallocations = reallocator.events
        timings['reallocation'] = reallocator.seconds
    if episode.timed_out:
        plan.reason = f'time limit of {time_limit_s:g} s reached after {len(plan.steps)} steps'
    else:
        plan.reason = episode.reason
    plan.final_scene = run.world['scene']
    plan.predicted_coverage = env.coverage()
    open_cells = env.state.occupancy < 0
    plan.conflicts = [p for p in run.seen if open_cells[list(p.first)].any()]
    plan.success = not plan.reason and not run.allowed.guide.open_poses(env.state)
    if not plan.success and not plan.reason:
        plan.reason = 'allocated poses remain unbuilt'
    return _done(plan, t0)


def new_pace() -> dict:
    """`plan_assembly`'s pace before any call: {'rank': [seconds, count], 'motion': [seconds, count]}."""
    return {'rank': [0.0, 0], 'motion': [0.0, 0]}


class _OutOfTime(Exception):
    """The plan's deadline passed before a ranking or a motion it needed (`_Planning.episode` ends there)."""


class _Planning:
    """One `plan_assembly` call under way: the planning copy (its MDP `env`, and `world`: the scene
    and the arm joints), the plan so far, and the sequencer's and GAMP's answers in this state."""

    def __init__(self, plan: AssemblyPlan, env: AssemblyEnv, plan_motion: PlanMotion, sequencer, start,
                 verify: bool, precedences, deadline: float, pace: dict | None = None, drops: bool = True):
        self.plan, self.env, self.timings = plan, env, plan.timings
        self.drops = drops
        # Where the fingers crowd every neighbour (a 2 cm unit: `grasps.beside_blocks`), nearly every block
        # is dropped in: waiting for one set down would cost `DROP_LOOKAHEAD` checks a step and find none.
        scene = plan.scene
        self.lookahead = 0 if beside_blocks(0, scene.unit, scene.clearance) else DROP_LOOKAHEAD
        self.allowed = AllocationActions(env, plan.allocation.placements)   # its guide changes on re-allocation
        self.world = {'scene': plan.scene, 'q': start}
        self.sequencer, self.verify, self.precedences, self.deadline = sequencer, verify, precedences, deadline
        self.rank = self.rank_by_policy if hasattr(sequencer, 'scores') else self.rank_by_sequencer
        self.asked: dict = {}   # the sequencer's last answer, and the step and allocation it answered for
        # GAMP's answers from the current planning state (the state changes only with a step):
        # a re-allocation's checks reuse what the step's own choice already planned.
        self.memo: dict = {}
        self.plan_motion = plan_motion
        # Motion planners that can move blocks aside (the in-process one, the gamp node's client) are asked to.
        self.aside = {'move_aside': True} if 'move_aside' in inspect.signature(plan_motion).parameters else {}
        self.seen: dict = {}    # Precedence -> None: what GAMP's refusals named, in order
        self.pace = pace if pace is not None else new_pace()

    def in_time(self, call: str) -> None:
        """Raise `_OutOfTime` where a `call` ('rank' or 'motion') as long as such calls take on
        average (`pace`) would end past the deadline."""
        seconds, count = self.pace[call]
        if time.perf_counter() + (seconds / count if count else 0.0) > self.deadline:
            raise _OutOfTime

    def timed(self, call: str, ask, *args, **kw):
        """ask(*args, **kw), its time counted in `pace` (not an answer from memory: under 1 ms)."""
        ts = time.perf_counter()
        answer = ask(*args, **kw)
        seconds = time.perf_counter() - ts
        if seconds >= 1e-3:
            self.pace[call][0] += seconds
            self.pace[call][1] += 1
        return answer

    def rank_by_policy(self, env: AssemblyEnv, allowed, rng, fallbacks: bool) -> list | str:
        ts = time.perf_counter()
        ranked = ranked_actions(self.sequencer, env, allowed, rng, fallbacks=fallbacks)
        self.timings['sequencing'] += time.perf_counter() - ts
        if fallbacks:
            return ranked or 'no fallback'
        if not ranked:
            left = len(self.allowed.guide.open_poses(env.state))
            return (f'{left} allocated poses left, none of them can be built next '
                    f'({getattr(self.sequencer, "why_none", self.sequencer.name + " values stopping more")})')
        return ranked

    def rank_by_sequencer(self, env: AssemblyEnv, allowed, rng, fallbacks: bool) -> list | str:
        asked, guide = self.asked, self.allowed.guide
        if asked.get('steps') != len(self.plan.steps) or asked.get('guide') is not guide:
            # (the fallbacks come from the answer the plan just had)
            self.in_time('rank')
            ts = time.perf_counter()
            ranking = self.timed('rank', self.sequencer, self.world['scene'], list(guide.placements), self.world['q'])
            self.timings['sequencer_call'] = self.timings.get('sequencer_call', 0.0) + time.perf_counter() - ts
            self.timings['sequencing'] += float(ranking.timings.get('sequencing', 0.0))
            asked.update(steps=len(self.plan.steps), guide=guide, ranking=ranking)
        ranking = asked['ranking']
        preferred = len(ranking.actions) - ranking.fallbacks
        if fallbacks:
            return mdp_actions(env, ranking.actions[preferred:], allowed) or 'no fallback'
        if not preferred or (ranking.terminate and not self.verify):
            return ranking.reason or 'the sequencer proposes to stop'
        ranked = mdp_actions(env, ranking.actions[:preferred], allowed)
        return ranked or (f'the sequencer proposed {preferred} actions, none of them among the '
                          f'{len(allowed)} the allocation allows now')

    def planned_motion(self, scene_now: Scene, action: SceneAction, q) -> MotionPlan:
        """GAMP's answer; a pick its neighbours on the table block is planned with them moved aside
        first, where the motion planner can (`MotionPlanner`'s move_aside)."""
        key = (len(self.plan.steps), action)
        if key not in self.memo:
            self.in_time('motion')
            if len(self.memo) > 4096:
                self.memo.clear()
            self.memo[key] = self.timed('motion', self.plan_motion, scene_now, action, q, **self.aside)
            self.timings['gamp'] = self.timings.get('gamp', 0.0) + self.memo[key].seconds
        return self.memo[key]

    def check_motion(self, env: AssemblyEnv, scene_now: Scene, action, q) -> MotionPlan:
        """`_checked_motion`, noting the placed blocks a refusal names (`conflicts_of`)."""
        motion = _checked_motion(env, scene_now, action, self.planned_motion, q, self.timings)
        if not motion.success and motion.failure != 'stability':
            for p in conflicts_of(env, action, motion.reason):
                self.seen.setdefault(p, None)
        return motion

    def pose_check(self, action) -> MotionPlan:
        """What the plan's own steps are held to (`_checked_motion`), for a re-allocation's checks: a
        pose whose block would tip the structure is as much a no-good as one the arm cannot reach. A plan
        that takes no drops refuses a pose GAMP can only drop in (`policy.first_feasible`)."""
        found = self.check_motion(self.env, self.world['scene'], action, self.world['q'])
        return found if self.drops or not found.success or found.drop <= 0 else refused(found)

    def decide(self, env: AssemblyEnv, rng, fallbacks: bool = False) -> Decision:
        """The best feasible action the sequencer ranks above stopping; fallbacks: of those it
        ranks below (a verified plan's last resort, `deciders.with_fallbacks`)."""
        allowed = self.allowed(env)
        if not allowed:
            return stop()
        ranked = self.rank(env, allowed, rng, fallbacks)
        if isinstance(ranked, str):
            return stop(ranked)
        if self.verify and PIT_LAYERS:
            ranked = pits_last(env, self.allowed.guide, ranked)
        if self.verify and self.precedences:
            ranked = precedences_last(env, ranked, self.precedences)
        found = _first_feasible(env, self.world['scene'], ranked if self.verify else ranked[:1], self.check_motion,
                                self.world['q'], book=not self.verify, drops=self.drops, lookahead=self.lookahead)
        if isinstance(found, str):
            return stop(found)
        action, step = found
        return Decision(action, step)

    def act(self, decision: Decision):
        if isinstance(decision.plan, MotionPlan):        # unverified: the best-ranked action cannot be done
            return _book_failure(self.env, decision.action, decision.plan)
        result = self.env.step(decision.action)
        if decision.plan is not None:
            step = decision.plan
            self.plan.steps.append(step)
            self.world['scene'] = step.scene_after(self.world['scene'])
            self.world['q'] = step.final_joints()
        return result

    def episode(self, reallocator: Reallocator | None, seed: int) -> Episode:
        """The planning copy's episode, deciding with re-allocation where there is a `reallocator` and
        with the fallbacks where verified; one the deadline cut is `timed_out`."""
        decided = with_reallocation(self.decide, reallocator) if reallocator is not None else self.decide
        if self.verify:
            decided = with_fallbacks(self.decide, decided)   # below stopping only where nothing else is left
        results: list = []
        try:
            return run_episode(self.env, decided, np.random.default_rng(seed), self.act,
                               on_step=lambda _, result: results.append(result), deadline=self.deadline)
        except _OutOfTime:      # within a step: the plan is as the last step left it
            gamma = self.env.config.gamma
            return Episode(sum(r.reward * gamma ** k for k, r in enumerate(results)),
                           results[-1].outcome if results else None, self.env.state.steps, self.env.coverage(),
                           timed_out=True)


class _SharedStability:
    """One PyBullet stability check for the process, used by one thread at a time: a client per plan
    or per thread would pile up in a node that plans for days (measured: +180 MB over 240 requests)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._judge = None

    def __call__(self, *args, **kw):
        with self._lock:
            if self._judge is None:
                self._judge = PhysicsStability()
            return self._judge(*args, **kw)


_STABILITY = _SharedStability()


PIT_LAYERS = 1
"""`pits_last`: how many layers above the top of an open allocated pose beside it a block may reach
before its action is tried after the others (0: never reordered)."""
PIT_REACH = 2.0
"""`pits_last`: 'beside', in units between cell centres horizontally (the palm reaches 10 cm, two
5 cm units, to either side of the fingers)."""


def pits_last(env: AssemblyEnv, guide, ranked: list) -> list:
    """The ranking with the actions that would dig a pit tried last (in their ranked order).

    A top-down hand carries its palm a unit or so above the top of the block it places, reaching
    two units to either side, and its wrist (link6, link7) above that. So a block whose top rises
    PIT_LAYERS layers or more above the top of an allocated pose still open beside it (a cell
    centre within PIT_REACH units horizontally: the next columns, or the other face of a two-deep
    wall) leaves that pose in a pit the hand cannot reach into; GAMP then refuses it ('hand hits
    block ...', 'link6 hits block ...'). Ranked as they are otherwise, such actions come after
    every other the ranking holds: lower poses first where the ranking allows it."""
    state, grid, u = env.state, env.grid, env.scene.unit
    open_cells = [guide.pose_cells[k] for k in guide.open_poses(state)]
    if not open_cells or len(ranked) < 2:
        return ranked
    tops = np.array([grid.centres[c][:, 2].max() for c in open_cells])
    flat_open = np.concatenate(open_cells)                 # every open pose's cells, pose by pose
    owner = np.concatenate([np.full(len(c), k) for k, c in enumerate(open_cells)])
    xy = grid.centres[flat_open][:, :2]
    keep, later = [], []
    for action in ranked:
        cells, _ = env.resulting_cells(action)
        if cells is None:
            keep.append(action)
            continue
        pts = grid.centres[cells]
        close = np.min(np.linalg.norm(xy[None, :, :] - pts[:, None, :2], axis=2), axis=0) <= PIT_REACH * u + 1e-9
        near = np.zeros(len(open_cells), dtype=bool)
        near[owner[close]] = True
        deep = (pts[:, 2].max() - tops) >= PIT_LAYERS * env.scene.course - 1e-9
        mine = np.zeros(len(open_cells), dtype=bool)      # open poses the action itself fills part of
        mine[owner[np.isin(flat_open, cells)]] = True
        (later if np.any(near & deep & ~mine) else keep).append(action)
    return keep + later


def conflicts_of(env: AssemblyEnv, action, reason: str) -> list[Precedence]:
    """The precedences a refusal of `action` (GAMP's `reason`) teaches: one per placed block it
    names ('hand hits block b3', 'carried block hits block b5', ...)."""
    names = blocks_named(reason)
    if not names:
        return []
    cells, _ = env.resulting_cells(action)
    if cells is None:
        return []
    first = tuple(sorted(int(c) for c in cells))
    index = {b.id: k for k, b in enumerate(env.scene.blocks)}
    found = []
    for name in sorted(names):
        k = index.get(name)
        if k is not None and k in env.state.placed:
            found.append(Precedence(first, tuple(sorted(int(c) for c in env.state.placed[k][0])), reason))
    return found


def precedences_last(env: AssemblyEnv, ranked: list, precedences) -> list:
    """The ranking with the actions that would break a precedence tried last (in their ranked
    order): an action that puts a block on a `then` cell while a `first` cell it does not fill
    itself is still open. A soft order, as `pits_last`: such an action is still taken when nothing
    ranked before it can be done."""
    open_cells = env.state.occupancy < 0
    firsts: dict[int, list[tuple]] = {}          # a `then` cell -> the `first` cells of its active precedences
    for p in precedences:
        if open_cells[list(p.first)].any():
            for c in p.then:
                firsts.setdefault(int(c), []).append(p.first)
    if not firsts or len(ranked) < 2:
        return ranked
    keep, later = [], []
    for action in ranked:
        cells, _ = env.resulting_cells(action)
        mine = frozenset() if cells is None else frozenset(int(c) for c in cells)
        breaks = any(open_cells[c] and c not in mine for t in mine for first in firsts.get(t, ()) for c in first)
        (later if breaks else keep).append(action)
    return keep + later


def _checked_motion(env: AssemblyEnv, scene: Scene, action, plan_motion: PlanMotion, q, timings) -> MotionPlan:
    """An action checked as a plan's step is: the stability check first (no motion for a block
    that falls), then GAMP's motion (its time added to timings['motion'])."""
    outcome, why, _, _ = env.evaluate(action)
    if outcome is not None:
        return MotionPlan(False, 'stability', why)
    ts = time.perf_counter()
    motion = plan_motion(scene, scene_action(env, action), q)
    timings['motion'] += time.perf_counter() - ts
    return motion


def _first_feasible(env: AssemblyEnv, scene: Scene, ranked, check_motion, q, book: bool = False,
                    drops: bool = True, lookahead: int = DROP_LOOKAHEAD):
    """(action, PlanStep) of the best-ranked action GAMP can execute, or why none.
    check_motion(env, scene, action, q): `_checked_motion` with the plan's motion planner. book (an
    unverified agent, given its one best-ranked action): a failure comes back as (action,
    its failed MotionPlan), for the episode to book it."""
    def check(action) -> MotionPlan:
        return check_motion(env, scene, action, q)

    action, motion, failed = first_feasible(env, ranked, check, drops, lookahead)
    if action is None and book and failed:
        return ranked[0], failed[0][1]      # unverified: the one action, and why it fails (booked by act)
    if action is None:
        failures = [f'{scene.blocks[a.block].id}: {m.reason}' for a, m in failed]
        shown = '; '.join(failures[:3]) + (f'; and {len(failures) - 3} more' if len(failures) > 3 else '')
        return f'no feasible next action ({len(failures)} tried): {shown}'
    cells, yaw = env.resulting_cells(action)
    _, ijk = env.grid.region_cells(cells)
    req, block = scene_action(env, action), scene.blocks[action.block]
    anchor = env.grid.centres[cells[0]]   # cells are in unit order: the first is the anchor's
    return action, PlanStep(block.id, block.type, req.target, int(yaw), ijk, action.unit, list(req.cell),
                            action.rotation, motion.grasp, [float(v) for v in anchor], motion.motion,
                            list(motion.moved_aside))


def _book_failure(env: AssemblyEnv, action, motion: MotionPlan):
    """The MDP step of an action that cannot be done, as the robot env books it: the stability
    check's own outcome, else a failed grasp (f_g) or a failed placement motion (f_p)."""
    if motion.failure == 'stability':
        return env.step(action)
    cells, _ = env.resulting_cells(action)
    failure = Outcome.INVALID_GRASP if motion.failure == 'grasp' else Outcome.INVALID_PLACEMENT
    return env.fail(failure, motion.reason, cells)


def _done(plan: AssemblyPlan, t0: float) -> AssemblyPlan:
    plan.timings['total'] = time.perf_counter() - t0
    return plan


def set_down(plan_motion: PlanMotion) -> PlanMotion:
    """plan_motion asking GAMP for no drops (its `set_down`, where it takes one: `GampConfig.drop`)."""
    if 'set_down' not in inspect.signature(plan_motion).parameters:
        return plan_motion

    def planned(scene, action, start, move_aside: bool = False):
        return plan_motion(scene, action, start, move_aside=move_aside, set_down=True)
    return planned


def local_motion_planner(planner) -> PlanMotion:
    """Adapt an in-process `gamp.action.MotionPlanner` to the PlanMotion signature."""
    def plan_motion(scene: Scene, action: SceneAction, start, move_aside: bool = False,
                    set_down: bool = False) -> MotionPlan:
        t0 = time.perf_counter()
        result, _, _ = planner(scene, action, start=start, move_aside=move_aside, set_down=set_down)
        if not result.success:
            return MotionPlan(False, result.failure, result.reason, seconds=time.perf_counter() - t0)
        return MotionPlan(True, '', result.reason if result.drop else '',
                          (int(result.grasp.unit), int(result.grasp.yaw), int(result.grasp.span)),
                          result.motion.to_dict(), list(result.moved_aside), seconds=time.perf_counter() - t0,
                          drop=result.drop)
    return plan_motion

"""Take a built structure apart, back onto the table: a plan of its own, every motion verified.

A cell that builds, takes apart and builds again with nothing touched by hand needs
the way back as much as the way there. `plan_take_apart` plans it from a registered
scene, one block at a time on a planning copy, like `sequencing.planning.plan.plan_assembly`:

- which block next: only a block with nothing resting on it (`resting_on`), the
  reverse of the build order where it is known, else the highest first;
- where it goes: its pose in the heap it came from (the start scene) when that spot
  is free (a block that can go straight back comes before one that cannot), else the
  nearest free table spot (`TableConfig`): within the arm's reach, away from the
  robot's base and the target regions, a finger's room from every other block and
  from the heap spots the others will go back to;
- how: GAMP picks the block where it lies and places its anchor at that pose (a
  `PlacePlanner`: `local_place_planner` in-process, /plan_action with a place pose
  over ROS); the first block and spot GAMP finds feasible is taken.

`take_apart` runs that plan on a plant through the execute loop
(`sequencing.execution.execute.execute_assembly`): the same arm and gripper callables, each
step verified against the registered world, a re-plan from what is seen when a
step deviates (bounded). Its `TakeApartResult` says what the heap looks like again:
blocks lost (in the heap, not seen at the end) and each block's drift (how far it
ended from its heap pose).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from rad_core.cell.mocap import Registration
from rad_core.domain.coverage import measured_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.gamp.planner import plan_action
from rad_core.sequencing.execution.execute import ExecuteConfig, ExecutionResult, Report, execute_assembly
from rad_core.sequencing.planning.plan import AssemblyPlan, MotionPlan, PlanStep, moved

# (scene state, block id, anchor position, yaw in degrees, start joints or None) -> the motion
PlacePlanner = Callable[[Scene, str, list, int, 'np.ndarray | None'], MotionPlan]


@dataclass(frozen=True)
class TableConfig:
    """Where a block may be put down on the table (robot base frame, metres)."""

    reach: float = 0.77
    """Every unit centre within this horizontal distance of the base (the generator's reach)."""
    base_clearance: float = 0.3
    """... and at least this far from it (the arm's own column)."""
    region_margin: float = 0.05
    """Kept free around every target region's footprint."""
    gap: float = 0.04
    """Free room between a put-down block's units and any other block's (the open fingers need it)."""
    x_range: tuple[float, float] = (0.2, 0.8)
    y_range: tuple[float, float] = (-0.75, 0.75)
    spot_step: float = 0.025
    """Pitch of the candidate spots."""
    max_spots: int = 4
    """GAMP tries at most this many spots per block (its heap spot first)."""
    max_blocks: int = 6
    """... and at most this many removable blocks before a plan gives up."""
    position_tol: float = 0.01
    """A block put down within this (m) of its spot counts as where the plan put it (the execute loop's
    tolerance is raised to it). Table spots are not cells: registration snaps nothing there, so a few mm
    of placement error would otherwise cost a re-plan, while the other blocks keep `gap` of room and
    every new plan starts from what is seen anyway. Blocks in the target regions snap to cells, so
    there a deviation is a unit or nothing."""
    recount: int = 3
    """A heap block not seen at the end is looked for in this many more motion-capture frames (a
    body dropped from a frame or two is not lost)."""

    def validate(self) -> None:
        values = (self.reach, self.base_clearance, self.region_margin, self.gap, self.spot_step,
                  *self.x_range, *self.y_range)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise RadError('table config: every distance must be a finite number')
        if not (0 <= self.base_clearance < self.reach and self.spot_step > 0 and self.gap >= 0
                and self.region_margin >= 0):
            raise RadError(f'table config: needs 0 <= base_clearance < reach, spot_step > 0, gap and '
                           f'region_margin >= 0 (got {self.base_clearance}, {self.reach}, {self.spot_step}, '
                           f'{self.gap}, {self.region_margin})')
        if self.x_range[0] >= self.x_range[1] or self.y_range[0] >= self.y_range[1]:
            raise RadError(f'table config: empty x_range {self.x_range} or y_range {self.y_range}')
        if not (math.isfinite(self.position_tol) and 0 < self.position_tol < 0.05) or self.recount < 0:
            raise RadError(f'table config: position_tol must be in (0, 0.05) m and recount >= 0, got '
                           f'{self.position_tol}, {self.recount}')
        if self.max_spots < 1 or self.max_blocks < 1:
            raise RadError(f'table config: max_spots and max_blocks must be >= 1, got {self.max_spots}, '
                           f'{self.max_blocks}')


# ---- the structure --------------------------------------------------------------------

def _in_regions(scene: Scene, points: np.ndarray, margin: float = 0.0) -> bool:
    """Whether any of the points lies over a target region's footprint (grown by margin)."""
    for t in scene.targets:
        lo, hi = t.bounds(scene.pitch)
        if np.any(np.all((points[:, :2] > lo[:2] - margin) & (points[:, :2] < hi[:2] + margin), axis=1)):
            return True
    return False


def to_take_apart(scene: Scene) -> list[str]:
    """Blocks still to take apart: those in a target region, or standing on another block."""
    c = scene.course
    out = []
    for b in scene.blocks:
        pts = scene.unit_positions(b)
        if _in_regions(scene, pts) or pts[:, 2].min() > c / 2 + 0.25 * c:
            out.append(b.id)
    return out


def resting_on(scene: Scene) -> dict[str, set[str]]:
    """Block id -> ids of the blocks resting directly on it (a unit one level up, over one of its units)."""
    u, c = scene.unit, scene.course
    units = {b.id: scene.unit_positions(b) for b in scene.blocks}
    out: dict[str, set[str]] = {b.id: set() for b in scene.blocks}
    for below, pb in units.items():
        for above, pa in units.items():
            if above == below:
                continue
            d = pa[:, None, :] - pb[None, :, :]
            on = (np.abs(d[..., 2] - c) < 0.25 * c) & np.all(np.abs(d[..., :2]) < 0.99 * u, axis=-1)
            if on.any():
                out[below].add(above)
    return out


def removal_order(scene: Scene, pending, build_order=()) -> list[str]:
    """The pending blocks that can be taken now (nothing rests on them), best first: the reverse of
    the build order where known, then the highest top first."""
    on = resting_on(scene)
    built = {bid: n for n, bid in enumerate(build_order)}
    free = [bid for bid in pending if not on.get(bid)]

    def key(bid):
        top = float(scene.unit_positions(scene.block(bid))[:, 2].max())
        return (0, -built[bid], 0.0, bid) if bid in built else (1, 0, -top, bid)
    return sorted(free, key=key)


# ---- the table ------------------------------------------------------------------------

def _units_at(scene: Scene, block_id: str, position, yaw: int) -> np.ndarray:
    btype = scene.block_types[scene.block(block_id).type]
    return np.asarray(position, dtype=float) + scene.pitch * btype.rotated(yaw)


def _on_table(scene: Scene, block_id: str, xy, yaw: int) -> np.ndarray:
    """The anchor position that puts the block down on the table at anchor x, y and yaw."""
    low = scene.block_types[scene.block(block_id).type].rotated(yaw)[:, 2].min()
    return np.array([xy[0], xy[1], scene.course / 2 - low * scene.course])


def _room(scene: Scene, pts: np.ndarray, others: list[np.ndarray], gap: float) -> bool:
    """Whether units `pts` keep `gap` of free room (side by side) from every unit in `others`."""
    reach = scene.unit + gap - 1e-9
    for o in others:
        d = np.abs(pts[:, None, :] - o[None, :, :])
        if np.any(np.all(d[..., :2] < reach, axis=-1) & (d[..., 2] < scene.course)):
            return False
    return True


def _spot_ok(scene: Scene, pts: np.ndarray, others: list[np.ndarray], config: TableConfig) -> bool:
    r = np.hypot(pts[:, 0], pts[:, 1])
    return bool(np.all(r <= config.reach) and np.all(r >= config.base_clearance)
                and not _in_regions(scene, pts, config.region_margin + scene.unit / 2)
                and _room(scene, pts, others, config.gap))


def return_poses(scene: Scene, block_id: str, heap: Scene, config: TableConfig = TableConfig()
                 ) -> list[tuple[np.ndarray, int]]:
    """Where a block may go back to, best first (anchor position, yaw): its heap pose when free,
    then the free table spots nearest to it (at most config.max_spots in all)."""
    current = {b.id: b for b in scene.blocks}
    in_heap = {b.id for b in heap.blocks if b.id in current and b.type == current[b.id].type}
    home = heap.block(block_id) if block_id in in_heap else current[block_id]
    others = [scene.unit_positions(b) for b in scene.blocks if b.id != block_id]
    out = []
    heap_pts = _units_at(scene, block_id, home.position, home.yaw)
    if block_id in in_heap and _room(scene, heap_pts, others, 0.0) and not _in_regions(scene, heap_pts):
        out.append((np.asarray(home.position, dtype=float), int(home.yaw)))
    # The heap spots of the other blocks not yet back stay free for them.
    reserved = [_units_at(scene, b.id, b.position, b.yaw) for b in heap.blocks
                if b.id != block_id and b.id in current and current[b.id].position != b.position]
    xs = np.arange(config.x_range[0], config.x_range[1] + 1e-9, config.spot_step)
    ys = np.arange(config.y_range[0], config.y_range[1] + 1e-9, config.spot_step)
    grid = np.array([(x, y) for x in xs for y in ys])
    grid = grid[np.argsort(np.hypot(*(grid - np.asarray(home.position[:2])).T), kind='stable')]
    yaws = list(dict.fromkeys((int(home.yaw), int(current[block_id].yaw))))
    # The nearest free spots, at least two units apart (GAMP may fail on one for a reason its
    # neighbour shares).
    for xy in grid:
        if len(out) >= config.max_spots:
            break
        if any(np.hypot(*(xy - pos[:2])) < 2 * scene.unit for pos, _ in out):
            continue
        for yaw in yaws:
            pos = _on_table(scene, block_id, xy, yaw)
            if _spot_ok(scene, _units_at(scene, block_id, pos, yaw), others + reserved, config):
                out.append((pos, yaw))
                break
    return out[:config.max_spots]


# ---- the plan -------------------------------------------------------------------------

def plan_take_apart(scene: Scene, heap: Scene, plan_place: PlacePlanner, start=None, build_order=(),
                    config: TableConfig = TableConfig(), time_limit_s: float = 60.0) -> AssemblyPlan:
    """Plan taking every block off the structure of `scene` back onto the table (see the module docstring).

    heap: the start scene the blocks came from (same ids). The plan's steps are `PlanStep`s with
    target '' and no cells (the table is no grid); success when nothing is left to take apart.
    plan_place's RadError (a planner that is down) propagates.
    """
    config.validate()
    t0 = time.perf_counter()
    deadline = t0 + time_limit_s
    current, q = scene, None if start is None else np.asarray(start, dtype=float)
    plan = AssemblyPlan(False, '', scene, final_scene=scene, timings={'motion': 0.0})
    reason = ''
    while True:
        pending = to_take_apart(current)
        if not pending:
            break
        if time.perf_counter() > deadline:
            reason = f'time limit of {time_limit_s:g} s reached after {len(plan.steps)} steps'
            break
        order = removal_order(current, pending, build_order)
        if not order:
            reason = f'{len(pending)} blocks left, each with another resting on it'
            break
        found, failures = _next_block(current, order[:config.max_blocks], heap, plan_place, q, config,
                                      plan.timings)
        if found is None:
            shown = '; '.join(f'{bid} {why}' for bid, why in failures.items())
            reason = f'no block can be taken off next ({len(pending)} left; first spot tried each): {shown}'
            break
        bid, pos, yaw, motion = found
        block = current.block(bid)
        step = PlanStep(bid, block.type, '', int(yaw) % 360, [], position=[float(v) for v in pos],
                        grasp=motion.grasp, motion=motion.motion)
        plan.steps.append(step)
        current = moved(current, bid, pos, yaw)
        q = step.final_joints()
    plan.final_scene, plan.reason, plan.success = current, reason, not reason
    plan.predicted_coverage = measured_coverage(current)
    plan.timings['total'] = time.perf_counter() - t0
    return plan


def _next_block(current: Scene, order: list[str], heap: Scene, plan_place: PlacePlanner, q, config: TableConfig,
                timings: dict) -> tuple[tuple | None, dict[str, str]]:
    """The first (block, position, yaw, motion) GAMP finds feasible, and each block's first failure.

    First pass: a block that can go straight back to its heap pose; second: any free spot.
    """
    failures: dict[str, str] = {}
    for home_only in (True, False):
        for bid in order:
            if failures.get(bid, '').startswith('cannot be picked'):
                continue
            poses = return_poses(current, bid, heap, config)
            home_first = bool(poses) and _is_home(heap, bid, poses[0])
            if home_only:
                poses = poses[:1] if home_first else []
            elif home_first and bid in failures:
                poses = poses[1:]     # its heap pose was tried in the first pass
            failures.setdefault(bid, 'no free spot on the table')
            for pos, yaw in poses:
                ts = time.perf_counter()
                motion = plan_place(current, bid, [float(v) for v in pos], int(yaw), q)
                timings['motion'] += time.perf_counter() - ts
                if motion.success:
                    return (bid, pos, yaw, motion), failures
                if motion.failure == 'grasp':
                    # It cannot be picked where it lies: no other spot changes that.
                    failures[bid] = f'cannot be picked: {motion.reason}'
                    break
                if failures[bid] == 'no free spot on the table':
                    failures[bid] = f'to ({pos[0]:.3f}, {pos[1]:.3f}) m: {motion.reason}'
    return None, failures


def _is_home(heap: Scene, block_id: str, pose) -> bool:
    ids = {b.id for b in heap.blocks}
    if block_id not in ids:
        return False
    home = heap.block(block_id)
    return int(pose[1]) == int(home.yaw) and bool(np.allclose(pose[0], home.position))


def local_place_planner(planner) -> PlacePlanner:
    """Adapt an in-process `gamp.action.MotionPlanner` (its world and config) to PlacePlanner."""

    def plan_place(scene: Scene, block_id: str, position, yaw: int, start) -> MotionPlan:
        q = planner.load(scene, start)
        result = plan_action(planner.world, block_id, position, float(yaw), start=q, config=planner.config)
        if not result.success:
            return MotionPlan(False, result.failure, result.reason)
        return MotionPlan(True, '', '', (int(result.grasp.unit), int(result.grasp.yaw)), result.motion.to_dict())
    return plan_place


# ---- on the plant ---------------------------------------------------------------------

@dataclass
class TakeApartResult:
    """What a take-apart did: the execute loop's result and the heap it left."""

    run: ExecutionResult
    heap: Scene
    lost: list[str] = field(default_factory=list)          # heap blocks not seen at the end
    drift: dict[str, float] = field(default_factory=dict)  # block id -> m from its heap pose

    @property
    def success(self) -> bool:
        return self.run.success and not self.lost

    @property
    def reason(self) -> str:
        if self.run.reason or not self.lost:
            return self.run.reason
        return f'blocks lost: {", ".join(self.lost)}'

    @property
    def steps(self) -> list[dict]:
        return self.run.steps

    @property
    def failures(self) -> list[dict]:
        """Executed steps that failed (a grasp on nothing), then the run's own reason if it failed."""
        out = [{'step': n, 'block': s['block'], 'failure': s['failure']}
               for n, s in enumerate(self.run.steps) if s.get('failure')]
        if not self.run.success:
            out.append({'step': len(self.run.steps), 'block': '', 'failure': self.run.reason})
        return out

    @property
    def final_scene(self) -> Scene | None:
        return self.run.final_scene

    def drift_stats(self) -> dict:
        """Drift over the blocks seen, in mm: mean and max (0 for none)."""
        values = list(self.drift.values())
        return {'mean_mm': 1e3 * float(np.mean(values)) if values else 0.0,
                'max_mm': 1e3 * float(np.max(values)) if values else 0.0}

    def document(self, timings: dict) -> dict:
        """A rad-result/1 document of the run (no allocation), with the take-apart's own figures."""
        doc = self.run.document(timings)
        doc['take_apart'] = {'success': self.success, 'reason': self.reason, 'replans': self.run.replans,
                             'failures': self.failures, 'lost': list(self.lost),
                             'drift_m': dict(self.drift), 'drift': self.drift_stats(),
                             'remaining': to_take_apart(self.run.final_scene) if self.run.final_scene else []}
        return doc


def drift_from_heap(final: Scene, heap: Scene) -> tuple[list[str], dict[str, float]]:
    """(heap blocks not in final, {block id: distance (m) of its final pose from its heap pose})."""
    seen = {b.id: b for b in final.blocks}
    lost = [b.id for b in heap.blocks if b.id not in seen]
    drift = {b.id: float(np.linalg.norm(np.subtract(seen[b.id].position, b.position)))
             for b in heap.blocks if b.id in seen}
    return lost, drift


def take_apart(scene: Scene, heap: Scene, plan_place: PlacePlanner, move_arm, move_gripper, register,
               config: ExecuteConfig = ExecuteConfig(), table: TableConfig = TableConfig(), build_order=(),
               time_limit_s: float = 60.0, joints: Callable[[], 'np.ndarray | None'] | None = None,
               cancelled: Callable[[], bool] = lambda: False, report: Report | None = None,
               settle: Callable[[float], None] = time.sleep) -> TakeApartResult:
    """Take the structure of `scene` (registered) apart onto the table of `heap` on a plant. Only a
    bad `table` config raises RadError; anything else that goes wrong becomes the result's reason.
    The plant callables and the phases reported are execute_assembly's."""
    table.validate()

    def plan(current: Scene, start) -> AssemblyPlan:
        return plan_take_apart(current, heap, plan_place, start, build_order, table, time_limit_s)

    config = replace(config, position_tol=max(config.position_tol, table.position_tol))
    run = execute_assembly(scene, plan, move_arm, move_gripper, register, config, joints=joints,
                           cancelled=cancelled, report=report, settle=settle)
    result = TakeApartResult(run, heap)
    if run.final_scene is None:
        return result
    result.lost, result.drift = drift_from_heap(run.final_scene, heap)
    for _ in range(table.recount if result.lost else 0):
        settle(0.05)
        try:
            got = register()
        except RadError:
            continue
        seen = got.scene if isinstance(got, Registration) else got
        lost, drift = drift_from_heap(seen, heap)
        if len(lost) < len(result.lost):
            run.final_scene, result.lost, result.drift = seen, lost, drift
        if not lost:
            break
    # A block registration set aside (fallen on its side, off its cell) is not back on the heap either.
    result.lost = sorted(set(result.lost) | set(run.lost_blocks))
    return result

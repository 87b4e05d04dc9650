"""What rad shows in Rerun, and how it is logged: geometry as plain data, then the log calls.

viz_node (rad_viz) turns messages into core types and calls these; nothing here
imports rclpy or message types, so every function is tested without DDS. The
geometry helpers return numpy arrays; the `log_*` functions write them to a
`rerun.RecordingStream` passed in (never the global one).

Entity paths (all under /world, z up, metres, the scene frame = robot base frame):

  /world/table                               Boxes3D, static
  /world/panda/visual_geometries/<link>/...  the Panda's URDF meshes (rerun.urdf), static
  /world/panda/joints/<joint>                Transform3D per joint, on `ros_time`
  /world/blocks/<block id>                   Boxes3D (unit cubes, type colour) + Transform3D from mocap
  /world/targets/<region>/target_cells       small pink boxes: target cells
  /world/targets/<region>/other_cells        smaller green boxes: the region's other cells
  /world/plan/allocation/<i>                 translucent ghost block per allocated placement
  /world/plan/step, /world/plan/done         on the `step` timeline: the step's block, all placed before it
  /plan/step_text                            TextDocument per step, on `step`
  /plan/timings/<stage>, /plan/predicted_coverage   Scalars, on `ros_time`
  /plan/anytime_coverage                            Scalars: the best plan's coverage at each moment
  /plan/summary                              TextDocument (markdown), on `ros_time`

The robot's links use Rerun's named transform frames (the URDF loader logs a
frame per link and its fixed joints); /world/panda/base ties the URDF root
link to the implicit frame of /world, so robot and blocks share one tree.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rad_core.allocation.placements import Placement
from rad_core.allocation.result import AllocationResult
from rad_core.cell.panda import check_effector, source_urdf_path, urdf_path
from rad_core.domain.blocks import unit_boxes
from rad_core.domain.colours import GREEN, PINK, TABLE, type_colour
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion
from rad_core.sequencing.planning.plan import PlanStep
from rad_core.sim.world import WorldConfig
from rad_core.view.render import BLOCK_SIZE, OTHER_CELL_SIZE, PLAN_SIZE, TARGET_SIZE

WORLD = 'world'
ROBOT_PREFIX = 'world'                  # rerun.urdf puts the model under /world/<robot name>
ROBOT_ROOT = 'world/panda'
TIMELINE = 'ros_time'
STEP_TIMELINE = 'step'

GHOST_ALPHA = 0.35
STEP_SIZE = 0.9
UNKNOWN_COLOUR = (0.6, 0.6, 0.6)


def rgba8(rgb: Sequence[float], alpha: float = 1.0) -> tuple[int, int, int, int]:
    """0..1 RGB (and alpha) as the 8-bit RGBA Rerun takes."""
    return tuple(round(255 * max(0.0, min(1.0, v))) for v in (*rgb[:3], alpha))


# ---- geometry as data ------------------------------------------------------------

@dataclass(frozen=True)
class BoxSet:
    """Axis-aligned boxes in one frame: centres (n, 3), half sizes (n, 3), RGBA8 colours (n, 4)."""

    centers: np.ndarray
    half_sizes: np.ndarray
    colors: np.ndarray

    def __len__(self) -> int:
        return len(self.centers)

    @staticmethod
    def of(centers, half: float, rgba) -> BoxSet:
        c = np.asarray(centers, dtype=float).reshape(-1, 3)
        return BoxSet(c, np.full_like(c, half), np.tile(np.asarray(rgba, dtype=np.uint8), (len(c), 1)))


def block_shape(scene: Scene, type_name: str) -> BoxSet:
    """A block's unit cubes in its own frame (anchor unit at the origin, yaw 0), in its colour.

    Logged once per block; motion capture then moves the block's frame, so a
    tilted or knocked-over block is drawn as it is, not snapped to the grid. With the
    scene's clearance the block's outer side faces are set back by half of it.
    """
    offsets = np.asarray(scene.block_types[type_name].offsets, dtype=float)
    boxes = BoxSet.of(scene.pitch * offsets, scene.pitch * BLOCK_SIZE / 2, rgba8(type_colour(type_name)))
    if not scene.clearance:
        return boxes
    half = scene.unit * BLOCK_SIZE / 2
    shift, halves = unit_boxes(offsets, half, scene.course * BLOCK_SIZE / 2, scene.clearance * scene.unit / 2)
    return BoxSet(boxes.centers + shift, halves, boxes.colors)


FEEDER_COLUMNS = 8
"""A feeder's waiting blocks are drawn in rows of this many beside its station (its magazine)."""


def shown_pose(scene: Scene, block) -> tuple[tuple, tuple]:
    """Where a block is drawn before motion capture says otherwise: its scene pose, or for the k-th
    block waiting in a feeder (all of which share the station pose) a place in rows beside the
    station, away from the robot (-y), the first (k = 0) at the station itself."""
    if not scene.in_feeder(block.id):
        return tuple(block.position), yaw_quaternion(block.yaw)
    k = scene.feeder.blocks.index(block.id)
    x, y, z = block.position
    if k:
        pitch, j = 4 * scene.unit, k - 1
        x, y = x + pitch * (j % FEEDER_COLUMNS), y - pitch * (1 + j // FEEDER_COLUMNS)
    return (x, y, z), yaw_quaternion(block.yaw)


def block_boxes(scene: Scene, poses: Mapping[str, tuple] | None = None) -> dict[str, BoxSet]:
    """World-frame unit cubes of every block: at `poses[id]` = (position, quaternion xyzw) where given,
    else at the scene's own pose. Boxes stay axis-aligned, so this is exact for yaws of
    multiples of 90 degrees (what the scene and registration allow)."""
    out = {}
    for block in scene.blocks:
        position, quaternion = (poses or {}).get(block.id) or shown_pose(scene, block)
        local = block_shape(scene, block.type)
        turn = matrix_from_quaternion(quaternion)
        centers = np.asarray(position, dtype=float) + local.centers @ turn.T
        half_sizes = local.half_sizes
        if scene.clearance:
            # A quarter turn swaps a box's x and y sizes (they differ with a clearance).
            half_sizes = half_sizes @ np.round(np.abs(turn)).T
        out[block.id] = BoxSet(centers, half_sizes, local.colors)
    return out


def cell_points(scene: Scene) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per region: (target cell centres (n, 3), other cell centres (m, 3)), in region index order."""
    out = {}
    for region in scene.targets:
        filled = set(region.filled)
        target, other = [], []
        for ijk in np.ndindex(*region.size):
            (target if ijk in filled else other).append(region.cell_center(ijk, scene.pitch))
        out[region.name] = (np.asarray(target, dtype=float).reshape(-1, 3),
                            np.asarray(other, dtype=float).reshape(-1, 3))
    return out


def cell_boxes(scene: Scene) -> dict[str, tuple[BoxSet, BoxSet]]:
    """Per region: (pink target cell markers, smaller green markers on the other cells)."""
    u = scene.pitch
    return {name: (BoxSet.of(t, u * TARGET_SIZE / 2, rgba8(PINK, 0.8)),
                   BoxSet.of(o, u * OTHER_CELL_SIZE / 2, rgba8(GREEN, 0.6)))
            for name, (t, o) in cell_points(scene).items()}


def placement_boxes(scene: Scene, placement, size: float = PLAN_SIZE, alpha: float = GHOST_ALPHA) -> BoxSet:
    """One allocated pose (type, target region, cells) as boxes at its region cells.

    Cell [i, j, k] of a region has its centre at origin + unit * [i, j, k]."""
    try:
        region = scene.target(placement.target)
    except RadError:
        raise RadError(f'placement of a {placement.type} names target region {placement.target!r}, '
                       f'which the scene does not have') from None
    colour = type_colour(placement.type) if placement.type in scene.block_types else UNKNOWN_COLOUR
    centers = [region.cell_center(c, scene.pitch) for c in placement.cells]
    return BoxSet.of(centers, scene.pitch * size / 2, rgba8(colour, alpha))


def table_box(scene: Scene | None = None) -> BoxSet:
    """The twin's table (rad_core.sim.world defaults: top at z = 0), grown to hold the scene."""
    cfg = WorldConfig()
    (cx, cy), (hx, hy, hz) = cfg.table_centre, cfg.table_half_extents
    lo, hi = np.array([cx - hx, cy - hy]), np.array([cx + hx, cy + hy])
    if scene is not None and scene.blocks:
        pts = np.concatenate([scene.unit_positions(b) for b in scene.blocks])[:, :2]
        lo, hi = np.minimum(lo, pts.min(axis=0) - scene.unit), np.maximum(hi, pts.max(axis=0) + scene.unit)
    centre = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, -hz]
    half = [(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, hz]
    return BoxSet(np.array([centre]), np.array([half]), np.array([rgba8(TABLE)], dtype=np.uint8))


# ---- the plan document (topic plan_json) ----------------------------------------------

@dataclass(frozen=True)
class PlanDoc:
    """What /plan_assembly publishes on plan_json, the parts the visualizer draws.

    steps are `rad_core.sequencing.planning.plan.PlanStep`s read back from the document (no trajectory).
    """

    allocation: AllocationResult | None
    steps: tuple[PlanStep, ...]
    timings: dict[str, float] = field(default_factory=dict)
    predicted_coverage: float | None = None
    reallocations: tuple[dict, ...] = ()   # Reallocation.to_dict() of each re-allocation, in order
    anytime: tuple[dict, ...] = ()         # anytime planning: {'t', 'coverage', 'plan'} after each plan


def _check_cells(value, where: str) -> None:
    if not isinstance(value, list) or not all(
            isinstance(c, list) and len(c) == 3 and all(isinstance(v, int) and not isinstance(v, bool) for v in c)
            for c in value):
        raise RadError(f'{where}: cells must be a list of [i, j, k] integer triples')


def parse_plan(text: str) -> PlanDoc:
    """Parse a plan_json document; a bad one raises RadError naming the field."""
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as e:
        raise RadError(f'plan_json is not valid JSON: {e}') from None
    if not isinstance(doc, dict):
        raise RadError('plan_json must be a JSON object')
    allocation = None
    if doc.get('allocation') is not None:
        alloc = doc['allocation']
        try:
            allocation = AllocationResult.from_dict(alloc)
        except (KeyError, TypeError, ValueError) as e:
            raise RadError(f'allocation: not a rad-allocation/1 document ({type(e).__name__}: {e})') from None
        for i, p in enumerate(alloc['placements']):
            _check_cells(p['cells'], f'allocation.placements[{i}]')
    steps = []
    raw_steps = doc.get('steps', [])
    if not isinstance(raw_steps, list):
        raise RadError('steps must be a list')
    for i, s in enumerate(raw_steps):
        where = f'steps[{i}]'
        if not isinstance(s, dict):
            raise RadError(f'{where} must be an object')
        missing = [k for k in ('block', 'type', 'target', 'yaw', 'cells') if k not in s]
        if missing:
            raise RadError(f'{where} lacks {", ".join(missing)}')
        if not isinstance(s['yaw'], (int, float)) or isinstance(s['yaw'], bool) or not math.isfinite(s['yaw']):
            raise RadError(f'{where}.yaw must be a number')
        _check_cells(s['cells'], where)
        try:
            steps.append(PlanStep.from_dict(s))
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise RadError(f'{where}: not a plan step ({type(e).__name__}: {e})') from None
    timings = doc.get('timings') or {}
    if not isinstance(timings, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in timings.values()):
        raise RadError('timings must map stage names to finite seconds')
    coverage = doc.get('predicted_coverage')
    if coverage is not None and (not isinstance(coverage, (int, float)) or isinstance(coverage, bool)
                                 or not math.isfinite(coverage)):
        raise RadError('predicted_coverage must be a finite number')
    reallocations = doc.get('reallocations') or []
    if not isinstance(reallocations, list) or not all(
            isinstance(e, dict) and isinstance(e.get('step'), int) and isinstance(e.get('reason'), str)
            and isinstance(e.get('no_goods', []), list) for e in reallocations):
        raise RadError('reallocations must be a list of objects with an integer step, a reason and no_goods')
    anytime = doc.get('anytime') or []
    if not isinstance(anytime, list) or not all(
            isinstance(a, dict) and all(isinstance(a.get(k), (int, float)) and not isinstance(a.get(k), bool)
                                        and math.isfinite(a[k]) for k in ('t', 'coverage'))
            for a in anytime):
        raise RadError('anytime must be a list of objects with finite t (s) and coverage')
    return PlanDoc(allocation, tuple(steps), {str(k): float(v) for k, v in timings.items()},
                   None if coverage is None else float(coverage), tuple(reallocations), tuple(anytime))


def step_text(i: int, step: PlanStep) -> str:
    cells = ' '.join(f'[{a},{b},{c}]' for a, b, c in step.cells)
    aside = (' (first moves ' + ', '.join(d['block'] for d in step.moved_aside) + ' aside)'
             if step.moved_aside else '')
    return f'step {i + 1}: {step.block} ({step.type}) -> {step.target} yaw {step.yaw} cells {cells}{aside}'


def plan_summary(plan: PlanDoc) -> str:
    """Markdown: allocation status, coverage, steps, per-stage timings."""
    lines = ['# Plan', '']
    if plan.allocation is not None:
        a = plan.allocation
        lines.append(f'allocation: **{a.status}**, objective {a.objective:g}, bound {a.bound:g}, '
                     f'{len(a.placements)} placements')
    if plan.predicted_coverage is not None:
        lines.append(f'\npredicted coverage: {plan.predicted_coverage:.3f}')
    if plan.anytime:
        lines.append('\nanytime: ' + '; '.join(f"{a.get('plan', 'plan')} plan best at {a['t']:.2f} s, "
                                                  f"coverage {a['coverage']:.3f}" for a in plan.anytime))
    lines += ['', f'{len(plan.steps)} steps:', '']
    lines += [f'{i + 1}. {s.block} ({s.type}) -> {s.target} yaw {s.yaw}'
              + (f" (first moves {', '.join(d['block'] for d in s.moved_aside)} aside)" if s.moved_aside else '')
              for i, s in enumerate(plan.steps)]
    if plan.reallocations:
        lines += ['', f'{len(plan.reallocations)} re-allocations (sequencing stalled):', '']
        for e in plan.reallocations:
            excluded = '; '.join(f"{d.get('type')} {d.get('cells')}: {d.get('reason', '')}" for d in e['no_goods'])
            outcome = (f"{len(e.get('placements', []))} new poses ({e.get('status', '')})" if e.get('changed')
                       else 'nothing new')
            blocks = '; '.join(f"{d.get('block')}: {d.get('reason', '')}" for d in e.get('blocks', []))
            lines.append(f"- after step {e['step']}: {e['reason']}; excluded {len(e['no_goods'])} poses"
                         + (f' ({excluded})' if excluded else '')
                         + (f" and {len(e['blocks'])} blocks that cannot be picked ({blocks})" if blocks else '')
                         + f'; {outcome}')
    if plan.timings:
        lines += ['', '| stage | seconds |', '|---|---|']
        lines += [f'| {k} | {v:.4f} |' for k, v in plan.timings.items()]
    return '\n'.join(lines) + '\n'


# ---- logging -----------------------------------------------------------------------------

def entity_part(name: str) -> str:
    """A block id or region name as one entity path part (escaped if it has '/' or spaces)."""
    import rerun as rr  # rerun: only a viewer pays for its import
    return rr.escape_entity_path_part(name)


def _boxes(boxes: BoxSet, fill: str = 'solid'):
    import rerun as rr  # rerun: only a viewer pays for its import
    return rr.Boxes3D(centers=boxes.centers, half_sizes=boxes.half_sizes, colors=boxes.colors, fill_mode=fill)


def default_blueprint():
    """A 3D view of /world (collision meshes hidden), the step log, timings and the plan summary."""
    import rerun.blueprint as rrb  # rerun: only a viewer pays for its import
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin='/world', name='cell',
                              contents=['+ /world/**', f'- /{ROBOT_ROOT}/collision_geometries/**'],
                              spatial_information=rrb.archetypes.SpatialInformation(target_frame=f'tf#/{WORLD}'),
                              # front-right of the robot, looking at where blocks lie and structures rise
                              eye_controls=rrb.archetypes.EyeControls3D(position=(1.4, -1.2, 0.9),
                                                                        look_target=(0.4, -0.15, 0.1),
                                                                        eye_up=(0.0, 0.0, 1.0))),
            rrb.Vertical(
                rrb.TextDocumentView(origin='/plan/step_text', name='step'),
                rrb.TimeSeriesView(origin='/plan/timings', name='stage timings (s)'),
                rrb.TextDocumentView(origin='/plan/summary', name='plan'),
            ),
            column_shares=[3, 1],
        ),
        rrb.TimePanel(timeline=TIMELINE, play_state='following'),   # open at the latest state
        collapse_panels=False,
    )


def set_ros_time(rec, seconds: float) -> None:
    """Every later log call of this thread goes on the ros_time timeline only."""
    rec.reset_time()
    rec.set_time(TIMELINE, timestamp=seconds)


def log_world(rec) -> None:
    """Static: z up, and the table."""
    import rerun as rr  # rerun: only a viewer pays for its import
    rec.log(WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f'{WORLD}/table', _boxes(table_box()), static=True)


def log_scene(rec, scene: Scene, previous: Scene | None = None) -> None:
    """Blocks (shape + pose from the scene), target and non-target cells.

    Entities of a `previous` scene that this one lacks are cleared. Nothing is
    cleared that is logged anew: a Clear and new data at the same time stamp is
    ambiguous in Rerun (measured: the new data may stay hidden).
    """
    import rerun as rr  # rerun: only a viewer pays for its import
    if previous is not None:
        for block_id in {b.id for b in previous.blocks} - {b.id for b in scene.blocks}:
            rec.log(f'{WORLD}/blocks/{entity_part(block_id)}', rr.Clear(recursive=True))
        for name in {t.name for t in previous.targets} - {t.name for t in scene.targets}:
            rec.log(f'{WORLD}/targets/{entity_part(name)}', rr.Clear(recursive=True))
    rec.log(f'{WORLD}/table', _boxes(table_box(scene)), static=True)
    for block in scene.blocks:
        path = f'{WORLD}/blocks/{entity_part(block.id)}'
        rec.log(path, _boxes(block_shape(scene, block.type)))
        position, quaternion = shown_pose(scene, block)
        rec.log(path, rr.Transform3D(translation=position, quaternion=quaternion))
    for name, (target, other) in cell_boxes(scene).items():
        base = f'{WORLD}/targets/{entity_part(name)}'
        rec.log(f'{base}/target_cells', _boxes(target))
        rec.log(f'{base}/other_cells', _boxes(other))


def log_block_poses(rec, poses: Iterable[tuple[str, Sequence[float], Sequence[float]]], known: set[str]) -> int:
    """One Transform3D per tracked block: (name, position, quaternion xyzw). Returns how many were logged."""
    import rerun as rr  # rerun: only a viewer pays for its import
    n = 0
    for name, position, quaternion in poses:
        if name in known:
            rec.log(f'{WORLD}/blocks/{entity_part(name)}', rr.Transform3D(translation=position, quaternion=quaternion))
            n += 1
    return n


def _concat(boxes: list[BoxSet]) -> BoxSet:
    return BoxSet(*(np.concatenate([getattr(b, f) for b in boxes]) for f in ('centers', 'half_sizes', 'colors')))


def log_plan(rec, scene: Scene, plan: PlanDoc, stamp_s: float, previous: PlanDoc | None = None) -> list[str]:
    """Ghost allocation and timings at `stamp_s`, the steps on the `step` timeline.

    Step i (1..n) shows that step's block (/world/plan/step), the blocks placed
    before it (/world/plan/done) and a line of text (/plan/step_text); step n + 1
    shows the finished plan. Parts of a `previous` plan this one does not
    overwrite are cleared. Returns problems (parts not drawn, with the reason).
    """
    import rerun as rr  # rerun: only a viewer pays for its import
    problems = []
    set_ros_time(rec, stamp_s)
    placements = plan.allocation.placements if plan.allocation is not None else ()
    for i, p in enumerate(placements):
        try:
            rec.log(f'{WORLD}/plan/allocation/{i}', _boxes(placement_boxes(scene, p)))
        except RadError as e:
            problems.append(f'allocation.placements[{i}]: {e}')
            rec.log(f'{WORLD}/plan/allocation/{i}', rr.Clear(recursive=False))
    old = previous.allocation.placements if previous is not None and previous.allocation is not None else ()
    for i in range(len(placements), len(old)):
        rec.log(f'{WORLD}/plan/allocation/{i}', rr.Clear(recursive=False))
    for stage, seconds in plan.timings.items():
        rec.log(f'plan/timings/{entity_part(stage)}', rr.Scalars(seconds))
    if plan.predicted_coverage is not None:
        rec.log('plan/predicted_coverage', rr.Scalars(plan.predicted_coverage))
    if plan.anytime:
        # The coverage of the best plan so far, at each moment since the request (which began
        # the last point's t before the plan arrived).
        began = stamp_s - float(plan.anytime[-1]['t'])
        for a in plan.anytime:
            set_ros_time(rec, began + float(a['t']))
            rec.log('plan/anytime_coverage', rr.Scalars(float(a['coverage'])))
        set_ros_time(rec, stamp_s)
    rec.log('plan/summary', rr.TextDocument(plan_summary(plan), media_type=rr.MediaType.MARKDOWN))

    rec.reset_time()
    done: list[BoxSet] = []
    n = len(plan.steps)
    for i in range(n + 1):
        rec.set_time(STEP_TIMELINE, sequence=i + 1)
        rec.log(f'{WORLD}/plan/done', _boxes(_concat(done)) if done else rr.Clear(recursive=False))
        if i == n:
            rec.log(f'{WORLD}/plan/step', rr.Clear(recursive=False))
            rec.log('plan/step_text', rr.TextDocument(f'plan done: {n} steps'))
            break
        step = plan.steps[i]
        try:
            cells = tuple(tuple(c) for c in step.cells)
            boxes = placement_boxes(scene, Placement(step.type, step.target, step.yaw, cells), size=STEP_SIZE,
                                    alpha=1.0)
        except RadError as e:
            problems.append(f'steps[{i}]: {e}')
            rec.log(f'{WORLD}/plan/step', rr.Clear(recursive=False))
            rec.log('plan/step_text', rr.TextDocument(step_text(i, step) + f' (not drawn: {e})'))
            continue
        rec.log(f'{WORLD}/plan/step', _boxes(boxes))
        rec.log('plan/step_text', rr.TextDocument(step_text(i, step)))
        done.append(boxes)
    if previous is not None and len(previous.steps) > n:
        rec.set_time(STEP_TIMELINE, sequence=n + 2)     # the older, longer plan's steps end here
        for path in (f'{WORLD}/plan/step', f'{WORLD}/plan/done', 'plan/step_text'):
            rec.log(path, rr.Clear(recursive=False))
    rec.reset_time()
    return problems


class PandaModel:
    """The Panda of pybullet_data as a rerun.urdf tree: meshes logged once, joints driven by joint states.
    effector: what the arm carries (`cell.panda.EFFECTORS`): the hand, or the vacuum gripper's housing and
    cup in its place (the URDF the twin loads, `cell.panda.urdf_path`); urdf: draw this file instead."""

    def __init__(self, urdf: str | Path | None = None, effector: str = 'hand'):
        import rerun.urdf as ru  # rerun: only a viewer pays for its import

        check_effector(effector)
        if urdf is None:     # what is drawn: its visual meshes
            urdf = source_urdf_path() if effector == 'hand' else urdf_path(effector)
        path = Path(urdf)
        # panda.urdf names its meshes package://meshes/...: the package root is the URDF's folder.
        packages = os.environ.get('ROS_PACKAGE_PATH', '')
        if str(path.parent) not in packages.split(os.pathsep):
            os.environ['ROS_PACKAGE_PATH'] = os.pathsep.join(p for p in (str(path.parent), packages) if p)
        self.tree = ru.UrdfTree.from_file_path(str(path), ROBOT_PREFIX,
                                               static_transform_entity_path=f'{ROBOT_ROOT}/tf_static')
        self.joints = {j.name: j for j in self.tree.joints() if j.joint_type != 'fixed'}
        self.root_frame = self.tree.root_link().name

    def link_names(self) -> list[str]:
        return [self.tree.root_link().name] + [j.child_link for j in self.tree.joints()]

    def log_model(self, rec) -> None:
        import rerun as rr  # rerun: only a viewer pays for its import
        self.tree.log_urdf_to_recording(rec)
        # The URDF's root link stands at the world origin (the robot base frame is the scene frame).
        rec.log(f'{ROBOT_ROOT}/base', rr.Transform3D(parent_frame=f'tf#/{WORLD}', child_frame=self.root_frame),
                static=True)

    def log_joints(self, rec, names: Sequence[str], positions: Sequence[float]) -> int:
        """One Transform3D per known, finite joint; returns how many were logged."""
        n = 0
        for name, q in zip(names, positions):
            joint = self.joints.get(name)
            if joint is None or not math.isfinite(q):
                continue
            rec.log(f'{ROBOT_ROOT}/joints/{entity_part(name)}', joint.compute_transform(float(q), clamp=False))
            n += 1
        return n

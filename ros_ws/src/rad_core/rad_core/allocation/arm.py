"""What the arm can never do, whatever the order: the allocation's arm-aware filter.

The paper's allocation is blind to the robot: it proposes block types the open hand
cannot take from above, poses whose every grasp lies beyond the arm's reach, and
blocks on the table the arm cannot pick where they lie. The sequencer then meets
them one pose at a time, and re-allocation excludes them pose by pose, so the same
unbuildable block comes back at the next pose. `support='arm'` (rad's allocation,
`cpsat.solve`) rules them out before solving, at the level they fail:

- a block TYPE with no top-down grasp at the scene's unit and clearance
  (`gamp.grasps.block_grasps` is empty: units wider than the open hand, or no unit free
  from above with both finger columns clear, e.g. a 2x2 square) is not allocated at all;
- a BLOCK on the table whose every grasp target lies outside the workspace
  (`gamp.ik.out_of_workspace`: below the table, or farther from the shoulder than the
  arm reaches) is not available: its type's count drops by one;
- a POSE (type, cells) whose every grasp target lies outside the workspace is not a
  candidate.

Each test is conservative: it only rules out what GAMP's own first checks refuse for
every grasp, whatever the other blocks, the arm's start or the order; so no
allocation the robot could build is lost. What is left (collisions with neighbours,
joint limits of a particular IK solution) stays with GAMP at sequencing time. An
approach blocked by target cells that must already be built is NOT tested: the only
cells certainly built before a pose are those it rests on, below it, which a top-down
hand never reaches (its fingertips stop within the grasped unit).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rad_core.allocation.placements import Candidate
from rad_core.domain.blocks import rotation_z
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Scene
from rad_core.gamp.grasps import (
    DROP_HEIGHT,
    grasp_lift,
    no_grasp_reason_for,
    scene_grasps,
    span_width,
)
from rad_core.gamp.hand_cells import DEPTH, NEAR_DEPTH, blocking_offsets
from rad_core.gamp.ik import out_of_workspace
from rad_core.gamp.planner import GampConfig, drop_styles, grasp_styles, suction_styles, wide_grasp_styles


@dataclass
class ArmFilter:
    """What `arm_filter` ruled out, with why: types and blocks by name, poses counted."""

    types: dict[str, str] = field(default_factory=dict)
    blocks: dict[str, str] = field(default_factory=dict)
    poses: int = 0
    pose_reasons: dict[str, int] = field(default_factory=dict)   # reason -> poses it ruled out

    def to_dict(self) -> dict:
        return {'types': dict(self.types), 'blocks': dict(self.blocks), 'poses': self.poses,
                'pose_reasons': dict(self.pose_reasons)}

    def summary(self) -> str:
        parts = [f'type {t}: {why}' for t, why in sorted(self.types.items())]
        parts += [f'block {b}: {why}' for b, why in sorted(self.blocks.items())]
        if self.poses:
            why = ', '.join(f'{k} ({n})' for k, n in sorted(self.pose_reasons.items()))
            parts.append(f'{self.poses} poses out of reach: {why}')
        return '; '.join(parts) or 'nothing ruled out'


def type_grasps(scene: Scene, gamp=None) -> dict[str, tuple]:
    """Every block type's top-down grasps at the scene's unit and clearance, as GAMP with these
    settings (`GampConfig`, default: the defaults) offers them: wide ones where it takes them, the
    cup's with the vacuum gripper."""
    gamp = gamp or GampConfig()
    return {name: scene_grasps(btype, scene.unit, scene.clearance, gamp.wide_grasps, gamp.effector)
            for name, btype in scene.block_types.items()}


def grasp_shift(grasp, pose_yaw: int) -> tuple[float, float]:
    """Where a grasp's target sits beside its first unit's centre, in units along world x and y, for
    a pose turned by `pose_yaw` (0 for a unit grasp; half the row's length for a wide one)."""
    if grasp.span == 1:
        return (0.0, 0.0)
    along = rotation_z(pose_yaw) @ np.array([1, 0, 0] if grasp.yaw == 0 else [0, 1, 0])
    half = (grasp.span - 1) / 2
    return (float(along[0] * half), float(along[1] * half))


def _no_grasp_reason(scene: Scene, name: str, effector: str = 'hand') -> str:
    return 'no top-down grasp: ' + no_grasp_reason_for(scene.block_types[name], scene.unit, scene.clearance, effector)


def _unreachable(points: np.ndarray) -> str:
    """'' if any of the grasp targets can be reached, else the first one's reason."""
    first = ''
    for p in points:
        why = out_of_workspace(np.asarray(p, dtype=float))
        if not why:
            return ''
        first = first or why
    return first


def _both_heights(points: np.ndarray, lift: float) -> np.ndarray:
    """Grasp targets at units' centres and, for the planner's tight grasp, `lift` over them."""
    return np.concatenate([points, points + (0.0, 0.0, lift)])


def block_unit_centres(scene: Scene, b: int) -> np.ndarray:
    """World centres of a block's units where it lies (its position is unit 0's centre)."""
    block = scene.blocks[b]
    offsets = scene.block_types[block.type].rotated(block.yaw)
    return np.asarray(block.position, dtype=float) + np.asarray(offsets, dtype=float) * scene.pitch


def arm_filter(scene: Scene, grid: Grid, candidates: list[Candidate],
               gamp=None) -> tuple[list[Candidate], dict, ArmFilter]:
    """(the candidates the arm could build, blocks available per type, what was ruled out and why).

    Blocks already on the grid are not counted (as `cpsat.available_counts`). gamp: GAMP's settings
    (`GampConfig`, default the defaults): its effector's grasps."""
    gamp = gamp or GampConfig()
    grasps = type_grasps(scene, gamp)
    # A tight grasp's target over the unit's centre; the cup's, on its top face.
    lift = suction_styles(scene.course, gamp)[0][1] if gamp.effector == 'suction' else grasp_lift(scene.course)
    report = ArmFilter()
    for name, gs in grasps.items():
        if not gs:
            report.types[name] = _no_grasp_reason(scene, name, gamp.effector)
    placed = blocks_on_grid(scene, grid)
    counts = {name: 0 for name in scene.block_types}
    for b, block in enumerate(scene.blocks):
        if b in placed or block.type in report.types:
            continue
        units = block_unit_centres(scene, b)[sorted({g.unit for g in grasps[block.type]})]
        why = _unreachable(_both_heights(units, lift))
        if why:
            report.blocks[block.id] = f'cannot be picked where it lies: {why}'
            continue
        counts[block.type] += 1
    kept = []
    for cand in candidates:
        name = cand.placement.type
        if name in report.types:
            continue
        centres = grid.centres[list(cand.cell_ids)][sorted({g.unit for g in grasps[name]})]
        why = _unreachable(_both_heights(centres, lift))
        if why:
            report.poses += 1
            key = why.split(':')[0] + ': ' + ('target below the table' if 'below' in why else 'beyond the reach')
            report.pose_reasons[key] = report.pose_reasons.get(key, 0) + 1
            continue
        kept.append(cand)
    return kept, counts, report


def finger_costs(scene: Scene, grid: Grid, candidates: list[Candidate], gamp=None) -> list[int]:
    """Per candidate pose, how hard a top-down hand finds it to hold at its final place: over
    its grasps, the fewest finger sides that land on a target cell of its region (0: some grasp
    closes with both fingers beside cells no block will ever fill; 2: every grasp has target
    cells on both sides, so whichever neighbour is built first blocks it). `prefer='open'`
    minimizes the sum among equally good allocations (`cpsat.build_model`)."""
    gamp = gamp or GampConfig()
    if gamp.effector == 'suction':
        return [0] * len(candidates)      # the cup needs nothing beside the block
    grasps = type_grasps(scene, gamp)
    out = []
    for cand in candidates:
        gs = grasps.get(cand.placement.type, ())
        if not gs:
            out.append(2)
            continue
        rot = rotation_z(cand.placement.yaw)
        ids = list(cand.cell_ids)
        region = int(grid.region_of[ids[0]])
        best = 2
        for g in gs:
            d = rot @ np.array([1, 0, 0] if g.yaw == 0 else [0, 1, 0])
            at = grid.ijk[ids[g.unit]]
            sides = 0
            for beside in (at + g.span * d, at - d):     # the finger columns beside the row
                c = grid.index(region, beside)
                if c is not None and bool(grid.is_target[c]):
                    sides += 1
            best = min(best, sides)
        out.append(best)
    return out


class HandBlocked:
    """Which poses a top-down hand can no longer place once some cells are built.

    A pose's grasp puts the hand, at one of two hand yaws, on its unit's cell
    (`gamp.planner.plan_action`: the yaw at the placement follows from the pose's yaw and the
    grasp, whichever block is held). `gamp.hand_cells.blocking_offsets` gives the cells around
    that unit whose built block the hand, its open fingers or panda_link7 would enter. A pose is
    blocked when, for each of its grasps and both hand yaws, one of those cells is built: the
    planner then refuses it from every arm configuration. Built cells stay built, so a pose
    blocked in a state is blocked in every state after it. Cells off the grid are never built.

    A wide grasp's cells count from the first unit of its row, the hand's target at the row's middle
    (`grasp_shift`), its fingers opened off the row's outer faces (`planner.wide_grasp_styles`). Where
    GAMP drops blocks (`GampConfig.drop`), the drop is one more way: the hand `grasps.DROP_HEIGHT` over the
    placement, holding the unit by its top (`planner.drop_styles`), its fingertips over the unit's level.
    With the vacuum gripper (`GampConfig.effector` 'suction') the cells are those its housing and
    cup enter, the cup's lip over the unit's top face; no finger goes down beside the block.

    gamp: the planner's settings (`GampConfig`), which say how the fingers may take a unit
    (`planner.grasp_styles`): an offset blocks only where it blocks in every way.

    near: count too the cells whose block would come within the planner's collision margin of the
    hand (`hand_cells.NEAR_DEPTH`), not only those it would enter, with the fingers open and closed on
    the block (the planner probes both at the placement): what the planner refuses, for orders that
    should agree with it (`sequencing.planning.courses.course_line`). At a 2 cm unit the 17.5 mm
    fingertips then block the cells diagonal to their columns and beside the held unit too. Bounds keep
    the default (a cell counts only where the hand surely enters it)."""

    def __init__(self, scene: Scene, grid: Grid, gamp=None, near: bool = False):
        self.grid = grid
        self.scene = scene
        self.gamp = gamp or GampConfig()
        self.depth = NEAR_DEPTH if near else DEPTH
        self.grasps = type_grasps(scene, self.gamp)
        self._offsets: dict[tuple, np.ndarray] = {}
        self._cells: dict[tuple, list] = {}

    def offsets(self, hand_yaw: int, span: int = 1, shift: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """The blocking offsets (n, 3) of a grasp across `span` units whose target sits `shift` units
        beside its first unit, at this hand yaw: those that block in every way the planner takes it."""
        key = (hand_yaw, span, shift)
        found = self._offsets.get(key)
        if found is None:
            scene = self.scene
            if self.gamp.effector == 'suction':
                styles = suction_styles(scene.course, self.gamp)
            else:
                width = span_width(span, scene.unit, scene.clearance)      # grasp_width's for one unit
                styles = (grasp_styles if span == 1 else wide_grasp_styles)(width, scene.course, self.gamp)
                if self.gamp.drop and scene.studs is None:
                    # Let go over its place: the hand `DROP_HEIGHT` over where it would set the block down.
                    styles += tuple((f, lift + DROP_HEIGHT) for f, lift in drop_styles(width, scene.course, self.gamp))
            course = None if scene.course == scene.unit else scene.course
            closed = max(0.0, width / 2 - self.gamp.grip_squeeze) if self.gamp.effector == 'hand' else None

            def way(f, lift):
                cells = blocking_offsets(scene.unit, scene.clearance, f, hand_yaw, lift, shift, self.gamp.effector,
                                         course, self.depth)
                if self.depth < 0 and closed is not None:
                    # The planner also probes the hand at the placement closed on the block it carries.
                    cells |= blocking_offsets(scene.unit, scene.clearance, closed, hand_yaw, lift, shift,
                                              self.gamp.effector, course, self.depth)
                return cells
            common = frozenset.intersection(*(way(f, lift) for f, lift in styles))
            found = self._offsets[key] = np.array(sorted(common), dtype=float).reshape(-1, 3)
        return found

    def cells(self, type_name: str, yaw: int, cell_ids) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per grasp of the pose (its cells in unit order), the grid cells that block it at each
        of its two hand yaws."""
        key = (type_name, int(yaw) % 360, tuple(int(c) for c in cell_ids))
        found = self._cells.get(key)
        if found is None:
            grid = self.grid
            found = []
            for g in self.grasps.get(type_name, ()):
                centre = grid.centres[key[2][g.unit]]
                # The hand yaw at the placement: the fingers close along the pose's yaw plus the
                # grasp's, the hand 90 deg off that, or the half turn of it.
                yaws = [(key[1] + g.yaw + 90 + half) % 360 for half in (0, 180)]
                shift = grasp_shift(g, key[1])
                found.append(tuple(self._on_grid(centre + self.offsets(y, g.span, shift) * grid.pitch)
                                   for y in yaws))
            self._cells[key] = found
        return found

    def _on_grid(self, points: np.ndarray) -> np.ndarray:
        ids = self.grid.lookup(points)
        return ids[ids >= 0]

    def blocked(self, type_name: str, yaw: int, cell_ids, occupied: np.ndarray) -> bool:
        """Whether every grasp of the pose, at both hand yaws, has a built cell in its way."""
        grasps = self.cells(type_name, yaw, cell_ids)
        return bool(grasps) and all(occupied[a].any() and occupied[b].any() for a, b in grasps)

    def __call__(self, cand: Candidate, occupied: np.ndarray) -> bool:
        """`blocked` for an allocation candidate."""
        return self.blocked(cand.placement.type, cand.placement.yaw, cand.cell_ids, occupied)

"""The predefined top-down grasps of a block type (the paper's Sec. IV-C), and the vacuum gripper's.

A grasp is (unit, yaw): the hand points straight down, the grasp target (the
point between the fingertips) sits at the centre of unit `unit` (or, in the planner's
tight grasp, `GRASP_BELOW_TOP` under its top), and the fingers close along the block's own
x axis (yaw 0) or y axis (yaw 90). 180 and
270 are the same grasps: the Panda hand is symmetric under a half turn, and
which of the two hand yaws is used is the IK's choice (joint 7's range).

Why a tight grasp holds the top: the rubber tips, 18.5 mm tall, are the fingers' thinnest
part (15 mm); above them the finger widens to 26 mm (`cell.panda.FINGER_BOXES`). Held near its
top, a unit has only the tips beside it, so a neighbour 2.5 cm away leaves room (the pads still
cover 16 mm of the unit's side at a 5 cm unit). The rule, from the hand's geometry: the
fingers open 0.08 m at most and their pads span from 8 mm below the grasp
target to 10 mm above it, so they close on exactly one unit, 1 unit wide, at or above its
centre, and pass the levels above it on their way down. A grasp of
unit u closing along axis d is offered when

1. no unit of the same block lies above u (u is the top of its column: the
   hand comes from above), and
2. no unit of the same block lies in the two finger columns u + d and u - d at
   u's height or above (a finger would land on it or hit it on the way down).

Where the fingers are wider than the unit (`beside_blocks`: at 2 cm units the 17.5 mm tips with the
planner's 2 mm margin reach past the unit's sides), units of the same block in the four columns
diagonal to u (u + d + e, u + d - e, ...; e across d) at u's level or above block the grasp too: the
finger beside u would touch them (the 22 mm finger above the tips counts for the levels above u).

Units below u's level are never touched (the fingertips stay within u). What
the rule cannot see (the hand's palm, 0.21 x 0.06 m, passing 14 mm above u's
top, 26 mm in a tight grasp, or neighbouring blocks) is left to the collision checks of the planner,
which probe the real geometry. Only units up to `MAX_GRASP_WIDTH` wide can be
taken: the open hand must clear the unit by a few millimetres on each side.

Wide grasps (`wide_grasps`, offered by the planner only with `GampConfig.wide_grasps`): the
fingers close along the block's x (yaw 0) or y (yaw 90) axis across the block's whole extent
there, `span` units, their pads on the block's outer faces, the fingers outside the block. A
wide grasp `Grasp(unit, yaw, span)` names the row of units at unit `unit`'s level and position
across the closing axis, `unit` being the row's first unit along the closing axis; its target
(`grasp_centre`) is the middle of the row, held at the tight grasp's height (`grasp_lift`). It is
offered where

1. the row is unbroken (every cell from its first unit to its last is a unit of the block),
   `span` >= 2 units, and its width (`span_width`) with 5 mm on each side fits the open hand;
2. no unit of the block lies above any unit of the row (the palm comes down on the row); and
3. no unit of the block lies in the two finger columns just outside the row's ends at the row's
   level or above (a finger would land on it or hit it on the way down), nor, where the fingers are
   wider than a unit (`beside_blocks`), in the columns diagonal to those.

Suction grasps (`suction_grasps`, the vacuum gripper in the hand's place: `GampConfig.effector`):
the cup centred on the top face of a unit no unit of the same block lies above, where the cup fits
that face with `CUP_MARGIN` to its edges (`cup_fits`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rad_core.cell import panda
from rad_core.domain.blocks import BlockType

MAX_GRASP_WIDTH = panda.MAX_OPENING - 2 * 0.005
"""Widest unit (m) the open hand can take: 0.08 m opening less 5 mm clearance per side."""

GRASP_YAWS = (0, 90)

GRASP_BELOW_TOP = 0.013
"""A tight grasp's target sits this far (m) under the top of the held unit, never below its
centre: the fingertips' pads then cover the unit's side from 2.4 mm under its top down to 21 mm."""


TIP_BELOW = 0.008
"""How far (m) the fingertips' pads reach under the grasp target (`cell.panda.FINGER_BOXES`' rubber tip)."""

TIP_FLOOR = TIP_BELOW + 0.002
"""The least height (m) of the grasp target over the held block's bottom: the pads stay 2 mm above what
the block rests on. A block thinner than that (a plate of a stud system) is held higher than its tight
grasp, the pads on its upper part (`tip_floor_lift`)."""


DROP_GRIP = 0.010
"""A drop's hold (`drop_lift`): the pads cover this much (m) of the held unit's side under its top."""

DROP_CLEAR = 0.004
"""How far (m) a drop's fingertips stay over the placed block's top when the fingers let go."""

DROP_HEIGHT = DROP_GRIP + DROP_CLEAR
"""How far (m) over its place a dropped block is let go (`drop_lift`): the fingertips, `DROP_GRIP`
under the held block's top, then clear the course it goes into by `DROP_CLEAR`."""


def drop_lift(height: float) -> float:
    """How far (m) a drop's grasp target sits above the held unit's centre, for a unit this high: the
    pads, reaching `TIP_BELOW` under the target, cover the top `DROP_GRIP` of the unit's sides.

    A drop is the hand's way into a place whose neighbours at its level are built on both sides:
    held by its top, the block is let go `DROP_HEIGHT` over its place, the fingers above those
    neighbours, and falls the rest (`planner.GampConfig.drop`)."""
    return max(0.0, height / 2 - (DROP_GRIP - TIP_BELOW))


def tip_floor_lift(hang: float) -> float:
    """How far (m) to raise a grasp whose target hangs `hang` above the held block's bottom, so that the
    fingertips stay `TIP_FLOOR` over what the block rests on (0 where they already do)."""
    return max(0.0, TIP_FLOOR - hang)


def grasp_lift(height: float) -> float:
    """How far (m) a tight grasp's target sits above the held unit's centre, for a unit this high (the
    unit, or a stud system's course height)."""
    return max(0.0, height / 2 - GRASP_BELOW_TOP)


@dataclass(frozen=True)
class Grasp:
    """Fingers close on unit `unit` (index into the type's offsets) along the
    block's x axis (yaw 0) or y axis (yaw 90). span > 1: a wide grasp across `span` units,
    the row that starts at unit `unit` along the closing axis (module docstring)."""

    unit: int
    yaw: int
    span: int = 1

    def __str__(self) -> str:
        if self.span == 1:
            return f'unit {self.unit} yaw {self.yaw}'
        return f'unit {self.unit} yaw {self.yaw} span {self.span}'


def grasp_width(unit: float, clearance: float = 0.0) -> float:
    """The width (m) the fingers close on: a unit's outer faces, which a scene's clearance sets back."""
    return unit * (1.0 - clearance)


def span_width(span: int, unit: float, clearance: float = 0.0) -> float:
    """The width (m) across the outer faces of `span` units in a row: a scene's clearance sets back
    the row's two outer faces only (`domain.blocks.unit_boxes`). `grasp_width` for one unit."""
    return unit * (span - clearance)


def grasp_centre(btype: BlockType, grasp: Grasp) -> np.ndarray:
    """Where (in units, the block's frame) the grasp target sits over the held unit's centre: the
    unit's centre, or for a wide grasp the middle of its row along the closing axis."""
    centre = np.asarray(btype.offsets[grasp.unit], dtype=float)
    if grasp.span > 1:
        centre[0 if grasp.yaw == 0 else 1] += (grasp.span - 1) / 2
    return centre


def wide_grasps(btype: BlockType, unit: float, clearance: float = 0.0) -> tuple[Grasp, ...]:
    """Every wide grasp the rule of the module docstring allows at this unit (m) and clearance,
    best first (`grasp_order`)."""
    offsets = np.asarray(btype.offsets, dtype=np.int64)
    cells = {tuple(o): u for u, o in enumerate(offsets.tolist())}
    height = _height(offsets)
    out = []
    for yaw in GRASP_YAWS:
        axis = 0 if yaw == 0 else 1
        step = np.eye(3, dtype=np.int64)[axis]
        for u, cell in enumerate(offsets.tolist()):
            first = np.asarray(cell)
            if tuple(first - step) in cells:
                continue                    # not the row's first unit
            row = [first]
            while tuple(row[-1] + step) in cells:
                row.append(row[-1] + step)
            span = len(row)
            if span < 2 or span_width(span, unit, clearance) > MAX_GRASP_WIDTH:
                continue
            up = [(0, 0, k) for k in range(1, height + 1)]
            covered = any(tuple(c + d) in cells for c in row for d in up)
            fingers = (first - step, row[-1] + step)
            blocked = any(tuple(f + (0, 0, k)) in cells for f in fingers for k in range(height + 1)) or \
                any(_diagonal_blocked(cells, f, step, height, unit, clearance) for f in fingers)
            if not covered and not blocked:
                out.append(Grasp(u, yaw, span))
    return tuple(grasp_order(btype, out))


FINGER_TIP_HALF = panda.FINGER_BOXES[-1][2][0] / 2
"""Half the fingertip's width across the closing axis (m): beside the held unit."""
FINGER_HALF = max(size[0] for *_, size in panda.FINGER_BOXES) / 2
"""Half the finger's widest part across the closing axis (m): beside the levels over the held unit."""
FINGER_MARGIN = 0.002
"""How close (m) a finger may come to a unit of the block it takes: the planner's collision margin
(`gamp.collision.CollisionConfig.robot_margin`)."""


def beside_blocks(level: int, unit: float, clearance: float = 0.0) -> bool:
    """Whether a unit of the block diagonal to a held unit (or to a wide grasp's finger column),
    `level` units over it (0: at its level), is in the way of the finger beside it: the finger's half
    width there with `FINGER_MARGIN` reaches past the diagonal unit's face, half a unit from the held
    unit's centre line plus the clearance it is set back by (m)."""
    half = FINGER_TIP_HALF if level == 0 else FINGER_HALF
    return half + FINGER_MARGIN > unit * (1.0 + clearance) / 2


def _diagonal_blocked(cells: set, at, step, height: int, unit: float, clearance: float) -> bool:
    """Whether a unit of the block (cells) lies diagonal to the finger column `at` (across `step`, the
    closing axis) at its level or above, where the finger is wide enough to touch it (`beside_blocks`)."""
    across = np.array([step[1], step[0], 0], dtype=np.int64)
    return any(tuple(np.asarray(at) + t * across + (0, 0, k)) in cells and beside_blocks(k, unit, clearance)
               for t in (1, -1) for k in range(height + 1))


def no_grasp_reason(btype: BlockType, unit_size: float) -> str:
    """Why `block_grasps(btype, unit_size)` offers nothing."""
    if unit_size > MAX_GRASP_WIDTH:
        return f'{unit_size * 1000:.0f} mm units are wider than the hand takes ({MAX_GRASP_WIDTH * 1000:.0f} mm)'
    return f'no unit of a {btype.name} is free from above'


def block_grasps(btype: BlockType, unit_size: float = 0.05, wide: bool = False,
                 clearance: float = 0.0) -> tuple[Grasp, ...]:
    """Every grasp the rule of the module docstring allows, best first (`grasp_order`).

    unit_size: the width of one unit (a scene's `grasp_width`). wide: the wide grasps
    (`wide_grasps`) after the unit grasps, for the scene's unit `unit_size / (1 - clearance)`."""
    unit = unit_size / (1.0 - clearance)
    unit_grasps = _unit_grasps(btype, unit, clearance)
    if not wide:
        return unit_grasps
    return unit_grasps + wide_grasps(btype, unit, clearance)


def _unit_grasps(btype: BlockType, unit: float, clearance: float = 0.0) -> tuple[Grasp, ...]:
    if grasp_width(unit, clearance) > MAX_GRASP_WIDTH:
        return ()
    offsets = np.asarray(btype.offsets, dtype=np.int64)
    cells = {tuple(o) for o in offsets.tolist()}
    height = _height(offsets)
    out = []
    for u, (x, y, z) in enumerate(offsets.tolist()):
        if any((x, y, z + k) in cells for k in range(1, height + 1)):
            continue
        for yaw in GRASP_YAWS:
            dx, dy = (1, 0) if yaw == 0 else (0, 1)
            blocked = any((x + s * dx, y + s * dy, z + k) in cells
                          for s in (1, -1) for k in range(height + 1)) or \
                any(_diagonal_blocked(cells, (x + s * dx, y + s * dy, z), (dx, dy, 0), height, unit, clearance)
                    for s in (1, -1))
            if not blocked:
                out.append(Grasp(u, yaw))
    return tuple(grasp_order(btype, out))


def grasp_order(btype: BlockType, grasps) -> list[Grasp]:
    """Heuristic order: units nearest (in plan) to the centre of mass first, so the
    block hangs level and the fingers carry little torque; then the higher unit
    (the hand stays farther from the table and neighbours); then yaw 0 before 90."""
    offsets = np.asarray(btype.offsets, dtype=float)
    com = offsets.mean(axis=0)

    def key(g: Grasp):
        o = offsets[g.unit] if g.span == 1 else grasp_centre(btype, g)
        return (round(float(np.hypot(*(o[:2] - com[:2]))), 6), -o[2], g.yaw, g.unit)

    return sorted(grasps, key=key)


def _height(offsets: np.ndarray) -> int:
    return int(offsets[:, 2].max() - offsets[:, 2].min())


def scene_grasps(btype: BlockType, unit: float, clearance: float = 0.0, wide: bool = True,
                 effector: str = 'hand') -> tuple[Grasp, ...]:
    """Every grasp of a block type in a scene of this unit (m) and clearance, best first: with the hand
    the unit grasps, then (wide) the wide grasps; with the vacuum gripper (effector 'suction') the
    suction grasps. What GAMP tries (`planner.plan_action`) and the allocation counts on
    (`allocation.arm.type_grasps`)."""
    if effector == 'suction':
        return suction_grasps(btype, unit, clearance)
    unit_grasps = _unit_grasps(btype, unit, clearance)
    return unit_grasps + wide_grasps(btype, unit, clearance) if wide else unit_grasps


CUP_MARGIN = 0.001
"""The cup's lip must stay this far (m) inside a unit's top face: a seal needs the whole lip on it."""


def cup_fits(unit: float, clearance: float = 0.0) -> bool:
    """Whether the suction cup (`cell.panda.CUP_RADIUS`) fits a unit's top face, centred on it, with
    `CUP_MARGIN` to the face's edges (a scene's clearance sets a block's outer faces back)."""
    return panda.CUP_RADIUS + CUP_MARGIN <= grasp_width(unit, clearance) / 2


def suction_grasps(btype: BlockType, unit: float, clearance: float = 0.0) -> tuple[Grasp, ...]:
    """The vacuum gripper's grasps: the cup centred on the top face of a unit no unit of the same
    block lies above, where the cup fits that face (`cup_fits`), best first (`grasp_order`: units
    nearest the centre of mass in plan, then the higher). `Grasp(unit, 0)`: a cup has no closing
    axis, so the hand's yaw is free (the planner tries the block's own two)."""
    if not cup_fits(unit, clearance):
        return ()
    offsets = np.asarray(btype.offsets, dtype=np.int64)
    cells = {tuple(o) for o in offsets.tolist()}
    tops = [u for u, (x, y, z) in enumerate(offsets.tolist())
            if not any((x, y, z + k) in cells for k in range(1, _height(offsets) + 1))]
    return tuple(grasp_order(btype, [Grasp(u, 0) for u in tops]))


def no_grasp_reason_for(btype: BlockType, unit: float, clearance: float = 0.0, effector: str = 'hand') -> str:
    """Why `scene_grasps` offers nothing for this block type, unit and effector."""
    if effector == 'suction':
        face = grasp_width(unit, clearance)
        return (f'the {2 * panda.CUP_RADIUS * 1000:.0f} mm suction cup does not fit a {face * 1000:.0f} mm top face '
                f'with {CUP_MARGIN * 1000:.0f} mm to its edges')
    return no_grasp_reason(btype, grasp_width(unit, clearance))

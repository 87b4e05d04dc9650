"""What RViz (or Foxglove) draws of rad: a scene and its plan as a visualization_msgs/MarkerArray.

The geometry is rad_core.view.viz's, the same boxes Rerun shows: the target cells, each block
(where motion capture sees it, else where the scene has it), the allocation's poses as ghosts and
the plan's next step, all in the robot's base frame. Namespaces: 'target', 'blocks', 'allocation',
'next_step'. The array starts with a DELETEALL marker, so one array replaces what the last drew.
"""

from __future__ import annotations

from typing import Mapping

from geometry_msgs.msg import Point
from rad_core.domain.scene import Scene
from rad_core.view import viz
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

NEXT_ALPHA = 0.9


def boxes_marker(boxes: viz.BoxSet, ns: str, marker_id: int, frame_id: str, stamp) -> Marker:
    """A BoxSet as one CUBE_LIST marker (its boxes share the first box's size)."""
    m = Marker(ns=ns, id=marker_id, type=Marker.CUBE_LIST, action=Marker.ADD)
    m.header.frame_id, m.header.stamp = frame_id, stamp
    m.pose.orientation.w = 1.0
    if len(boxes):
        m.scale.x, m.scale.y, m.scale.z = (float(2 * v) for v in boxes.half_sizes[0])
    for c, rgba in zip(boxes.centers, boxes.colors):
        m.points.append(Point(x=float(c[0]), y=float(c[1]), z=float(c[2])))
        m.colors.append(ColorRGBA(r=rgba[0] / 255.0, g=rgba[1] / 255.0, b=rgba[2] / 255.0, a=rgba[3] / 255.0))
    return m


def scene_markers(scene: Scene, frame_id: str, stamp, poses: Mapping[str, tuple] | None = None,
                  plan: viz.PlanDoc | None = None) -> MarkerArray:
    """The scene (blocks at `poses[id]` = (position, quaternion xyzw) where given) and the plan."""
    clear = Marker(action=Marker.DELETEALL)
    clear.header.frame_id, clear.header.stamp = frame_id, stamp
    out = [clear]
    for n, (target, _) in enumerate(viz.cell_boxes(scene).values()):
        out.append(boxes_marker(target, 'target', n, frame_id, stamp))
    for n, boxes in enumerate(viz.block_boxes(scene, poses).values()):
        out.append(boxes_marker(boxes, 'blocks', n, frame_id, stamp))
    if plan is not None and plan.allocation is not None:
        for n, placement in enumerate(plan.allocation.placements):
            out.append(boxes_marker(viz.placement_boxes(scene, placement), 'allocation', n, frame_id, stamp))
    if plan is not None and plan.steps:
        step = plan.steps[0]
        out.append(boxes_marker(viz.placement_boxes(scene, step, alpha=NEXT_ALPHA), 'next_step', 0, frame_id, stamp))
    return MarkerArray(markers=out)

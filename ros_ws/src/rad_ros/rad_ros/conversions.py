"""rad_msgs <-> rad_core conversions. Imports message types only, never rclpy.

A scene message is turned into the rad-scene/1 document and parsed by the same
validator the CLI uses, so a bad message gets the same field-naming errors.

A scene's ``clearance`` (rad_core.domain.scene) travels in rad_msgs/Scene's ``clearance``
field (0 = flush, as in a scene document without the key), its ``studs`` in ``studs`` (at most
one rad_msgs/Studs; none: blocks that only rest). What registration and design add to a scene
(``measured_offsets``, ``obstacles``, ``design``) travels in a request's ``scene_json`` only.
"""

from __future__ import annotations

from geometry_msgs.msg import Point
from rad_core.allocation import AllocationResult
from rad_core.allocation.placements import Placement as CorePlacement
from rad_core.domain.errors import RadError
from rad_core.domain.scene import FORMAT, Scene
from rad_msgs.msg import Block, BlockType, Cell, Placement, TargetRegion
from rad_msgs.msg import Feeder as FeederMsg
from rad_msgs.msg import Scene as SceneMsg
from rad_msgs.msg import Studs as StudsMsg

MAX_SCENE_JSON_BYTES = 10 * 1024 * 1024


def cells_msg(cells) -> list:
    return [Cell(i=int(c[0]), j=int(c[1]), k=int(c[2])) for c in cells]


def _ijk(cells) -> list[list[int]]:
    return [[c.i, c.j, c.k] for c in cells]


def scene_to_msg(scene: Scene, frame_id: str = 'world') -> SceneMsg:
    """The scene as a message."""
    msg = SceneMsg()
    msg.clearance = float(scene.clearance)
    msg.header.frame_id = frame_id
    msg.unit = float(scene.unit)
    msg.block_types = [BlockType(name=t.name, cells=cells_msg(t.offsets)) for t in scene.block_types.values()]
    msg.blocks = [Block(id=b.id, type=b.type, position=Point(x=b.position[0], y=b.position[1], z=b.position[2]),
                        yaw_deg=int(b.yaw)) for b in scene.blocks]
    msg.targets = [TargetRegion(name=t.name, origin=Point(x=t.origin[0], y=t.origin[1], z=t.origin[2]),
                                size=[int(v) for v in t.size], filled=cells_msg(t.filled)) for t in scene.targets]
    if scene.feeder is not None:
        f = scene.feeder
        msg.feeder = [FeederMsg(station_x=float(f.station[0]), station_y=float(f.station[1]), yaw_deg=int(f.yaw),
                                order=f.order, window=int(f.window), blocks=list(f.blocks))]
    if scene.studs is not None:
        s = scene.studs
        msg.studs = [StudsMsg(system=s.system, course=float(s.course), clutch=float(s.clutch), mass=float(s.mass),
                              baseplate=bool(s.baseplate))]
    return msg


def scene_msg_to_dict(msg: SceneMsg) -> dict:
    """The rad-scene/1 document a scene message stands for (not yet validated)."""
    return {
        'format': FORMAT,
        'unit': msg.unit,
        **({'clearance': msg.clearance} if msg.clearance else {}),
        'block_types': {t.name: _ijk(t.cells) for t in msg.block_types},
        'blocks': [{'id': b.id, 'type': b.type, 'position': [b.position.x, b.position.y, b.position.z],
                    'yaw': b.yaw_deg} for b in msg.blocks],
        'targets': [{'name': t.name, 'origin': [t.origin.x, t.origin.y, t.origin.z],
                     'size': [int(v) for v in t.size], 'filled': _ijk(t.filled)} for t in msg.targets],
        **{'feeder': {'station': [f.station_x, f.station_y], 'yaw': f.yaw_deg, 'order': f.order,
                      **({'window': int(f.window)} if f.order == 'queue' else {}), 'blocks': list(f.blocks)}
           for f in msg.feeder[:1]},
        **{'studs': {'system': s.system, 'course': s.course, 'clutch': s.clutch, 'mass': s.mass,
                     **({'baseplate': True} if s.baseplate else {})}
           for s in msg.studs[:1]},
    }


def scene_from_msg(msg: SceneMsg) -> Scene:
    doc = scene_msg_to_dict(msg)
    names = [t.name for t in msg.block_types]
    if len(set(names)) != len(names):
        raise RadError('block_types: a type name appears twice')
    return Scene.from_dict(doc)


def scene_msg_is_empty(msg: SceneMsg) -> bool:
    return not (msg.block_types or msg.blocks or msg.targets or msg.unit)


def scene_from_request(msg: SceneMsg, scene_json: str) -> Scene:
    """The scene of a request that carries it as a message or as JSON text, not both."""
    has_msg, has_json = not scene_msg_is_empty(msg), bool(scene_json.strip())
    if has_msg and has_json:
        raise RadError('give the scene either as a message or as scene_json, not both')
    if has_json:
        size = len(scene_json.encode())
        if size > MAX_SCENE_JSON_BYTES:
            raise RadError(f'scene_json is {size} bytes, more than the limit of {MAX_SCENE_JSON_BYTES}')
        return Scene.loads(scene_json)
    if has_msg:
        return scene_from_msg(msg)
    raise RadError('no scene given: fill the scene message or scene_json')


def placement_to_msg(p: CorePlacement) -> Placement:
    return Placement(type=p.type, target=p.target, yaw_deg=int(p.yaw), cells=cells_msg(p.cells))


def placement_from_msg(msg: Placement) -> CorePlacement:
    return CorePlacement(msg.type, msg.target, int(msg.yaw_deg), tuple(tuple(c) for c in _ijk(msg.cells)))


def fill_allocation_response(response, result: AllocationResult):
    """Copy an allocation result into an Allocate response (or any with the same fields)."""
    response.success = result.has_solution
    response.reason = '' if result.has_solution else f'the solver found no allocation (status {result.status})'
    response.status = result.status
    response.objective = float(result.objective)
    response.bound = float(result.bound)
    response.solve_time_s = float(result.solve_time_s)
    response.placements = [placement_to_msg(p) for p in result.placements]
    return response


def allocation_from_response(response) -> AllocationResult:
    return AllocationResult(response.status, response.objective, response.bound, response.solve_time_s,
                            tuple(placement_from_msg(p) for p in response.placements))


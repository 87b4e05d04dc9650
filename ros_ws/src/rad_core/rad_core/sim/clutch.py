"""Studs that hold in the physics world: a brick pressed home is joined to the bricks under it, one
joint per stud, and a joint lets go when it is pulled harder than the clutch.

The model is the statics' (`rad_core.domain.statics`): contacts push, studs pull. Each stud is a
point-to-point joint at the centre of the unit square where the two bricks meet, its force capped
at the scene's clutch (N, ``studs.clutch``). Contacts stay Bullet's own, so a brick tipping about
an edge of what holds it lifts the studs on the far side, which pull it back up to their clutch;
a stud pulled harder stretches, and once it has stretched `BREAK_STRETCH` it is broken for good
(its force set to 0, as a stud that popped off stays off until the brick is pressed again).
Across the stud a joint gives way only after `BREAK_SLIDE`: a stud in its socket is held sideways by
its shape, not by the clutch, so a brick pushed along the one under it comes back to its seat
(its joints pull it there) where a millimetre's slide broke its studs before, and a cantilever
held by one column of studs fell with it.

Only bricks pressed home are joined (`join`): the twin's press, or a teleported placement, which
stands for one. On a baseplate (``studs.baseplate``) a brick pressed onto the table is joined to it
in the same way, at the studs of the target's lattice (`TABLE` its lower id). A brick set down
unpressed only rests. Joints are part of a world's snapshot: restored, a world has the joints,
broken or not, it had then.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BREAK_STRETCH = 0.001
"""How far (m) a stud's joint may stretch, the upper brick lifted off its seat or slid along it,
before it counts as pulled off. Pushed further onto its seat (a press, a load) it holds: contacts
bear that."""

BREAK_SLIDE = 0.1
"""How far (a fraction of the unit) a stud's joint may be slid along the brick under it before it
counts as pushed off its stud: a brick that slides that far has left its socket."""

TABLE = '(table)'
"""The lower id of a stud joint that holds a brick onto a baseplate (`World.table`)."""

SEATED = 0.15
"""How far (a fraction of the unit, and of the course height) a brick may sit off the lattice above
the brick under it and still be pressed home onto its studs."""


@dataclass
class Stud:
    """One stud joint: the constraint, the upper and lower block ids, where it sits in each body's
    inertial frame, whether it has let go."""

    constraint: int
    upper: str
    lower: str
    in_upper: tuple
    in_lower: tuple
    broken: bool = False


class StudJoints:
    """The stud joints of one world (module docstring)."""

    def __init__(self):
        self.studs: dict[int, Stud] = {}
        self.broken: list[tuple[str, str]] = []
        """(upper, lower) of every connection that let go since the last `take_broken`."""

    def clear(self) -> None:
        self.studs.clear()
        self.broken.clear()

    def join(self, world, block_id: str) -> list[str]:
        """Join a brick to the bricks its bottom units sit on within `SEATED`, one joint per stud;
        the ids it was joined to (none in a scene without studs)."""
        scene = world.scene
        if scene is None or scene.studs is None or self.joined(block_id):
            return []
        p, cid = world.pybullet, world.client
        found = _seated_on(world, block_id)
        upper = world.blocks[block_id]
        half = np.array([0.0, 0.0, scene.course / 2])
        for other, pairs in found.items():
            lower = _body(world, other)
            for i, j in pairs:
                # Each stud where the lattice puts it in both bricks (the middle of the face they share),
                # not where they happen to be: the joint pulls a brick still pressed in, or a hair off,
                # to its seat.
                in_upper = world.in_inertial_frame(block_id, _offset(world, block_id, i) - half)
                in_lower = (_in_table(world, block_id, j) if other == TABLE
                            else world.in_inertial_frame(other, _offset(world, other, j) + half))
                c = p.createConstraint(lower, -1, upper, -1, p.JOINT_POINT2POINT, [0, 0, 0],
                                       parentFramePosition=in_lower, childFramePosition=in_upper,
                                       physicsClientId=cid)
                p.changeConstraint(c, maxForce=float(scene.studs.clutch), physicsClientId=cid)
                self.studs[c] = Stud(c, block_id, other, in_upper, in_lower)
        return sorted(found)

    def joined(self, block_id: str) -> bool:
        """Whether the brick holds onto the studs under it (a stud of it, not broken)."""
        return any(s.upper == block_id and not s.broken for s in self.studs.values())

    def unpressed(self, world, block_id: str) -> bool:
        """Whether the brick stands on the studs of a brick under it, within `SEATED` of its seat, without
        being joined to them: set down or knocked loose, never pressed home. Bricks only: a brick that
        rests on a baseplate unpressed is not told from one lying on the table."""
        scene = world.scene
        return (scene is not None and scene.studs is not None and not self.joined(block_id)
                and bool(set(_seated_on(world, block_id)) - {TABLE}))

    def let_go(self, world, block_id: str) -> list[str]:
        """Break every stud that holds the brick onto the bricks under it (a knock); the lower ids."""
        p, cid = world.pybullet, world.client
        out = []
        for stud in self.studs.values():
            if stud.upper == block_id and not stud.broken:
                _give_way(p, cid, stud)
                out.append(stud.lower)
        self.broken.extend((block_id, lower) for lower in out)
        return sorted(set(out))

    def check(self, world) -> list[tuple[str, str]]:
        """Break the studs lifted more than `BREAK_STRETCH` off their seat or slid more than `BREAK_SLIDE`
        along it; the (upper, lower) connections that lost a stud now."""
        p, cid = world.pybullet, world.client
        slide = BREAK_SLIDE * world.scene.unit
        out = []
        for stud in self.studs.values():
            if stud.broken:
                continue
            d = _world(p, cid, world.blocks[stud.upper], stud.in_upper) - _world(p, cid, _body(world, stud.lower),
                                                                                  stud.in_lower)
            if d[2] > BREAK_STRETCH or np.hypot(d[0], d[1]) > slide:
                _give_way(p, cid, stud)
                out.append((stud.upper, stud.lower))
        self.broken.extend(out)
        return out

    def state(self) -> dict:
        return {c: (s.broken,) for c, s in self.studs.items()}

    def restore(self, world, state: dict) -> None:
        """Back to `state` (from `state()`): joints made since are gone (the world removed their
        constraints), broken ones hold again where they held then."""
        p, cid = world.pybullet, world.client
        for c in list(self.studs):
            if c not in state:
                del self.studs[c]
        for c, (broken,) in state.items():
            stud = self.studs.get(c)
            if stud is not None and stud.broken != broken:
                stud.broken = broken
                limit = 0.0 if broken else float(world.scene.studs.clutch)
                p.changeConstraint(c, maxForce=limit, physicsClientId=cid)


def _give_way(p, cid: int, stud: Stud) -> None:
    """The stud lets go for good: broken, its joint's force 0."""
    stud.broken = True
    p.changeConstraint(stud.constraint, maxForce=0.0, physicsClientId=cid)


def _body(world, block_id: str) -> int:
    return world.table if block_id == TABLE else world.blocks[block_id]


def _table_studs(world) -> np.ndarray | None:
    """Where the baseplate's studs are: the target lattice's columns at the table's top, as an
    origin (x, y, 0) they lie at whole pitches from; None without a baseplate."""
    scene = world.scene
    if scene.studs is None or not scene.studs.baseplate or not scene.targets:
        return None
    return np.array([*scene.targets[0].origin[:2], 0.0])


def _table_seats(world, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(per unit centre, whether it is seated on a baseplate stud; the stud's world point), None
    without a baseplate. A seated bottom unit lies within `SEATED` of a target lattice column at
    the table's top."""
    studs = _table_studs(world)
    if studs is None:
        return None
    pitch = world.scene.pitch
    steps = (centres - studs) / pitch - (0.0, 0.0, 0.5)
    near = np.rint(steps)
    seated = np.all(np.abs(steps - near) < SEATED, axis=1) & (near[:, 2] == 0)
    return seated, studs + near * pitch


def _in_table(world, block_id: str, unit: int) -> list[float]:
    """The baseplate stud under a brick's unit, in the table body's frame."""
    p, cid = world.pybullet, world.client
    point = _table_seats(world, world.unit_centres(block_id))[1][unit]
    pos, orn = p.getBasePositionAndOrientation(world.table, physicsClientId=cid)
    inv_pos, inv_orn = p.invertTransform(pos, orn)
    local, _ = p.multiplyTransforms(inv_pos, inv_orn, point.tolist(), [0, 0, 0, 1])
    return list(local)


def _seated_on(world, block_id: str) -> dict[str, list[tuple[int, int]]]:
    """The bricks the brick's units sit on within `SEATED` of the lattice: other id -> [(unit of this
    brick, unit of the other)]; on a baseplate, `TABLE` -> [(unit, unit)] for its units seated on
    the table's studs (`_table_seats`)."""
    mine = world.unit_centres(block_id)
    pitch = world.scene.pitch
    found: dict[str, list[tuple[int, int]]] = {}
    seats = _table_seats(world, mine)
    if seats is not None and seats[0].any():
        found[TABLE] = [(int(u), int(u)) for u in np.nonzero(seats[0])[0]]
    for other in world.blocks:
        if other == block_id or other in world.parked:
            continue
        theirs = world.unit_centres(other)
        gap = (mine[:, None, :] - pitch * (0, 0, 1)) - theirs[None, :, :]
        seated = np.all(np.abs(gap) < SEATED * pitch, axis=-1)
        if seated.any():
            found[other] = list(zip(*np.nonzero(seated)))
    return found


def _offset(world, block_id: str, unit: int) -> np.ndarray:
    """The centre of a block's unit in its own frame (its yaw turns the frame, not the offsets)."""
    scene = world.scene
    return np.asarray(scene.block_types[scene.block(block_id).type].offsets[unit], dtype=float) * scene.pitch


def _world(p, cid: int, body: int, local) -> np.ndarray:
    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
    point, _ = p.multiplyTransforms(pos, orn, list(local), [0, 0, 0, 1])
    return np.asarray(point)

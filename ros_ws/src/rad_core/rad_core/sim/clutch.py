"""Studs that hold in the physics world: a brick pressed home is joined to the bricks under it, one
joint per stud, and a joint lets go when it is pulled harder than the clutch.

The model is the statics' (`rad_core.domain.statics`): contacts push, studs pull. Each stud is a
point-to-point joint at the centre of the unit square where the two bricks meet, its force capped
at the scene's clutch (N, ``studs.clutch``). Contacts stay Bullet's own, so a brick tipping about
an edge of what holds it lifts the studs on the far side, which pull it back up to their clutch;
a stud pulled harder stretches, and once it has stretched `BREAK_STRETCH` it is broken for good
(its force set to 0, as a stud that popped off stays off until the brick is pressed again).

Only bricks pressed home are joined (`join`): the twin's press, or a teleported placement, which
stands for one. A brick set down unpressed only rests. Joints are part of a world's snapshot:
restored, a world has the joints, broken or not, it had then.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BREAK_STRETCH = 0.001
"""How far (m) a stud's joint may stretch before it counts as pulled off."""

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
        if scene is None or scene.studs is None or any(
                s.upper == block_id and not s.broken for s in self.studs.values()):
            return []
        p, cid = world.pybullet, world.client
        mine = world.unit_centres(block_id)
        pitch = scene.pitch
        found: dict[str, list[np.ndarray]] = {}
        for other in world.blocks:
            if other == block_id or other in world.parked:
                continue
            theirs = world.unit_centres(other)
            gap = (mine[:, None, :] - pitch * (0, 0, 1)) - theirs[None, :, :]
            seated = np.all(np.abs(gap) < SEATED * pitch, axis=-1)
            for i, j in zip(*np.nonzero(seated)):
                found.setdefault(other, []).append((mine[i] + theirs[j]) / 2)
        upper = world.blocks[block_id]
        for other, points in found.items():
            lower = world.blocks[other]
            for point in points:
                pivot = [float(point[0]), float(point[1]), float(point[2])]
                in_upper = _local(p, cid, upper, pivot)
                in_lower = _local(p, cid, lower, pivot)
                c = p.createConstraint(lower, -1, upper, -1, p.JOINT_POINT2POINT, [0, 0, 0],
                                       parentFramePosition=in_lower, childFramePosition=in_upper,
                                       physicsClientId=cid)
                p.changeConstraint(c, maxForce=float(scene.studs.clutch), physicsClientId=cid)
                self.studs[c] = Stud(c, block_id, other, in_upper, in_lower)
        return sorted(found)

    def joined_above(self, block_id: str) -> set[str]:
        """Blocks joined on top of this one (unbroken studs)."""
        return {s.upper for s in self.studs.values() if s.lower == block_id and not s.broken}

    def check(self, world) -> list[tuple[str, str]]:
        """Break the studs stretched more than `BREAK_STRETCH`; the (upper, lower) connections that
        lost a stud now."""
        p, cid = world.pybullet, world.client
        out = []
        for stud in self.studs.values():
            if stud.broken:
                continue
            a = _world(p, cid, world.blocks[stud.upper], stud.in_upper)
            b = _world(p, cid, world.blocks[stud.lower], stud.in_lower)
            if np.linalg.norm(a - b) > BREAK_STRETCH:
                stud.broken = True
                p.changeConstraint(stud.constraint, maxForce=0.0, physicsClientId=cid)
                out.append((stud.upper, stud.lower))
        self.broken.extend(out)
        return out

    def release(self, world, block_id: str) -> None:
        """Let go of every stud of a brick, above and below it (it is lifted off, or removed)."""
        p, cid = world.pybullet, world.client
        for c, stud in list(self.studs.items()):
            if block_id in (stud.upper, stud.lower):
                p.removeConstraint(c, physicsClientId=cid)
                del self.studs[c]

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


def _local(p, cid: int, body: int, point) -> list[float]:
    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
    inv_pos, inv_orn = p.invertTransform(pos, orn)
    local, _ = p.multiplyTransforms(inv_pos, inv_orn, point, [0, 0, 0, 1])
    return list(local)


def _world(p, cid: int, body: int, local) -> np.ndarray:
    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
    point, _ = p.multiplyTransforms(pos, orn, list(local), [0, 0, 0, 1])
    return np.asarray(point)

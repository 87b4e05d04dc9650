"""Collision probes for GAMP: callables built over a World, as motion planners want them.

`make_collision_fn(world, ...)` returns ``fn(q) -> reason`` ('' when free). It
moves the robot (and the carried block) in the world, so call it only inside
``world.preserved()``; the planner wraps a whole plan in one such block.

What counts as a collision:
- a robot link (base excluded: it stands on the table) closer than
  ``robot_margin`` to the table or to any block not excluded;
- two robot links that are not rigidly joined and closer than ``self_margin``;
- the carried block penetrating another block or the table by more than
  ``block_penetration``: its collision boxes are a hair narrower than a unit at
  the sides and a hair taller (see sim.world), so face contact with a neighbour
  or the block below reads as distance ~0, an overlap of a real cube as -unit.

Candidates are pruned by bounding boxes (each link's against the obstacles', read
when the probe is made; link pairs by theirs, and `NEVER_TOUCHING` pairs not at all)
and then measured exactly with getClosestPoints. A probe function reads where the
obstacles are once: make a new one after moving a block.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from rad_core.cell import panda
from rad_core.sim.world import World

CollisionFn = Callable[[np.ndarray], str]

# Links that move rigidly together (link7, link8, hand) and the fingers on the hand
# are never checked against each other; nor are neighbours in the chain.
_WRIST_GROUP = ('panda_link7', 'panda_link8', 'panda_hand', 'panda_leftfinger', 'panda_rightfinger')
_LINK_LABEL = {'panda_hand': 'hand', 'panda_leftfinger': 'left finger', 'panda_rightfinger': 'right finger'}


@dataclass(frozen=True)
class CollisionConfig:
    """Clearances of the collision probes (m)."""

    robot_margin: float = 0.002
    """The robot must keep this far from the table and from blocks."""
    self_margin: float = 0.0
    """Robot links must not touch each other."""
    block_penetration: float = 0.002
    """The carried block may touch others (face contact) but not sink in deeper than this:
    room for the IK residual (accepted up to 2 mm, usually under 0.2 mm) that places
    the held block; a real overlap of two cubes reads as a whole unit."""


@dataclass(frozen=True)
class Attachment:
    """A block held in the hand: its anchor frame expressed in the grasp-target frame."""

    block_id: str
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]


def attachment_from_world(world: World, block_id: str) -> Attachment:
    """The attachment that holds a block where it is now, relative to the grasp target now."""
    p = world.pybullet
    ee_pos, ee_orn = world.link_pose()
    b_pos, b_orn = world.block_pose(block_id)
    inv_pos, inv_orn = p.invertTransform(ee_pos.tolist(), ee_orn.tolist())
    pos, orn = p.multiplyTransforms(inv_pos, inv_orn, b_pos.tolist(), b_orn.tolist())
    return Attachment(block_id, tuple(pos), tuple(orn))


def place_attached(world: World, attachment: Attachment) -> None:
    """Move the held block to where the hand holds it now (every probe of a carrying plan does)."""
    p, cid = world.pybullet, world.client
    state = p.getLinkState(world.robot, world.ee_link, computeForwardKinematics=True, physicsClientId=cid)
    pos, orn = p.multiplyTransforms(state[4], state[5], attachment.position, attachment.quaternion)
    world.set_block_pose(attachment.block_id, pos, orn)


def robot_links(world: World) -> list[int]:
    """Robot links that can hit something (base and shapeless links left out)."""
    p, cid = world.pybullet, world.client
    names = {v: k for k, v in world.link_index.items()}
    return [j for j in sorted(names) if names[j] != 'panda_link1' and names[j] != 'panda_grasptarget'
            and p.getCollisionShapeData(world.robot, j, physicsClientId=cid)]


NEVER_TOUCHING = (('panda_link1', 'panda_link3'), ('panda_link2', 'panda_link4'), ('panda_link3', 'panda_link5'),
                  ('panda_link4', 'panda_link6'), ('panda_link6', 'panda_hand'))
"""Panda link pairs that cannot touch anywhere in the URDF's joint ranges, so a probe of a
configuration within them skips them. Each pair's relative pose depends on the one or two joints
between them only; over those joints' URDF ranges on a 0.02 rad grid they are never nearer than
11.5, 4.0, 4.3, 13.0 and 2.8 cm, and no point of a link is 0.6 m from those joints' axes, so
between grid points nothing moves more than 0.6 m/rad x 0.01 rad per joint: 1.2 cm at most, and
the pairs stay 1.6 cm apart or more
(tests/core/test_gamp.py::test_never_touching_pairs_stay_apart_over_their_joints_ranges). Their
boxes overlap in most probes of a plan, so skipping them saves a measurement each."""


def self_collision_pairs(world: World) -> list[tuple[int, int]]:
    """Link pairs that can meet: not chain neighbours, not both in the wrist group."""
    links = [-1, world.link_index['panda_link1']] + robot_links(world)
    wrist = {world.link_index[n] for n in _WRIST_GROUP}
    return [(a, b) for i, a in enumerate(links) for b in links[i + 1:]
            if b - a >= 2 and not (a in wrist and b in wrist)]


def make_collision_fn(world: World, exclude: Iterable[str] = (), attached: Attachment | None = None,
                      config: CollisionConfig = CollisionConfig(), remember: bool = False) -> CollisionFn:
    """fn(q) -> '' when configuration q (9,) is free, else what collides (one reason).

    exclude: block ids the robot may touch (none, usually). The attached block is
    never an obstacle of the robot (the fingers hold it), but it is checked
    against every other block and the table.

    remember: answer a configuration probed before in the same world state (every block's
    and obstacle's pose, the table, exclude, attachment, margins: `world_key` when fn is
    made) from memory (`_MEMO`), after posing the robot and the held block at q as the probe
    does. Only for callers that move nothing but the robot and the held block between
    probes of one fn (the planner: each fn is made where the world stays put).
    """
    if not remember:
        return _make_probe(world, exclude, attached, config)
    memo = _memo_for(world, world_key(world, exclude, attached, config))
    probe = None            # made at the first configuration not in memory (often none is)

    def collision(q: np.ndarray) -> str:
        nonlocal probe
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        reason = memo.get(key)
        if reason is None:
            if probe is None:
                probe = _make_probe(world, exclude, attached, config)
            reason = memo[key] = probe(q)
        else:
            # What the probe leaves behind: the robot at q, the held block in the hand.
            world.set_joint_positions(q, hold=False)
            if attached is not None:
                place_attached(world, attached)
        return reason

    return collision


# World -> {world key -> {q bytes -> reason}}: answers of remembering probes. The key pins
# everything a probe reads besides q, so an answer is reused only where the same probe
# would run again on the same bodies in the same poses. Bounded: cleared when it grows large.
_MEMO: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_MEMO_MAX_STATES = 256


def _memo_for(world: World, key: tuple) -> dict:
    states = _MEMO.setdefault(world, {})
    if key not in states and len(states) >= _MEMO_MAX_STATES:
        states.clear()
    return states.setdefault(key, {})


def world_key(world: World, exclude, attached: Attachment | None, config: CollisionConfig) -> tuple:
    """What a probe's answer depends on besides q: the bodies (ids, names, types, unit), their
    poses as Bullet holds them (the held block's comes from q and the attachment), the table, the
    excluded blocks, the attachment and the margins."""
    p, cid = world.pybullet, world.client
    held = attached.block_id if attached is not None else None
    scene = world.scene
    shapes = ((scene.unit, scene.course, scene.clearance, tuple(b.type for b in scene.blocks),
               tuple(o.type for o in scene.obstacles)) if scene is not None else None)
    blocks = tuple((bid, body, None if bid == held else p.getBasePositionAndOrientation(body, physicsClientId=cid))
                   for bid, body in world.blocks.items())
    obstacles = tuple((oid, body, p.getBasePositionAndOrientation(body, physicsClientId=cid))
                      for oid, body in world.obstacles.items())
    table = (world.table, p.getAABB(world.table, -1, physicsClientId=cid))
    return shapes, blocks, obstacles, table, frozenset(exclude), attached, config


def _make_probe(world: World, exclude, attached: Attachment | None, config: CollisionConfig) -> CollisionFn:
    """The collision check of `make_collision_fn`, run every time."""
    p, cid, robot = world.pybullet, world.client, world.robot
    exclude = set(exclude)
    if attached is not None:
        exclude.add(attached.block_id)
    names = {body: f'block {bid}' for bid, body in world.blocks.items()}
    names.update({body: f'block {bid} (set aside)' for bid, body in world.obstacles.items()})
    names[world.table] = 'the table'
    obstacles = ({body for bid, body in world.blocks.items() if bid not in exclude} | {world.table}
                 | set(world.obstacles.values()))
    # Bodies are looked at in a fixed order, the table, then the scene's blocks and set-aside blocks
    # in scene order, so the body a reason names ('hand hits block b4'), which moving neighbours
    # aside acts on, does not depend on the ids Bullet gave them: a world that loaded other scenes
    # before hands out freed ids again, in another order (seen: the same scene planned after nine
    # others named b5 where a fresh world named b4).
    rank = {body: k for k, body in enumerate([world.table, *world.blocks.values(), *world.obstacles.values()])}
    link_name = {v: _LINK_LABEL.get(k, k.replace('panda_', '')) for k, v in world.link_index.items()}
    link_name[-1] = 'base'
    links = robot_links(world)
    pairs = self_collision_pairs(world)
    box_links = sorted({a for pair in pairs for a in pair} | set(links))
    row = {link: i for i, link in enumerate(box_links)}
    link_rows = np.array([row[link] for link in links], dtype=np.int64)
    pair_a = np.array([row[a] for a, _ in pairs], dtype=np.int64)
    pair_b = np.array([row[b] for _, b in pairs], dtype=np.int64)
    never = {(world.link_index[a], world.link_index[b]) for a, b in NEVER_TOUCHING
             if a in world.link_index and b in world.link_index}
    may_touch = np.array([pair not in never for pair in pairs])
    urdf_low, urdf_high = panda.URDF_LOWER[:7], panda.URDF_UPPER[:7]
    carried = world.blocks[attached.block_id] if attached is not None else None
    m, s = config.robot_margin, config.self_margin
    # The obstacles in rank order with their bounding boxes, read once: they stay put while fn is used.
    # A body whose box (which holds its collision shape) does not come within the margin of a link's
    # box cannot be within it of the link, so only those that do are measured, in rank order (the order
    # Bullet's broadphase queries return; those also return bodies whose box only comes near, and
    # measuring those finds nothing).
    order = sorted(obstacles, key=rank.__getitem__)
    obstacle_box = np.array([p.getAABB(body, -1, physicsClientId=cid) for body in order]).reshape(len(order), 2, 3)
    low_m, high_m = obstacle_box[:, 0] - m, obstacle_box[:, 1] + m      # grown by the margin
    # The carried block is never its own obstacle.
    carried_rows = np.array([k for k, body in enumerate(order) if body != carried], dtype=np.int64)
    carried_low, carried_high = obstacle_box[carried_rows, 0], obstacle_box[carried_rows, 1]
    joints, zeros = world.joints, [[0.0]] * len(world.joints)
    get_aabb, closest = p.getAABB, p.getClosestPoints

    def collision(q: np.ndarray) -> str:
        # world.set_joint_positions(q, hold=False), the robot's joints in one reset command.
        q = np.asarray(q, dtype=float).ravel()
        values = q.tolist()
        if len(values) != 9 or not math.isfinite(sum(values)):
            world.set_joint_positions(q, hold=False)            # a 7-joint q, or raises naming the problem
        else:
            p.resetJointStatesMultiDof(robot, joints, [[v] for v in values], zeros, physicsClientId=cid)
        if carried is not None:
            # The held block first: its overlap is the more telling reason at a placement.
            place_attached(world, attached)
            lo, hi = get_aabb(carried, -1, physicsClientId=cid)
            for k in carried_rows[(carried_low <= hi).all(axis=1) & (carried_high >= lo).all(axis=1)]:
                pts = closest(carried, order[k], 0.0, physicsClientId=cid)
                if any(pt[8] < -config.block_penetration for pt in pts):
                    return f'carried block hits {names[order[k]]}'
        box = np.array([get_aabb(robot, link, physicsClientId=cid) for link in box_links])   # (links, lo/hi, xyz)
        arm = box[link_rows]
        # (links, obstacles): the obstacle's box within the margin of the link's.
        near = ((arm[:, None, 0] <= high_m) & (arm[:, None, 1] >= low_m)).all(axis=2)
        for i, k in zip(*near.nonzero()):                       # links in order, bodies in rank order
            pts = closest(robot, order[k], m, linkIndexA=links[i], physicsClientId=cid)
            if any(pt[8] < m for pt in pts):
                return f'{link_name[links[i]]} hits {names[order[k]]}'
        # Links whose bounding boxes (which hold their collision shapes, margins included) are
        # farther apart than self_margin along an axis cannot be closer than it: no contact
        # point below the margin, so no need to ask for one (`_apart`, for all pairs at once).
        a_box, b_box = box[pair_a], box[pair_b]
        touching = ((a_box[:, 0] <= b_box[:, 1] + s) & (b_box[:, 0] <= a_box[:, 1] + s)).all(axis=1)
        if s <= 0.0 and ((urdf_low <= q[:7]) & (q[:7] <= urdf_high)).all():
            touching &= may_touch                                # NEVER_TOUCHING
        for k in touching.nonzero()[0]:
            a, b = pairs[k]
            pts = closest(robot, robot, s, linkIndexA=a, linkIndexB=b, physicsClientId=cid)
            if any(pt[8] < s for pt in pts):
                return f'self-collision {link_name[a]} / {link_name[b]}'
        return ''

    return collision


def _apart(box_a, box_b, gap: float) -> bool:
    """Whether two axis-aligned boxes ((lo, hi), (lo, hi)) are more than `gap` apart along some axis."""
    (alo, ahi), (blo, bhi) = box_a, box_b
    return (alo[0] > bhi[0] + gap or blo[0] > ahi[0] + gap or alo[1] > bhi[1] + gap or blo[1] > ahi[1] + gap
            or alo[2] > bhi[2] + gap or blo[2] > ahi[2] + gap)


def check_path(collision_fn: CollisionFn, q_from: np.ndarray, q_to: np.ndarray,
               max_step: float = 0.05) -> str:
    """Probe the straight joint-space segment q_from -> q_to at intermediate points no
    more than max_step (rad, or m for fingers) apart, end point included, start
    excluded (it was checked as the previous waypoint). '' when free."""
    q_from, q_to = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    n = max(1, int(np.ceil(np.max(np.abs(q_to - q_from)) / max_step)))
    for k in range(1, n + 1):
        reason = collision_fn(q_from + (q_to - q_from) * (k / n))
        if reason:
            return reason
    return ''

"""GAMP: grasps, a real pick-and-place plan, and each failure class for the right reason."""

import math
from pathlib import Path

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.cell import panda
from rad_core.cell.motion import GripperCommand, Motion
from rad_core.cell.robot_model import PANDA, robot_model
from rad_core.cell.trajectory import limit_ratios
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_of_quaternion
from rad_core.gamp import GampResult, Grasp, allocated_pose, block_grasps, placement_pose, plan_action
from rad_core.gamp.collision import (
    CollisionConfig,
    _apart,
    attachment_from_world,
    make_collision_fn,
    place_attached,
    robot_links,
    self_collision_pairs,
)
from rad_core.gamp.ik import solve_pose, solve_top_down
from rad_core.sim.world import World

U = 0.05


def _scene(blocks, unit=U, types=None):
    """A hand-made scene: cubes (or given types) at free positions, a target region out of the way."""
    types = types or {'cube': [[0, 0, 0]]}
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': unit, 'block_types': types,
        'blocks': [{'id': bid, 'type': t, 'position': list(pos), 'yaw': 0} for bid, t, pos in blocks],
        'targets': [{'name': 't', 'origin': [0.4, 0.35, unit / 2], 'size': [2, 1, 2], 'filled': [[0, 0, 0]]}],
    })


def _yaw_quat(yaw):
    return [0, 0, math.sin(math.radians(yaw) / 2), math.cos(math.radians(yaw) / 2)]


# ---- grasps ----------------------------------------------------------------

def test_grasp_rule_on_the_library():
    lib = DEFAULT_LIBRARY
    assert set(block_grasps(lib['cube'])) == {Grasp(0, 0), Grasp(0, 90)}
    # A flat bar is taken across, never along (a finger would land on the next unit).
    assert set(block_grasps(lib['I2'])) == {Grasp(0, 90), Grasp(1, 90)}
    assert block_grasps(lib['I3'])[0] == Grasp(1, 90)          # the middle unit first
    # Upright: only the top unit; the bottom one is covered.
    assert {g.unit for g in block_grasps(lib['I2_up'])} == {1}
    # L3_up: unit 1 (beside the column) only across, the column's top both ways.
    assert set(block_grasps(lib['L3_up'])) == {Grasp(2, 0), Grasp(2, 90), Grasp(1, 90)}
    for btype in lib.values():
        assert block_grasps(btype), btype.name
        assert not block_grasps(btype, unit_size=0.075)         # wider than the open hand


# ---- a real action ---------------------------------------------------------

@pytest.fixture(scope='module')
def generated():
    scene = generate_scene(GeneratorConfig(grid=4), seed=1)
    alloc = solve(scene, AllocationParams(time_limit_s=5.0))
    with World(scene) as world:
        yield scene, alloc, world


def _replay(world, result, block_id):
    """Kinematic execution of the motion: the arm to each point of each trajectory, the fingers as
    the gripper commands set them; the block rides with the hand from the grasp to the release.
    Returns the block's final pose."""
    with world.preserved():
        attachment = None
        q = world.joint_positions()
        for command in result.motion.sequence():
            if isinstance(command, GripperCommand):
                q[7:] = command.expected_position if command.action == 'grasp' else command.position
                world.set_joint_positions(q)
                if command.action == 'grasp':
                    attachment = attachment_from_world(world, block_id)
                elif command.action == 'release':
                    attachment = None
                continue
            for pt in command.points:
                q[:7] = pt.positions
                world.set_joint_positions(q)
                if attachment is not None:
                    place_attached(world, attachment)
        return world.block_pose(block_id)


def test_free_block_is_picked_and_placed_at_its_allocated_pose(generated):
    scene, alloc, world = generated
    placement = next(p for p in alloc.placements if p.type == 'I2_up')
    block = next(b for b in scene.blocks if b.type == 'I2_up')
    position, yaw = allocated_pose(scene, placement)
    joints_before = world.joint_positions()
    poses_before = {b: world.block_pose(b)[0] for b in world.blocks}

    r = plan_action(world, block.id, position, yaw)
    assert isinstance(r, GampResult)
    assert r.success and r.failure == '' and r.reason == '', r.reason
    motion = r.motion
    # Arm and hand apart: three arm trajectories (approach, carry, retreat) of the 7 arm joints, the
    # hand set to the approach opening first, then grasp and release between them.
    assert len(motion.trajectories) == 3
    assert [(g.action, g.before) for g in motion.gripper] == [('close', 0), ('open', 0), ('grasp', 1), ('release', 2)]
    grasp = motion.gripper[2]
    assert grasp.expected_position == pytest.approx(U / 2) and grasp.position == pytest.approx(U / 2 - 0.001)
    assert motion.gripper[1].position == motion.gripper[3].position == pytest.approx(U / 2 + 0.01)
    start = joints_before[:7]
    for traj in motion.trajectories:
        assert traj.joint_names == panda.ARM_JOINT_NAMES
        times = traj.times()
        assert times[0] > 0 and np.all(np.diff(times) > 0)
        q = traj.positions()
        assert q.shape[1] == 7 and all(panda.within_limits(row) for row in q)
        assert all(len(p.velocities) == len(p.accelerations) == 7 for p in traj.points)
        assert not np.any(traj.points[-1].velocities) and not np.any(traj.points[-1].accelerations)
        # Within the Panda's and the FR3's limits at the configured scales (velocity 0.7), as the
        # controller interpolates it at 1 kHz.
        for model in (PANDA, robot_model('fr3', 'panda')):
            ratios = limit_ratios(traj, start, model)
            assert ratios['velocity'] <= 0.7 and ratios['acceleration'] <= 1.0 and ratios['jerk'] <= 1.0, ratios
        start = q[-1]
    # Executed kinematically, the block ends at the allocated pose.
    final_pos, final_quat = _replay(world, r, block.id)
    assert np.linalg.norm(final_pos - position) < 0.002
    assert abs(((yaw_of_quaternion(final_quat) - yaw) + 180) % 360 - 180) < 2.0
    # The result's dict form is the JointTrajectory shape result.json uses, with accelerations.
    doc = motion.to_dict()
    assert set(doc) == {'trajectories', 'gripper'}
    assert set(doc['trajectories'][0]) == {'joint_names', 'points'}
    assert set(doc['trajectories'][0]['points'][0]) == {'positions', 'velocities', 'accelerations', 'time_from_start'}
    assert Motion.from_dict(doc).to_dict() == doc
    assert set(r.timings) == {'ik_s', 'collision_s', 'total_s'} and r.timings['total_s'] < 2.0
    # Planning left the world as it was.
    assert np.array_equal(world.joint_positions(), joints_before)
    assert all(np.allclose(world.block_pose(b)[0], p) for b, p in poses_before.items())


def test_planning_is_deterministic(generated):
    scene, alloc, world = generated
    placement = alloc.placements[0]
    block = next(b for b in scene.blocks if b.type == placement.type)
    position, yaw = allocated_pose(scene, placement)
    a = plan_action(world, block.id, position, yaw)
    b = plan_action(world, block.id, position, yaw)
    assert a.success == b.success and a.reason == b.reason
    if a.success:
        assert a.motion.to_dict() == b.motion.to_dict()


def test_placement_pose_of_an_mdp_action():
    scene = generate_scene(GeneratorConfig(grid=3), seed=0)
    block = next(b for b in scene.blocks if scene.block_types[b.type].size > 1)
    centre = np.array([0.5, 0.025, 0.075])
    pos, yaw = placement_pose(scene, block.id, 1, centre, rotation=1)
    assert yaw == (block.yaw + 90) % 360
    units = pos + U * scene.block_types[block.type].rotated(yaw)
    assert np.allclose(units[1], centre)
    with pytest.raises(RadError):
        placement_pose(scene, block.id, 9, centre, 0)


# ---- failures --------------------------------------------------------------

def test_buried_block_fails_on_grasp():
    c = (0.5, -0.2, U / 2)
    around = [(c[0] + dx * U, c[1] + dy * U, U / 2) for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    scene = _scene([('target', 'cube', c)] + [(f'n{i}', 'cube', p) for i, p in enumerate(around)])
    with World(scene) as world:
        r = plan_action(world, 'target', [0.45, 0.2, U / 2], 0)
    assert not r.success and r.failure == 'grasp' and r.motion is None
    assert r.reason.startswith('grasp: all 2 grasps blocked') and 'hits block n' in r.reason, r.reason


def _target_height_at_the_grasp(world, motion) -> float:
    """Where the approach ends, the fingers about to close: the grasp target's height."""
    world.set_joint_positions(motion.trajectories[0].points[-1].positions, hold=False)
    return float(world.link_pose()[0][2])


@pytest.mark.parametrize('gap, picked', [(0.025, True), (0.015, False)])
def test_a_block_packed_among_neighbours_is_taken_by_a_tight_grasp_only_where_the_tips_fit(gap, picked):
    # Neighbours on all four sides, `gap` away. The fingers' rubber tips (15 mm thick) fit in 2.5 cm
    # with the fingers 4 mm off the block and the grasp near its top, not 1 cm off at its centre;
    # in 1.5 cm nothing fits.
    c = np.array([0.5, -0.2, U / 2])
    around = [c + (dx * (U + gap), dy * (U + gap), 0) for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    scene = _scene([('target', 'cube', c)] + [(f'n{i}', 'cube', p) for i, p in enumerate(around)])
    with World(scene) as world:
        r = plan_action(world, 'target', [0.45, 0.2, U / 2], 0)
        assert r.success == picked, r.reason
        if picked:
            assert r.motion.opening == pytest.approx(U / 2 + 0.004)
            assert _target_height_at_the_grasp(world, r.motion) == pytest.approx(U - 0.013, abs=2e-3)
        else:
            assert r.failure == 'grasp' and 'finger hits block n' in r.reason and 'tight grasp:' in r.reason, r.reason


def test_a_block_with_room_around_it_is_grasped_at_its_centre_with_the_fingers_wide():
    scene = _scene([('free', 'cube', (0.45, -0.2, U / 2))])
    with World(scene) as world:
        r = plan_action(world, 'free', [0.45, 0.2, U / 2], 0)
        assert r.success
        assert r.motion.opening == pytest.approx(U / 2 + 0.01)
        assert _target_height_at_the_grasp(world, r.motion) == pytest.approx(U / 2, abs=2e-3)


def test_the_fingers_collide_as_franka_models_them_and_the_hull_is_left_for_the_visuals(monkeypatch, tmp_path):
    import pybullet as p
    with World(_scene([('free', 'cube', (0.45, -0.2, U / 2))])) as world:
        for link in world.finger_links:
            shapes = p.getCollisionShapeData(world.robot, link, physicsClientId=world.client)
            assert len(shapes) == 4 and all(s[2] == p.GEOM_BOX for s in shapes)
            # The rubber tip, the thinnest part across the closing axis.
            assert min(round(s[3][1], 4) for s in shapes if round(s[3][2], 4) == 0.0185) == 0.0152
    assert panda.source_urdf_path().name == 'panda.urdf' and panda.urdf_path() != panda.source_urdf_path()
    assert 'finger.obj' in panda.source_urdf_path().read_text() and 'collision/finger.obj' not in \
        panda.urdf_path().read_text()
    # Its meshes are named by absolute path, in this environment's pybullet_data.
    import xml.etree.ElementTree as ET
    meshes = [m.get('filename') for m in ET.parse(panda.urdf_path()).getroot().iter('mesh')]
    assert meshes and all(m.startswith(str(panda.source_urdf_path().parent)) and Path(m).is_file() for m in meshes)
    # Taken away (a temporary folder's cleaner), it is written again for the next world.
    _, source, text = panda._urdf_name('hand')
    monkeypatch.setattr(panda, '_urdf_name', lambda effector: (tmp_path / 'panda.urdf', source, text))
    first = panda.urdf_path().read_bytes()
    panda.urdf_path().unlink()
    assert panda.urdf_path().read_bytes() == first


def test_block_under_another_fails_on_grasp():
    scene = _scene([('low', 'cube', (0.5, -0.2, U / 2)), ('top', 'cube', (0.5, -0.2, 1.5 * U))])
    with World(scene) as world:
        r = plan_action(world, 'low', [0.45, 0.2, U / 2], 0)
        assert r.failure == 'grasp' and 'block top' in r.reason, r.reason
        assert plan_action(world, 'top', [0.45, 0.2, U / 2], 0).success


def test_placement_between_tall_towers_fails_on_placement():
    dest = np.array([0.5, 0.15, U / 2])
    # Three-cube towers right against the destination on both sides along x.
    towers = [(f't{"p" if side > 0 else "m"}{k}', 'cube', (dest[0] + side * U, dest[1], U / 2 + k * U))
              for side in (1, -1) for k in range(3)]
    scene = _scene([('free', 'cube', (0.45, -0.2, U / 2))] + towers)
    with World(scene) as world:
        r = plan_action(world, 'free', dest, 0)
        assert not r.success and r.failure == 'placement', r.reason
        assert r.reason.startswith('placement: 2 of 2 grasps feasible')
        assert 'at the placement' in r.reason and 'hits block t' in r.reason, r.reason
        # The same block goes to an open spot.
        assert plan_action(world, 'free', [0.45, 0.3, U / 2], 90).success


def test_placement_onto_an_occupied_pose_fails_on_placement():
    scene = _scene([('free', 'cube', (0.45, -0.2, U / 2)), ('there', 'cube', (0.5, 0.15, U / 2))])
    with World(scene) as world:
        r = plan_action(world, 'free', [0.5, 0.15, U / 2], 0)
    assert r.failure == 'placement' and 'carried block hits block there' in r.reason, r.reason


def test_unreachable_placement_is_a_placement_failure_with_the_ik_reason():
    scene = _scene([('free', 'cube', (0.45, -0.2, U / 2))])
    with World(scene) as world:
        r = plan_action(world, 'free', [1.6, 0.0, U / 2], 0)
    assert r.failure == 'placement' and 'unreachable' in r.reason, r.reason


def test_units_too_wide_for_the_hand_fail_on_grasp():
    scene = _scene([('big', 'cube', (0.45, -0.2, 0.045))], unit=0.09)
    with World(scene) as world:
        r = plan_action(world, 'big', [0.45, 0.2, 0.045], 0)
    assert r.failure == 'grasp' and 'no top-down grasp' in r.reason and '90 mm' in r.reason, r.reason


def test_bad_requests_raise(generated):
    scene, _, world = generated
    with pytest.raises(RadError, match='unknown block id'):
        plan_action(world, 'nope', [0.5, 0, 0.05], 0)
    with pytest.raises(RadError, match='finite'):
        plan_action(world, scene.blocks[0].id, [0.5, np.nan, 0.05], 0)
    with pytest.raises(RadError):
        plan_action(world, scene.blocks[0].id, [0.5, 0, 0.05], 0, start=np.zeros(4))


# ---- seats against neighbours seen off their cells ------------------------------------------------------

def _row(offsets, placed=('a', 'c'), size=(3, 2, 1)):
    """A 3x2 region at x 0.45..0.55, y 0..0.05; 'a' on cell (0,0), 'c' on (2,0), 'd' on (2,1) when placed,
    else on the table; 'b' (to place, on cell (1,0)) on the table."""
    cells = {'a': (0.45, 0.0), 'c': (0.55, 0.0), 'd': (0.55, 0.05)}
    table = {'a': (0.3, -0.3), 'b': (0.4, -0.3), 'c': (0.5, -0.3), 'd': (0.6, -0.3)}
    blocks = [{'id': k, 'type': 'cube', 'yaw': 0,
               'position': [*(cells[k] if k in placed else table[k]), U / 2]} for k in 'abcd']
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': U, 'block_types': {'cube': [[0, 0, 0]]}, 'blocks': blocks,
        'targets': [{'name': 't', 'origin': [0.45, 0.0, U / 2], 'size': list(size),
                     'filled': [[i, j, 0] for i in range(3) for j in range(2)]}],
        'measured_offsets': {k: v for k, v in offsets.items() if k in placed}})


@pytest.mark.parametrize('offsets, placed, want', [
    ({}, ('a', 'c'), (0, 0)),                                          # nothing off: the cell's pose
    ({'a': [0.002, 0.0005]}, ('a',), (0.002, 0)),                       # a landed 2 mm into b's cell
    ({'a': [-0.002, 0.0]}, ('a', 'c'), (0, 0)),                         # off, but away from b
    ({'a': [0.002, 0.0], 'c': [0.0, 0.0]}, ('a', 'c'), (0.001, 0)),     # squeezed: the middle
    ({'a': [0.001, 0.0], 'c': [0.003, 0.0]}, ('a', 'c'), (0.001, 0)),   # a row drifting: follow it, no further
    ({'d': [-0.001, -0.0015]}, ('d',), (-0.001, 0)),                    # a corner: cleared along the cheaper axis
    ({'a': [0.04 * 0.5 - 1e-3, 0.0]}, ('a',), (0.0125, 0)),             # at most a quarter unit
])
def test_seat_shift_clears_neighbours_seen_off_their_cells(offsets, placed, want):
    from rad_core.gamp.action import seat_shift
    s = _row(offsets, placed)
    shift = seat_shift(s, 'b', np.array([0.5, 0.0, U / 2]), 0)
    assert shift == pytest.approx([*want, 0.0], abs=1e-6)


def test_a_block_is_placed_clear_of_a_neighbour_seen_off_its_cell():
    from rad_core.gamp.action import MotionPlanner, SceneAction
    planner = MotionPlanner()
    try:
        action = SceneAction('b', 0, 't', (1, 0, 0), 0)
        shifted = _row({'a': [0.002, 0.0]}, ('a',))
        result, position, _ = planner(shifted, action)
        assert result.success, result.reason
        assert position.tolist() == pytest.approx([0.5, 0.0, U / 2])        # the plan's pose is the cell's
        # Replayed in the world: the block is released 2 mm over, flush with its neighbour, not into it.
        planner.world.load_scene(shifted)
        placed, _ = _replay(planner.world, result, 'b')
        assert placed[0] == pytest.approx(0.502, abs=3e-4)
        assert planner.world.block_pose('a')[0][0] == pytest.approx(0.452)
    finally:
        planner.close()


def test_a_block_set_aside_where_the_placement_goes_is_an_obstacle_to_the_plan():
    from rad_core.gamp.action import MotionPlanner, SceneAction
    d = _row({}, ()).to_dict()
    # A block on its side over cell (1, 0): no block of the scene, but there.
    d['blocks'] = [b for b in d['blocks'] if b['id'] != 'd']
    d['obstacles'] = [{'id': 'd', 'type': 'cube', 'position': [0.5, 0.0, U / 2],
                       'quaternion': [math.sin(math.pi / 4), 0, 0, math.cos(math.pi / 4)]}]
    planner = MotionPlanner()
    try:
        result, _, _ = planner(Scene.from_dict(d), SceneAction('b', 0, 't', (1, 0, 0), 0))
        assert not result.success and result.failure == 'placement'
        assert 'block d (set aside)' in result.reason
        assert list(planner.world.obstacles) == ['d']
        result, _, _ = planner(_row({}, ()), SceneAction('b', 0, 't', (1, 0, 0), 0))
        assert result.success and planner.world.obstacles == {}          # gone with the next scene
    finally:
        planner.close()


def test_a_set_aside_block_the_hand_touches_is_no_obstacle_to_leaving():
    from rad_core.gamp.action import drop_obstacles_on_the_hand
    world = World()
    try:
        world.set_joint_positions(panda.HOME)
        p = world.pybullet
        tip = p.getLinkState(world.robot, world.link_index['panda_leftfinger'], physicsClientId=world.client)[0]
        d = _row({}, ()).to_dict()
        d['obstacles'] = [
            {'id': 'stuck', 'type': 'cube', 'position': list(tip), 'quaternion': [0, 0, 0, 1]},
            {'id': 'fallen', 'type': 'cube', 'position': [0.3, 0.4, U / 2], 'quaternion': [0.7071068, 0, 0, 0.7071068]}]
        world.load_scene(Scene.from_dict(d))
        assert drop_obstacles_on_the_hand(world, panda.HOME) == ['stuck']
        assert list(world.obstacles) == ['fallen']
    finally:
        world.close()


# ---- what makes a probe cheap changes no answer --------------------------------

def _reference_collision(world, attached=None, config=CollisionConfig()):
    """The probe as it was before its shortcuts: every link's own broadphase query, every
    self-collision pair measured."""
    p, cid, robot = world.pybullet, world.client, world.robot
    exclude = {attached.block_id} if attached is not None else set()
    obstacles = {b for bid, b in world.blocks.items() if bid not in exclude} | {world.table}
    links, pairs, m = robot_links(world), self_collision_pairs(world), config.robot_margin

    def collision(q):
        world.set_joint_positions(q, hold=False)
        if attached is not None:
            place_attached(world, attached)
            carried = world.blocks[attached.block_id]
            lo, hi = p.getAABB(carried, -1, physicsClientId=cid)
            for body in sorted({b for b, _ in p.getOverlappingObjects(lo, hi, physicsClientId=cid) or ()
                                if b in obstacles - {carried}}):
                if any(pt[8] < -config.block_penetration
                       for pt in p.getClosestPoints(carried, body, 0.0, physicsClientId=cid)):
                    return 'carried'
        for link in links:
            lo, hi = p.getAABB(robot, link, physicsClientId=cid)
            near = p.getOverlappingObjects([v - m for v in lo], [v + m for v in hi], physicsClientId=cid) or ()
            for body in {b for b, _ in near if b in obstacles}:
                if any(pt[8] < m for pt in p.getClosestPoints(robot, body, m, linkIndexA=link, physicsClientId=cid)):
                    return 'obstacle'
        for a, b in pairs:
            if any(pt[8] < config.self_margin for pt in p.getClosestPoints(
                    robot, robot, config.self_margin, linkIndexA=a, linkIndexB=b, physicsClientId=cid)):
                return 'self'
        return ''

    return collision


def _kind(reason: str) -> str:
    return ('' if not reason else 'carried' if reason.startswith('carried') else
            'self' if reason.startswith('self-collision') else 'obstacle')


def _near_configurations(world, block_id, n, rng):
    """Configurations that bring the hand down among the blocks (many collide, many do not)."""
    pos, _ = world.block_pose(block_id)
    out = []
    for _ in range(n):
        target = pos + rng.uniform([-0.08, -0.08, -0.01], [0.08, 0.08, 0.15])
        r = solve_top_down(world, target, rng.uniform(-math.pi, math.pi), rng=rng)
        q = r.q if r.ok else rng.uniform(panda.LOWER, panda.UPPER)
        out.append(q + rng.normal(0.0, 0.15, 9) * np.r_[np.ones(7), 0.0, 0.0])
    return out


def test_pruned_probes_answer_as_the_full_check(generated):
    """The arm-wide broadphase query and the self-collision pairs pruned by bounding boxes give the
    same verdict and kind of reason as querying every link and measuring every pair."""
    scene, _, world = generated
    rng = np.random.default_rng(3)
    block_id = scene.blocks[0].id
    kinds = []
    with world.preserved():
        qs = _near_configurations(world, block_id, 60, rng)
        fast, slow = make_collision_fn(world), _reference_collision(world)
        for q in qs:
            kinds.append((_kind(fast(q)), slow(q)))
        world.set_joint_positions(qs[0], hold=False)
        attached = attachment_from_world(world, block_id)
        fast, slow = make_collision_fn(world, attached=attached), _reference_collision(world, attached)
        for q in qs:
            kinds.append((_kind(fast(q)), slow(q)))
    assert all(a == b for a, b in kinds), [k for k in kinds if k[0] != k[1]]
    seen = {b for _, b in kinds}
    assert '' in seen and 'obstacle' in seen      # the set exercises both answers


def test_links_apart_by_their_boxes_never_touch():
    """The pruning rule: a pair whose AABBs are apart by more than the margin has no contact point
    below it (measured on random configurations, where many pairs do touch)."""
    with World() as world:
        p, cid, robot = world.pybullet, world.client, world.robot
        rng = np.random.default_rng(5)
        pairs, pruned, touching = self_collision_pairs(world), 0, 0
        for _ in range(200):
            world.set_joint_positions(rng.uniform(panda.LOWER, panda.UPPER), hold=False)
            for a, b in pairs:
                pts = p.getClosestPoints(robot, robot, 0.01, linkIndexA=a, linkIndexB=b, physicsClientId=cid)
                close = min((pt[8] for pt in pts), default=math.inf)
                touching += close < 0.0
                if _apart(p.getAABB(robot, a, physicsClientId=cid), p.getAABB(robot, b, physicsClientId=cid), 0.0):
                    pruned += 1
                    assert close > 0.0
        assert pruned > 1000 and touching > 0


def test_remembered_probes_answer_and_leave_the_world_as_a_probe_does(generated):
    scene, _, world = generated
    rng = np.random.default_rng(4)
    block_id = scene.blocks[0].id
    with world.preserved():
        qs = _near_configurations(world, block_id, 12, rng)
        world.set_joint_positions(qs[0], hold=False)
        attached = attachment_from_world(world, block_id)
        plain = make_collision_fn(world, attached=attached)
        remembering = make_collision_fn(world, attached=attached, remember=True)
        first = [remembering(q) for q in qs]
        for q, reason in zip(qs[::-1], first[::-1]):     # every answer now from memory
            assert remembering(q) == reason == plain(q)
            plain_pose = world.block_pose(block_id), world.joint_positions()
            remembering(q)
            assert np.array_equal(world.joint_positions(), plain_pose[1])
            assert all(np.array_equal(a, b) for a, b in zip(world.block_pose(block_id), plain_pose[0]))
        # Another world state is another key: a block moved away changes the answer it may give.
        other = scene.blocks[1].id
        world.set_block_pose(other, [0.0, 0.7, 0.5])
        moved = make_collision_fn(world, attached=attached, remember=True)
        assert [moved(q) for q in qs] == [_plain_now(world, attached, q) for q in qs]


def _plain_now(world, attached, q):
    return make_collision_fn(world, attached=attached)(q)


def test_remembered_ik_is_the_ik_and_leaves_the_generator_where_solving_does():
    with World() as world:
        target, quat = np.array([0.5, 0.1, 0.08]), panda.top_down_quaternion(0.3)
        far = np.array([0.0, 0.95, 0.05])                # unreachable: the random restarts draw
        for position in (target, far):
            a, b = np.random.default_rng(11), np.random.default_rng(11)
            first = solve_pose(world, position, quat, [panda.HOME], rng=a)
            again = solve_pose(world, position, quat, [panda.HOME], rng=b)
            assert again.calls == 0 and first.calls > 0          # from memory
            assert first.ok == again.ok and first.reason == again.reason
            assert (first.q is None and again.q is None) or np.array_equal(first.q, again.q)
            assert a.bit_generator.state == b.bit_generator.state
        # A generator in another state is another question (its restarts would differ).
        c = np.random.default_rng(12)
        assert solve_pose(world, far, quat, [panda.HOME], rng=c).calls > 0


def test_a_grasp_whose_lift_fails_leaves_the_block_where_it_lies_for_the_next_one(monkeypatch):
    """The lift check carries the block with the hand; when it fails, the next grasp must be planned
    with the block back where it lies (a fault made on demand: the first lift is refused)."""
    from rad_core.gamp import planner
    scene = _scene([('b', 'cube', (0.5, -0.2, U / 2))])
    seen, refused, real_check = [], [], planner._check_column

    def first_lift_refused(fn, q, column, config, where, where_path):
        if where == 'lifting the block' and not refused:
            refused.append(True)
            for q_lift in column:
                fn(q_lift)                  # carried along the lift, as the real check does
            raise planner._Blocked('lifting the block: refused here on demand')
        return real_check(fn, q, column, config, where, where_path)

    real_pick = planner._plan_pick

    def pick(world, block_id, *args, **kw):
        seen.append(tuple(np.round(world.block_pose(block_id)[0], 9)))
        return real_pick(world, block_id, *args, **kw)

    monkeypatch.setattr(planner, '_check_column', first_lift_refused)
    monkeypatch.setattr(planner, '_plan_pick', pick)
    with World(scene) as world:
        before = tuple(np.round(world.block_pose('b')[0], 9))
        r = plan_action(world, 'b', [0.45, 0.2, U / 2], 0)
    assert r.success and refused
    assert len(seen) >= 2 and all(p == before for p in seen)


def test_the_body_a_reason_names_does_not_depend_on_what_the_world_loaded_before():
    """A world that loaded other scenes hands out freed body ids again, in another order; where
    the hand meets several blocks at once, the one GAMP names ('hand hits block ...', which moving
    neighbours aside acts on) is the one a fresh world names, the first in the scene's order."""
    dest = np.array([0.5, 0.15, U / 2])
    # Stacks around the destination (x, y offsets in units: height), two of them two high beside
    # the hand: it meets both at the placement.
    heights = {(-1, 0): 2, (0, 1): 1, (0, -1): 2, (1, 1): 1, (-1, -1): 1, (1, -1): 2, (-1, 1): 2}
    blocks = [('free', 'cube', (0.45, -0.2, U / 2))] + [
        (f'n{dx}{dy}_{k}', 'cube', (dest[0] + dx * U, dest[1] + dy * U, U / 2 + k * U))
        for (dx, dy), h in heights.items() for k in range(h)]
    scene = _scene(blocks)
    with World(scene) as fresh:
        want = plan_action(fresh, 'free', dest, 0).reason
    assert 'at the placement: hand hits block n-10_1' in want, want
    with World(generate_scene(GeneratorConfig(grid=6, sides=2), 3)) as used:   # more blocks than this scene
        used.load_scene(scene)
        assert sorted(used.blocks.values()) != list(used.blocks.values())       # ids out of scene order
        assert plan_action(used, 'free', dest, 0).reason == want


def test_a_pick_met_again_in_the_same_world_is_answered_from_memory_and_plans_the_same(monkeypatch):
    from rad_core.gamp import planner
    picked = []
    plan_pick = planner._plan_pick

    def counting(world, block_id, *args):
        picked.append(block_id)
        return plan_pick(world, block_id, *args)
    monkeypatch.setattr(planner, '_plan_pick', counting)
    c = (0.5, -0.2, U / 2)
    around = [(c[0] + dx * U, c[1] + dy * U, U / 2) for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    scene = _scene([('free', 'cube', (0.45, -0.35, U / 2)), ('buried', 'cube', c)]
                   + [(f'n{i}', 'cube', p) for i, p in enumerate(around)])
    here, there = [0.45, 0.2, U / 2], [0.4, 0.25, U / 2]
    with World(scene) as fresh:
        alone = {b: plan_action(fresh, b, there, 90) for b in ('free', 'buried')}
    with World(scene) as world:
        for block in ('free', 'buried'):
            plan_action(world, block, here, 0)            # the same picks, another placement
            n = len(picked)
            again = plan_action(world, block, there, 90)
            assert len(picked) == n                      # no pick planned: all from memory
            assert (again.success, again.failure, again.reason) == (alone[block].success, alone[block].failure,
                                                                   alone[block].reason)
            if again.success:
                assert again.motion.to_dict() == alone[block].motion.to_dict()
        assert alone['free'].success and alone['buried'].failure == 'grasp'
        # Another world (the neighbours along x moved away): planned anew, and now it can be picked.
        world.set_block_pose('n0', (0.7, -0.4, U / 2), _yaw_quat(0))
        world.set_block_pose('n1', (0.6, -0.45, U / 2), _yaw_quat(0))
        n = len(picked)
        assert plan_action(world, 'buried', there, 90).success and len(picked) > n


def test_a_plans_motion_is_timed_when_read_and_ends_where_final_joints_says(generated):
    """The teleporting twin asks only where the motion ends (GampResult.final_joints, without timing it);
    the motion read later is the one plan_motion makes of the plan's waypoints, ending there exactly."""
    from rad_core.gamp.trajectory import plan_motion
    scene, alloc, world = generated
    placement = next(p for p in alloc.placements if p.type == 'I2_up')
    block = next(b for b in scene.blocks if b.type == 'I2_up')
    position, yaw = allocated_pose(scene, placement)
    r = plan_action(world, block.id, position, yaw)
    assert r.success and r._motion is None
    start, waypoints, timing, grasp, vacuum = r._path
    assert vacuum is None                                       # the hand's
    end = r.final_joints()
    assert r._motion is None                                    # not timed for that
    eager = plan_motion(start, waypoints, timing, grasp_expected=grasp)
    assert r.motion.to_dict() == eager.to_dict()
    assert np.array_equal(end, r.motion.final_joints())


@pytest.mark.slow
def test_never_touching_pairs_stay_apart_over_their_joints_ranges():
    """The proof behind collision.NEVER_TOUCHING: each pair's relative pose depends on the joints between
    them; over their URDF ranges on a 0.02 rad grid the pair keeps 1 cm more than any of its points can
    move to a configuration between grid points (0.6 m/rad, more than any point's distance from those
    joints' axes, times half a step on each joint)."""
    from rad_core.gamp.collision import NEVER_TOUCHING
    with World() as world:
        p, cid, robot, index = world.pybullet, world.client, world.robot, world.link_index
        step = 0.02
        for a, b in NEVER_TOUCHING:
            between = list(range(index[a] + 1, index[b] + 1 if index[b] < 7 else 7))
            grids = [np.arange(panda.URDF_LOWER[j], panda.URDF_UPPER[j] + step, step) for j in between]
            slack = 0.6 * step / 2 * len(between)
            q = panda.HOME.copy()
            nearest = math.inf
            for values in np.array(np.meshgrid(*grids)).reshape(len(between), -1).T:
                q[between] = values
                world.set_joint_positions(q, hold=False)
                pts = p.getClosestPoints(robot, robot, 0.2, linkIndexA=index[a], linkIndexB=index[b],
                                         physicsClientId=cid)
                nearest = min(nearest, min((pt[8] for pt in pts), default=0.2))
            assert nearest > slack + 0.01, (a, b, nearest)


def test_vertical_moves_step_finely_among_neighbours_and_coarsely_above():
    from rad_core.gamp.planner import GampConfig, column_heights
    heights = column_heights(0.12, 0.045)
    assert heights[-1] == pytest.approx(0.12) and heights == sorted(heights)
    steps = np.diff([0.0, *heights])
    low = [h for h in heights if h <= 0.045 + 1e-9]
    assert low[-1] == pytest.approx(0.045) and max(np.diff([0.0, *low])) <= 0.01 + 1e-9
    assert max(steps) <= GampConfig().cartesian_step + 1e-9 and len(heights) == len(low) + 2
    # near_step 0: the coarse steps alone, as before; a band above the top stops at the top.
    assert column_heights(0.12, 0.045, GampConfig(near_step=0.0)) == pytest.approx([0.04, 0.08, 0.12])
    assert column_heights(0.03, 0.05)[-1] == pytest.approx(0.03)
    for bad in (dict(near_step=-0.01), dict(near_margin=-1.0), dict(cartesian_step=0.0)):
        with pytest.raises(RadError, match='step|margin'):
            GampConfig(**bad).validate()

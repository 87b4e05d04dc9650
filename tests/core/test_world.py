"""sim.World: the scene's blocks at their scene poses, the Panda at HOME, cheap undo."""

import math
import time

import numpy as np
import pytest
from rad_core.cell import panda
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.transforms import yaw_of_quaternion
from rad_core.sim.world import World


@pytest.fixture(scope='module')
def scene():
    return generate_scene(GeneratorConfig(grid=4), seed=1)


@pytest.fixture
def world(scene):
    with World(scene) as w:
        yield w


def test_panda_constants_come_from_the_urdf_and_franka():
    assert len(panda.JOINT_NAMES) == 9 and panda.ARM_JOINT_NAMES == panda.JOINT_NAMES[:7]
    assert panda.LOWER.shape == panda.UPPER.shape == panda.VELOCITY_LIMITS.shape == (9,)
    # pybullet_data's model: joint 4 in [-3.1416, 0], joint 6 in [-0.0873, 3.8223] (wider than a real Panda).
    assert panda.URDF_LOWER[3] == pytest.approx(-3.1416) and panda.URDF_UPPER[5] == pytest.approx(3.8223)
    # Plans keep to Franka's published ranges, of the Panda and the FR3 both: joint 4 up to the Panda's
    # -0.0698 and the FR3's -0.1518, joint 6 from the FR3's 0.5445 to the Panda's 3.7525.
    # Both then 0.02 rad clear of the FR3's braking zones (robot_model.BRAKING_MARGIN): joint 4's ends at
    # -0.1458 - 0.3^2 / 8, joint 6's at 0.54092 + 0.35^2 / 11.
    assert panda.UPPER[3] == pytest.approx(-0.1458 - 0.09 / 8 - 0.02)
    assert panda.LOWER[5] == pytest.approx(0.54092 + 0.1225 / 11 + 0.02)
    assert panda.UPPER[5] == pytest.approx(3.7525) and panda.LOWER[0] == pytest.approx(-2.7501 + 0.09 / 12 + 0.02)
    assert np.all(panda.LOWER >= panda.URDF_LOWER) and np.all(panda.UPPER <= panda.URDF_UPPER)
    assert panda.UPPER[7] == panda.UPPER[8] == 0.04
    assert panda.within_limits(panda.HOME)


def test_blocks_sit_at_their_scene_poses_and_the_robot_at_home(world, scene):
    assert set(world.blocks) == {b.id for b in scene.blocks}
    for b in scene.blocks:
        pos, quat = world.block_pose(b.id)
        assert np.allclose(pos, b.position, atol=1e-6)
        assert yaw_of_quaternion(quat) == pytest.approx(b.yaw, abs=1e-4)
    assert np.allclose(world.joint_positions(), panda.HOME, atol=1e-9)
    assert world.joint_index['panda_finger_joint2'] == 10 and world.ee_link == 11
    # The grasp target at HOME is in front of the robot, above the table.
    pos, _ = world.link_pose()
    assert 0.3 < pos[0] < 0.6 and 0.1 < pos[2] < 0.4


def test_blocks_rest_and_robot_holds_when_stepped(world, scene):
    world.step(240)
    for b in scene.blocks:
        assert np.linalg.norm(world.block_pose(b.id)[0] - b.position) < 1e-3, b.id
    assert np.allclose(world.joint_positions(), panda.HOME, atol=1e-3)


def test_block_mass_is_per_cube(world, scene):
    import pybullet as p
    for b in scene.blocks:
        mass = p.getDynamicsInfo(world.blocks[b.id], -1, physicsClientId=world.client)[0]
        assert mass == pytest.approx(0.1 * scene.block_types[b.type].size)


def test_set_block_pose_round_trips_anchor_frame(world, scene):
    b = scene.blocks[0]
    q = [0, 0, math.sin(math.radians(45)), math.cos(math.radians(45))]
    world.set_block_pose(b.id, [0.1, 0.4, 0.3], q)
    pos, quat = world.block_pose(b.id)
    assert np.allclose(pos, [0.1, 0.4, 0.3], atol=1e-6)
    assert abs(abs(np.dot(quat, q)) - 1) < 1e-6
    with pytest.raises(RadError, match='unknown block id'):
        world.block_pose('nope')


def test_preserved_undoes_joints_blocks_and_constraints(world, scene):
    import pybullet as p
    b = scene.blocks[0]
    before_q, before_pose = world.joint_positions(), world.block_pose(b.id)
    for exact in (False, True):
        with world.preserved(exact=exact):
            world.set_joint_positions(np.zeros(7))
            world.set_block_pose(b.id, [0.0, 0.5, 0.5])
            p.createConstraint(world.robot, world.ee_link, world.blocks[b.id], -1, p.JOINT_FIXED,
                               [0, 0, 0], [0, 0, 0], [0, 0, 0], physicsClientId=world.client)
            world.step(5)
        assert np.allclose(world.joint_positions(), before_q)
        assert np.allclose(world.block_pose(b.id)[0], before_pose[0])
        assert p.getNumConstraints(physicsClientId=world.client) == 0


def test_preserved_is_cheap(world):
    t = time.perf_counter()
    for _ in range(50):
        with world.preserved():
            world.set_joint_positions(np.zeros(9))
    per_call = (time.perf_counter() - t) / 50
    print(f'preserved(): {per_call * 1e6:.0f} us per use')
    assert per_call < 2e-3


def test_bad_joint_vectors_are_refused(world):
    with pytest.raises(RadError):
        world.set_joint_positions(np.zeros(5))
    with pytest.raises(RadError):
        world.set_joint_positions([np.nan] * 9)


def test_load_scene_replaces_blocks_and_close_is_idempotent(scene):
    w = World()
    assert w.blocks == {}
    w.load_scene(scene)
    first = dict(w.blocks)
    w.load_scene(scene)
    assert set(w.blocks) == set(first)
    w.close()
    w.close()


def _kinematic_state(world):
    p, cid, r = world.pybullet, world.client, world.robot
    n = p.getNumJoints(r, physicsClientId=cid)
    links = p.getLinkStates(r, list(range(n)), computeLinkVelocity=True, computeForwardKinematics=True,
                            physicsClientId=cid)
    joints = p.getJointStates(r, list(range(n)), physicsClientId=cid)
    boxes = [p.getAABB(r, link, physicsClientId=cid) for link in range(-1, n)]
    return links, [j[:2] for j in joints], boxes


def test_setting_joints_in_one_command_equals_one_command_per_joint(world):
    """set_joint_positions sends one reset for all joints: the joints, their velocities, every
    link's pose and velocity and bounding box come out bit for bit as nine resetJointState would."""
    p, cid, r = world.pybullet, world.client, world.robot
    rng = np.random.default_rng(7)
    for _ in range(30):
        q = rng.uniform(panda.LOWER, panda.UPPER)
        for j in world.joints:                 # moving joints first, so zero velocities must be set
            p.resetJointState(r, j, 0.1, 0.5, physicsClientId=cid)
        for j, v in zip(world.joints, q):
            p.resetJointState(r, j, float(v), 0.0, physicsClientId=cid)
        one_by_one = _kinematic_state(world)
        for j in world.joints:
            p.resetJointState(r, j, 0.1, 0.5, physicsClientId=cid)
        world.set_joint_positions(q, hold=False)
        assert _kinematic_state(world) == one_by_one


def test_preserved_restores_joint_velocities_exactly(world):
    p, cid, r = world.pybullet, world.client, world.robot
    for j, v in zip(world.joints, np.linspace(-0.3, 0.3, 9)):
        p.resetJointState(r, j, float(panda.HOME[world.joints.index(j)]), float(v), physicsClientId=cid)
    before = _kinematic_state(world)
    with world.preserved():
        world.set_joint_positions(np.zeros(9))
    assert _kinematic_state(world) == before


def test_a_block_unparked_gets_back_its_mass_and_exact_inertia(scene):
    """Bullet recomputes the inertia from the collision shape when only the mass is set; a block made
    static and dynamic again (the feeder's park and unpark, `asleep`'s neighbours) must keep its own."""
    from rad_core.domain.scene import Scene
    doc = scene.to_dict()
    for b in doc['blocks']:
        b['yaw'] = 0            # the feeder presents every block at its station, at yaw 0
        b.pop('position')
    doc['feeder'] = {'station': [0.45, -0.3], 'blocks': [b['id'] for b in doc['blocks']], 'order': 'request'}
    with World(Scene.from_dict(doc)) as w:
        p, cid = w.pybullet, w.client
        block_id = scene.blocks[0].id
        body = w.blocks[block_id]
        assert block_id in w.parked and p.getDynamicsInfo(body, -1, physicsClientId=cid)[0] == 0.0
        w.present(block_id)
        mass, _, inertia = p.getDynamicsInfo(body, -1, physicsClientId=cid)[:3]
    with World(scene) as fresh:         # the same block type: its mass and inertia as made
        want = fresh.pybullet.getDynamicsInfo(fresh.blocks[block_id], -1, physicsClientId=fresh.client)[:3]
    assert (mass, inertia) == (want[0], want[2])


def test_asleep_blocks_stay_put_wake_when_hit_and_everything_is_awake_after(world, scene):
    p, cid = world.pybullet, world.client
    ids = [b.id for b in scene.blocks]
    poses = {b: world.block_pose(b) for b in ids}
    with world.preserved():
        with world.asleep(ids[1:]):
            world.step(120)
            # Asleep, Bullet moves none of them, not even by the micrometres a block at rest on the
            # table creeps (only the first step integrates them once).
            still = {b: world.block_pose(b) for b in ids[1:]}
            world.step(60)
            assert all(np.array_equal(world.block_pose(b)[0], still[b][0]) for b in ids[1:])
            # A block dropped on a sleeping one wakes it: it is pushed into the table like any body.
            below = ids[1]
            pos, quat = world.block_pose(below)
            world.set_block_pose(ids[0], pos + [0.0, 0.0, 2.5 * scene.unit], quat)
            world.step(120)
            assert not np.array_equal(world.block_pose(below)[0], still[below][0])
        # After it nothing sleeps: a block tossed up flies (from the second step on: the first after
        # waking still counts Bullet's islands as asleep, see World.asleep).
        world.step(1)
        far = ids[-1]
        p.resetBaseVelocity(world.blocks[far], [0.0, 0.0, 1.0], [0, 0, 0], physicsClientId=cid)
        world.step(10)
        assert world.block_pose(far)[0][2] > poses[far][0][2] + 0.02
    assert all(np.allclose(world.block_pose(b)[0], poses[b][0]) for b in ids)


def test_joints_kept_puts_the_joints_back_exactly(world):
    world.set_joint_positions(panda.HOME)
    world.step(3)
    before = world.pybullet.getJointStates(world.robot, world.joints, physicsClientId=world.client)
    with world.joints_kept():
        world.set_joint_positions(panda.HOME + 0.1, hold=False)
    after = world.pybullet.getJointStates(world.robot, world.joints, physicsClientId=world.client)
    assert [s[:2] for s in after] == [s[:2] for s in before]



def test_a_later_state_of_the_loaded_scene_is_reposed_as_load_scene_would_put_it():
    # A planner loads each state of a plan: the same bodies, moved. `repose` puts them where a fresh
    # `load_scene` does, with their masses; a scene of other blocks is left to `load_scene`. GAMP
    # plans the next block the same from either world.
    from rad_core.domain.large_shapes import large_scene
    from rad_core.gamp.action import MotionPlanner, SceneAction
    from rad_core.sequencing.planning.plan import moved
    scene = large_scene('wall_openings')                   # its blocks in a feeder
    placed = scene.feeder.blocks[0]
    later = moved(scene, placed, (0.45, 0.25, scene.unit / 2), 90)
    assert placed not in later.feeder.blocks
    with World() as fresh, World() as kept:
        fresh.load_scene(later)
        kept.load_scene(scene)
        bodies = dict(kept.blocks)
        assert kept.repose(later)
        assert kept.blocks == bodies and kept.parked == fresh.parked
        for block in later.blocks:
            if block.id not in fresh.parked:
                for a, b in zip(kept.block_pose(block.id), fresh.block_pose(block.id)):
                    assert np.allclose(a, b, atol=1e-9)
        p = kept.pybullet
        mass = p.getDynamicsInfo(fresh.blocks[placed], -1, physicsClientId=fresh.client)[0]
        assert mass > 0 and p.getDynamicsInfo(kept.blocks[placed], -1, physicsClientId=kept.client)[0] == mass
        assert not kept.repose(generate_scene(GeneratorConfig(grid=4), seed=0))
    target = later.targets[0].name
    action = SceneAction(later.feeder.blocks[0], 0, target, (0, 0, 0), 0)
    first, again = MotionPlanner(), MotionPlanner()
    try:
        first(scene, action)                               # loads the first state
        reposed, *_ = first(later, action)
        made, *_ = again(later, action)
    finally:
        first.close()
        again.close()
    assert made.success, made.reason
    assert (reposed.success, reposed.reason, reposed.grasp) == (made.success, made.reason, made.grasp)
    assert np.allclose(reposed.final_joints(), made.final_joints())

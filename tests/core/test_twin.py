"""sim.Twin: trajectory execution, validation that leaves the world alone, grasping."""

import math
import time

import numpy as np
import pytest

from rad_core.errors import RadError
from rad_core.scene import Scene
from rad_core.sim import panda
from rad_core.sim.twin import Twin, TwinConfig
from rad_core.sim.world import World
from rad_core.trajectory import Trajectory, TrajectoryPoint, parse_trajectory

U = 0.05
PICK = np.array([0.5, -0.2, U / 2])
PLACE = np.array([0.5, 0.15, U / 2])
CLOSE_ALONG_X = math.pi / 2            # hand yaw whose fingers close along world x


def one_cube_scene(extra_blocks=()) -> Scene:
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': U, 'block_types': {'cube': [[0, 0, 0]]},
        'blocks': [{'id': 'c0', 'type': 'cube', 'position': PICK.tolist(), 'yaw': 0}, *extra_blocks],
        'targets': [{'name': 't', 'origin': PLACE.tolist(), 'size': [1, 1, 1], 'filled': [[0, 0, 0]]}]})


@pytest.fixture
def twin():
    with World(one_cube_scene()) as world:
        yield Twin(world)


def ik(world: World, position, hand_yaw: float, seed) -> np.ndarray:
    """Arm joints putting the grasp target at position, hand pointing down; FK-checked."""
    import pybullet as p
    quat = panda.top_down_quaternion(hand_yaw)
    q = np.asarray(seed, dtype=float)
    with world.preserved():
        for _ in range(20):                   # one call is one solver run: repeat from its answer
            world.set_joint_positions(q, hold=False)
            q = np.array(p.calculateInverseKinematics(
                world.robot, world.ee_link, list(position), list(quat), maxNumIterations=200,
                residualThreshold=1e-6, physicsClientId=world.client)[:7])
            world.set_joint_positions(q, hold=False)
            reached, _ = world.link_pose()
            if np.linalg.norm(reached - position) < 5e-4:
                break
    assert np.linalg.norm(reached - position) < 1e-3 and panda.within_limits(q)
    return q


def arm_move(q7, t, fingers=None):
    names = list(panda.ARM_JOINT_NAMES) + (list(panda.FINGER_JOINT_NAMES) if fingers is not None else [])
    pos = list(q7) + ([fingers, fingers] if fingers is not None else [])
    return {'joint_names': names, 'points': [{'positions': pos, 'time_from_start': t}]}


def pick_and_place(world: World, pick=PICK, place=PLACE, drop=0.007) -> dict:
    """Above the cube, down, close, lift, over the target, down, open, up: one trajectory."""
    up = np.array([0, 0, 0.15])
    above = ik(world, pick + up, CLOSE_ALONG_X, panda.HOME[:7])
    at = ik(world, pick + [0, 0, 0.005], CLOSE_ALONG_X, above)
    above_place = ik(world, place + up, CLOSE_ALONG_X, above)
    at_place = ik(world, place + [0, 0, drop], CLOSE_ALONG_X, above_place)
    points, t = [], 0.0
    for q, f, dt in [(above, 0.04, 1.5), (at, 0.04, 1.0), (at, 0.0, 0.5), (above, 0.0, 1.0),
                     (above_place, 0.0, 1.5), (at_place, 0.0, 1.0), (at_place, 0.04, 0.5), (above_place, 0.04, 1.0)]:
        t += dt
        points.append({'positions': list(q) + [f, f], 'time_from_start': t})
    return {'joint_names': list(panda.JOINT_NAMES), 'points': points}


# ---- following trajectories -------------------------------------------------

def test_arm_reaches_the_last_point(twin):
    target = panda.HOME.copy()
    target[[0, 1, 3, 6]] += [0.6, 0.4, 0.5, -0.8]
    report = twin.execute(arm_move(target[:7], 1.5))
    q = twin.world.joint_positions()
    assert np.abs(q[:7] - target[:7]).max() < 2e-3
    assert report.final_error < 2e-3 and report.max_tracking_error < 0.02
    assert 1.5 <= report.sim_time <= 2.0 and report.steps == round(report.sim_time * 240)
    assert report.real_time_factor > 1 and not report.preempted
    # Fingers were not named: they held their command (open).
    assert q[7:] == pytest.approx([0.04, 0.04], abs=1e-3)


def test_names_in_any_order_and_a_subset():
    with World() as world:
        twin = Twin(world)
        names = ['panda_joint4', 'panda_joint1']
        twin.execute({'joint_names': names, 'points': [{'positions': [-2.0, 0.3], 'time_from_start': 1.0}]})
        q = world.joint_positions()
        assert q[3] == pytest.approx(-2.0, abs=2e-3) and q[0] == pytest.approx(0.3, abs=2e-3)
        others = [1, 2, 4, 5, 6]
        assert np.abs(q[others] - panda.HOME[others]).max() < 5e-3


def test_cubic_with_velocities_passes_through_the_middle_point():
    with World() as world:
        twin = Twin(world)
        mid, end = panda.HOME[:7] + 0.3, panda.HOME[:7] + 0.6
        seen = []
        traj = {'joint_names': list(panda.ARM_JOINT_NAMES), 'points': [
            {'positions': list(panda.HOME[:7]), 'velocities': [0.0] * 7, 'time_from_start': 0.0},
            {'positions': list(mid), 'velocities': [0.4] * 7, 'time_from_start': 0.75},
            {'positions': list(end), 'velocities': [0.0] * 7, 'time_from_start': 1.5}]}
        report = twin.execute(traj, callback=lambda tw: seen.append((tw.time, tw.world.joint_positions()[:7])),
                              callback_period=0.25)
        at_mid = min(seen, key=lambda s: abs(s[0] - 0.75))[1]
        assert np.abs(at_mid - mid).max() < 0.01
        assert report.final_error < 2e-3


def test_advance_in_slices_reports_once_and_a_new_trajectory_preempts():
    with World() as world:
        twin = Twin(world)
        twin.start(arm_move(panda.HOME[:7] + 0.2, 0.5))
        reports = [r for r in (twin.advance(1 / 50) for _ in range(60)) if r is not None]
        assert len(reports) == 1 and not reports[0]['preempted'] and not twin.busy
        assert reports[0]['final_error'] < 2e-3
        twin.start(arm_move(panda.HOME[:7], 1.0))
        twin.advance(0.3)
        info = twin.start(arm_move(panda.HOME[:7] - 0.2, 0.5))
        assert info == {'joints': list(panda.ARM_JOINT_NAMES), 'points': 1, 'duration': 0.5}
        done = None
        while done is None:
            done = twin.advance(0.1)
        assert np.abs(world.joint_positions()[:7] - (panda.HOME[:7] - 0.2)).max() < 2e-3


def test_execute_paced_to_real_time_takes_wall_time():
    with World() as world:
        twin = Twin(world)
        calls = []
        t0 = time.perf_counter()
        report = twin.execute(arm_move(panda.HOME[:7] + 0.05, 0.2), callback=calls.append, real_time_factor=2.0)
        wall = time.perf_counter() - t0
        assert wall >= report.sim_time / 2.0 - 0.01
        assert report.real_time_factor == pytest.approx(2.0, rel=0.2)
        assert len(calls) >= report.sim_time / 0.02 - 1


# ---- bad trajectories: a clear error, nothing moves --------------------------

GOOD = list(panda.HOME)


def _pt(pos, t, vel=None):
    d = {'positions': pos, 'time_from_start': t}
    if vel is not None:
        d['velocities'] = vel
    return d


BAD = [
    ({'joint_names': ['panda_joint1', 'elbow'], 'points': [_pt([0, 0], 1)]}, "unknown joint name 'elbow'"),
    ({'joint_names': ['panda_joint1', 'panda_joint1'], 'points': [_pt([0, 0], 1)]}, "'panda_joint1' is named twice"),
    ({'joint_names': list(panda.JOINT_NAMES), 'points': [_pt(GOOD[:3] + [math.nan] + GOOD[4:], 1)]},
     'NaN or infinity'),
    ({'joint_names': list(panda.JOINT_NAMES), 'points': [_pt(GOOD, 1, [0.0] * 8 + [math.inf])]}, 'NaN or infinity'),
    ({'joint_names': ['panda_joint1'], 'points': [_pt([0.1], math.nan)]}, 'time_from_start must be a finite'),
    ({'joint_names': ['panda_joint4'], 'points': [_pt([0.5], 1)]}, 'panda_joint4 = 0.5000 is outside its limits'),
    ({'joint_names': ['panda_finger_joint1'], 'points': [_pt([0.06], 1)]}, 'outside its limits'),
    ({'joint_names': ['panda_joint1'], 'points': [_pt([0.1], 1.0), _pt([0.2], 1.0)]}, 'does not increase'),
    ({'joint_names': ['panda_joint1'], 'points': [_pt([0.1], 1.0), _pt([0.2], 0.5)]}, 'does not increase'),
    ({'joint_names': ['panda_joint1'], 'points': [_pt([0.1], -0.1)]}, 'is negative'),
    ({'joint_names': ['panda_joint1'], 'points': []}, 'has no points'),
    ({'joint_names': ['panda_joint1', 'panda_joint2'], 'points': [_pt([0.1], 1)]}, '1 positions for 2 joint names'),
    ({'joint_names': ['panda_joint1'], 'points': [_pt([0.1], 1, [0.0, 0.0])]}, '2 velocities for 1 joint names'),
    ({'joint_names': [], 'points': [_pt([], 1)]}, 'non-empty list'),
    ({'points': []}, 'expected {"joint_names"'),
    ({'joint_names': ['panda_joint1'], 'points': [{'positions': 'a', 'time_from_start': 1}]}, 'list of numbers'),
]


@pytest.mark.parametrize('traj, message', BAD)
def test_bad_trajectory_is_refused_and_nothing_moves(twin, traj, message):
    twin.settle(0.1)
    q0, poses0 = twin.world.joint_positions(), twin.block_poses()
    twin.start(arm_move(panda.HOME[:7] + 0.1, 1.0))      # the running one must go on untouched
    twin.advance(0.2)
    mid = twin.world.joint_positions()
    with pytest.raises(RadError, match='trajectory') as e:
        twin.start(traj)
    assert message in str(e.value)
    assert np.array_equal(twin.world.joint_positions(), mid) and twin.busy
    report = None
    while report is None:
        report = twin.advance(0.25)
    assert not report['preempted'] and np.abs(twin.world.joint_positions()[:7] - q0[:7] - 0.1).max() < 2e-3
    for bid, (pos, _) in twin.block_poses().items():
        assert np.linalg.norm(pos - poses0[bid][0]) < 1e-4


def test_positions_a_hair_past_a_limit_are_clipped_not_refused():
    lo = panda.LOWER[3] - 5e-4
    traj = parse_trajectory({'joint_names': ['panda_joint4'], 'points': [_pt([lo], 1)]})
    assert traj.positions()[0, 0] == panda.LOWER[3]



def test_a_trajectory_object_is_taken_as_its_dict_form_is():
    traj = Trajectory(panda.ARM_JOINT_NAMES, [TrajectoryPoint(list(panda.HOME[:7] + 0.2), [], 0.5),
                                              TrajectoryPoint(list(panda.HOME[:7] + 0.3), [], 1.0)])
    finals = []
    for form in (traj, traj.to_dict()):
        with World() as world:
            twin = Twin(world)
            assert twin.start(form) == {'joints': list(panda.ARM_JOINT_NAMES), 'points': 2, 'duration': 1.0}
            finals.append(twin.execute(form).final_positions)
    assert np.array_equal(finals[0], finals[1])
    bad = Trajectory(('panda_joint1',), [TrajectoryPoint([0.1], [], 1.0), TrajectoryPoint([math.nan], [], 2.0)])
    with pytest.raises(RadError, match='trajectory point 1 positions: contains NaN or infinity'):
        parse_trajectory(bad)

# ---- grasping ---------------------------------------------------------------------

def test_pick_and_place_puts_the_cube_on_its_target(twin):
    held = []
    traj = pick_and_place(twin.world)
    report = twin.execute(traj, callback=lambda tw: held.append((tw.time, tw.attached and tw.attached[0])))
    twin.settle(0.3)
    pos, quat = twin.world.block_pose('c0')
    assert np.linalg.norm(pos - PLACE) < 0.004
    assert abs(quat[2]) < 0.02                                   # still yaw 0 (or close)
    assert [(e['action'], e['block']) for e in report.grasp_events] == [('attach', 'c0'), ('detach', 'c0')]
    # Attached while it was lifted and carried (2.5 s .. 6.5 s), not before closing or after opening.
    assert all(b == 'c0' for t, b in held if 3.2 < t < 6.4)
    assert all(b is None for t, b in held if t < 2.5 or t > 7.1)
    assert twin.attached is None and twin.current_scene().block('c0').position == pytest.approx(tuple(PLACE))


def test_fingers_closing_on_air_attach_nothing(twin):
    report = twin.execute({'joint_names': list(panda.FINGER_JOINT_NAMES),
                           'points': [_pt([0.0, 0.0], 0.5)]})
    assert report.grasp_events == [] and twin.attached is None
    assert twin.world.joint_positions()[7:] == pytest.approx([0.0, 0.0], abs=2e-3)


def test_closing_next_to_a_cube_with_one_finger_touching_attaches_nothing(twin):
    # The hand 3 cm off to the side of the cube along the closing axis: one finger
    # sweeps into it, the other closes on air.
    side = PICK + [0.03, 0, 0.005]
    above = ik(twin.world, side + [0, 0, 0.15], CLOSE_ALONG_X, panda.HOME[:7])
    at = ik(twin.world, side, CLOSE_ALONG_X, above)
    twin.execute({'joint_names': list(panda.JOINT_NAMES), 'points': [
        _pt(list(above) + [0.04, 0.04], 1.5), _pt(list(at) + [0.04, 0.04], 2.5), _pt(list(at) + [0.0, 0.0], 3.0)]})
    assert twin.attached is None


def test_reloading_a_scene_drops_the_grasp(twin):
    traj = pick_and_place(twin.world)
    traj['points'] = traj['points'][:4]                         # stop after the lift, cube held
    twin.execute(traj)
    assert twin.attached is not None and twin.world.block_pose('c0')[0][2] > 0.1
    twin.load_scene(one_cube_scene())
    assert twin.attached is None and not twin.busy
    twin.settle(0.2)
    assert np.linalg.norm(twin.world.block_pose('c0')[0] - PICK) < 1e-3


def test_current_scene_registers_the_world_and_bodies_are_mocap_poses(twin):
    bodies = twin.bodies()
    assert [b.name for b in bodies] == ['c0'] and bodies[0].position == pytest.approx(tuple(PICK), abs=1e-6)
    assert twin.current_scene().to_dict() == one_cube_scene().to_dict()
    names, q, dq = twin.joint_state()
    assert names == panda.JOINT_NAMES and q.shape == dq.shape == (9,)


def test_config_is_checked():
    with pytest.raises(RadError):
        TwinConfig(finger_force=math.nan)
    with pytest.raises(RadError):
        TwinConfig(arm_forces=(1.0,))


@pytest.mark.parametrize('seed', [1, 3])
def test_a_twin_at_rest_reports_the_scene_it_was_loaded_with(seed):
    from rad_core.generator import GeneratorConfig, generate_scene
    scene = generate_scene(GeneratorConfig(grid=4), seed)
    with World() as world:
        twin = Twin(world)
        twin.load_scene(scene)
        twin.settle(2.0)
        assert twin.current_scene(scene).to_dict() == scene.to_dict()

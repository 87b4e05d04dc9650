"""sim.Twin as a real Franka cell: arm trajectories checked like a franka_ros2 controller
checks them (7 arm joints, Franka's limits at 1 kHz, FollowJointTrajectory error codes),
followed by quintic interpolation, the hand driven by gripper commands, grasping.

Valid arm motion comes from `rad_core.gamp.trajectory.retime` (ruckig, rest to rest) or,
for a hand-made move, a single point at rest (zero velocity and acceleration: a quintic
from rest to rest). Position-only trajectories are what a real Franka refuses.
"""

import math
import re
import time

import numpy as np
import pytest
from rad_core.cell import panda
from rad_core.cell.motion import GripperCommand, Motion, grasp_problem
from rad_core.cell.robot_model import FR3, PANDA
from rad_core.cell.trajectory import (
    GOAL_TOLERANCE_VIOLATED,
    INVALID_GOAL,
    INVALID_JOINTS,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    Spline,
    Trajectory,
    TrajectoryPoint,
    TrajectoryRejected,
    parse_trajectory,
)
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.gamp.trajectory import retime
from rad_core.sim.twin import Tolerances, Twin, TwinConfig
from rad_core.sim.world import World

U = 0.05
PICK = np.array([0.5, -0.2, U / 2])
PLACE = np.array([0.5, 0.15, U / 2])
CLOSE_ALONG_X = math.pi / 2            # hand yaw whose fingers close along world x
HOME7 = panda.HOME[:7]
ARM = list(panda.ARM_JOINT_NAMES)
GRASP = GripperCommand('grasp', U / 2 - 0.001, 20.0, 0, U / 2)   # as GAMP commands it: 1 mm inside the faces
OPEN = GripperCommand('release', panda.FINGER_OPEN, 20.0, 0)


def one_cube_scene(extra_blocks=(), at=PICK) -> Scene:
    return Scene.from_dict({
        'format': 'rad-scene/1', 'unit': U, 'block_types': {'cube': [[0, 0, 0]]},
        'blocks': [{'id': 'c0', 'type': 'cube', 'position': list(at), 'yaw': 0}, *extra_blocks],
        'targets': [{'name': 't', 'origin': PLACE.tolist(), 'size': [1, 1, 1], 'filled': [[0, 0, 0]]}]})


@pytest.fixture
def twin():
    with World(one_cube_scene()) as world:
        yield Twin(world)


@pytest.fixture
def bare():
    with World() as world:
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


def move(*waypoints, speed=0.5, model=PANDA, names=None) -> Trajectory:
    """The arm through (7,) waypoints (the first: where it is), timed within the model's limits."""
    return retime([np.asarray(w, dtype=float)[:7] for w in waypoints], model, speed, names)


def rest_move(q7, t, names=ARM) -> dict:
    """One point at rest: the controller makes a quintic from rest to rest of it."""
    return {'joint_names': list(names),
            'points': [{'positions': list(q7), 'velocities': [0.0] * 7, 'accelerations': [0.0] * 7,
                        'time_from_start': t}]}


def scaled(traj: Trajectory, k: float) -> Trajectory:
    """The same path with every time multiplied by k (k < 1: faster)."""
    return Trajectory(traj.joint_names, [
        TrajectoryPoint(p.positions, [v / k for v in p.velocities], p.time_from_start * k,
                        [a / k / k for a in p.accelerations]) for p in traj.points])


def ratio_in(error) -> float:
    """The 'N.NNx' by which a limit message says the limit is exceeded."""
    return float(re.search(r'\((\d+\.\d+)x', str(error)).group(1))


def run_to_end(twin: Twin, slice_s=0.1) -> dict:
    report = None
    while report is None:
        report = twin.advance(slice_s)
    return report


def finger_contacts(world: World, block_id: str) -> list[bool]:
    """Whether each finger link touches the block."""
    p = world.pybullet
    return [any(c[8] < 1e-3 for c in p.getContactPoints(bodyA=world.robot, linkIndexA=link,
                                                         bodyB=world.blocks[block_id], physicsClientId=world.client))
            for link in world.finger_links]


def pick_and_place(twin: Twin, pick=PICK, place=PLACE, drop=0.007, callback=None, stop_after_lift=False):
    """Retimed arm moves and gripper commands: above the cube, down, grasp, lift, over the target,
    down, release, up. Returns the grasp's result and the (start, end) twin times of each phase."""
    world, up = twin.world, np.array([0, 0, 0.15])
    above = ik(world, pick + up, CLOSE_ALONG_X, HOME7)
    at = ik(world, pick + [0, 0, 0.005], CLOSE_ALONG_X, above)
    above_place = ik(world, place + up, CLOSE_ALONG_X, above)
    at_place = ik(world, place + [0, 0, drop], CLOSE_ALONG_X, above_place)
    phases = {}

    def phase(name, run):
        t0 = twin.time
        out = run()
        phases[name] = (t0, twin.time)
        return out

    q0 = world.joint_positions()[:7]
    for name, run in [
            ('approach', lambda: twin.execute(move(q0, above, at), callback)),
            ('grasp', lambda: twin.execute_gripper(GRASP, callback)),
            ('lift', lambda: twin.execute(move(at, above), callback)),
            ('carry', lambda: twin.execute(move(above, above_place, at_place), callback)),
            ('release', lambda: twin.execute_gripper(OPEN, callback)),
            ('retreat', lambda: twin.execute(move(at_place, above_place), callback))]:
        out = phase(name, run)
        if name == 'grasp':
            grasp = out
        else:
            assert name == 'release' or out.error_code == SUCCESSFUL, (name, out.error_string)
        if stop_after_lift and name == 'lift':
            break
    return grasp, phases


# ---- following trajectories -------------------------------------------------

def test_arm_reaches_the_last_point(twin):
    target = HOME7.copy()
    target[[0, 1, 3, 6]] += [0.6, 0.4, 0.5, -0.8]
    traj = move(HOME7, target)
    report = twin.execute(traj)
    q = twin.world.joint_positions()
    assert report.error_code == SUCCESSFUL and report.error_string == '' and not report.preempted
    assert np.abs(q[:7] - target).max() < 2e-3
    assert report.final_error < 2e-3 and report.max_tracking_error < 0.02
    assert report.duration == traj.duration
    assert traj.duration <= report.sim_time <= traj.duration + 0.5 and report.steps == round(report.sim_time * 240)
    assert report.real_time_factor > 1
    # The arm controller does not touch the hand: the fingers held their command (open).
    assert q[7:] == pytest.approx([0.04, 0.04], abs=1e-3)


def test_names_in_any_order_reach_the_same_joints():
    target = HOME7 + [0.3, 0.2, -0.2, 0.4, 0.1, -0.3, 0.2]
    traj = move(HOME7, target)
    order = [4, 0, 6, 2, 5, 1, 3]
    shuffled = traj.to_dict()
    shuffled['joint_names'] = [ARM[k] for k in order]
    for pt in shuffled['points']:
        for key in ('positions', 'velocities', 'accelerations'):
            pt[key] = [pt[key][k] for k in order]
    finals = []
    for form in (traj, shuffled):
        with World() as world:
            twin = Twin(world)
            assert twin.start(form)['joints'] == ARM              # taken in the model's order
            finals.append(run_to_end(twin)['final_positions'])
    assert np.abs(np.array(finals[1][:7]) - target).max() < 2e-3
    assert finals[0] == finals[1]


def test_a_retimed_path_is_followed_through_its_waypoints(bare):
    """The quintic interpolation follows ruckig's motion: small tracking error, measured here
    against the interpolant independently of the report, and the arm stops at each waypoint."""
    mid = HOME7 + [0.5, 0.3, 0.0, 0.3, 0.0, -0.2, -0.5]
    end = HOME7 + [0.9, 0.0, 0.2, 0.5, 0.2, 0.1, -0.9]
    traj = move(HOME7, mid, end)
    at_mid = next(p.time_from_start for p in traj.points if np.array_equal(p.positions, mid))
    spline = Spline(parse_trajectory(traj), HOME7)
    t0, seen = bare.time, []
    report = bare.execute(traj, callback=lambda tw: seen.append((tw.time - t0, tw.world.joint_positions()[:7])),
                          callback_period=1 / 240)
    assert report.error_code == SUCCESSFUL and report.final_error < 2e-3
    errors = [np.abs(q - spline(t)[0]).max() for t, q in seen if t < traj.duration - 1e-9]
    assert len(errors) >= traj.duration * 240 - 2
    # Measured 0.0054 rad at speed_scale 0.5 (position gain 0.3 with velocity feed-forward).
    assert max(errors) < 0.01
    assert max(errors) == pytest.approx(report.max_tracking_error, abs=1e-9)
    passing = min(seen, key=lambda s: abs(s[0] - at_mid))[1]
    assert np.abs(passing - mid).max() < 0.01
    assert np.abs(bare.world.joint_positions()[:7] - end).max() < 2e-3


def test_advance_in_slices_reports_once_and_a_new_trajectory_preempts(bare):
    world = bare.world
    info = bare.start(move(HOME7, HOME7 + 0.2))
    assert info['joints'] == ARM and info['points'] >= 2 and info['duration'] > 0.1
    reports = [r for r in (bare.advance(1 / 50) for _ in range(60)) if r is not None]
    assert len(reports) == 1 and not reports[0]['preempted'] and not bare.busy
    assert reports[0]['error_code'] == SUCCESSFUL and reports[0]['final_error'] < 2e-3
    # A slow move back, replaced mid-way (the arm moving) by a move elsewhere.
    bare.start(rest_move(HOME7, 2.0))
    assert bare.advance(0.5) is None and bare.busy
    assert np.abs(world.joint_positions()[:7] - (HOME7 + 0.2)).max() > 0.02       # it is on its way
    info = bare.start(rest_move(HOME7 - 0.2, 2.0))
    assert info == {'joints': ARM, 'points': 1, 'duration': 2.0}
    done = run_to_end(bare)
    assert not done['preempted'] and done['error_code'] == SUCCESSFUL
    assert np.abs(world.joint_positions()[:7] - (HOME7 - 0.2)).max() < 2e-3


def test_execute_paced_to_real_time_takes_wall_time(bare):
    calls = []
    t0 = time.perf_counter()
    # Real time: unpaced the twin runs ~3x faster, so pacing (not compute) sets the wall time.
    report = bare.execute(move(HOME7, HOME7 + 0.1), callback=calls.append, real_time_factor=1.0)
    wall = time.perf_counter() - t0
    assert report.error_code == SUCCESSFUL
    assert wall >= report.sim_time - 0.01
    assert report.real_time_factor == pytest.approx(1.0, rel=0.2)
    assert len(calls) >= report.sim_time / 0.02 - 1


def test_a_trajectory_object_is_taken_as_its_dict_form_is():
    traj = move(HOME7, HOME7 + 0.2, HOME7 + 0.3)
    finals = []
    for form in (traj, traj.to_dict()):
        with World() as world:
            twin = Twin(world)
            assert twin.start(form) == {'joints': ARM, 'points': len(traj.points), 'duration': traj.duration}
            finals.append(twin.execute(form).final_positions)
    assert np.array_equal(finals[0], finals[1])
    bad = Trajectory(tuple(ARM), [TrajectoryPoint(list(HOME7), [], 1.0), TrajectoryPoint([math.nan] * 7, [], 2.0)])
    with pytest.raises(TrajectoryRejected, match='trajectory point 1 positions: contains NaN or infinity'):
        parse_trajectory(bad)


# ---- cancel and tolerances ---------------------------------------------------

def test_cancel_stops_the_arm_where_it_is(bare):
    goal = HOME7 - [1.0, 0, 0, 0, 0, 0, 0]
    traj = move(HOME7, goal)
    assert bare.cancel() is None                              # nothing to cancel
    bare.start(traj)
    bare.advance(traj.duration / 2)
    found = bare.world.joint_positions()[:7]
    report = bare.cancel()
    assert report is not None and report.preempted and not bare.busy
    bare.settle(1.0)
    q = bare.world.joint_positions()[:7]
    # Measured: 4e-6 rad from where cancel found it.
    assert np.abs(q - found).max() < 3e-3
    assert np.abs(q - goal).max() > 0.2 and np.abs(q - HOME7).max() > 0.2


def test_a_path_tolerance_tighter_than_the_tracking_aborts_the_run(bare):
    goal = HOME7 + [0.5, 0.3, 0, 0.3, 0, 0, 0]
    report = bare.execute(move(HOME7, goal), tolerances=Tolerances(path=1e-4))
    assert report.error_code == PATH_TOLERANCE_VIOLATED
    assert report.error_string.endswith("(no contact)"), report.error_string   # the twin names what it touches
    assert re.search(r'path tolerance violated: panda_joint\d is 0\.\d+ rad from the command', report.error_string)
    assert report.sim_time < 0.2 and not bare.busy
    bare.settle(0.5)
    assert np.abs(bare.world.joint_positions()[:7] - goal).max() > 0.2        # it stopped, not arrived
    # The same motion with room for the tracking goes through.
    report = bare.execute(move(bare.world.joint_positions(), goal), tolerances=Tolerances(path=0.05))
    assert report.error_code == SUCCESSFUL and report.final_error < 2e-3


def test_a_goal_tolerance_the_arm_cannot_meet_fails_the_goal(bare):
    report = bare.execute(move(HOME7, HOME7 + 0.2), tolerances=Tolerances(goal=1e-9, goal_time=0.1))
    assert report.error_code == GOAL_TOLERANCE_VIOLATED and 'goal tolerance violated' in report.error_string
    assert 0 < report.final_error < 2e-3


def test_tolerances_must_be_finite_and_non_negative(bare):
    for tol in (Tolerances(path=math.nan), Tolerances(goal=-1.0), Tolerances(goal_time=math.inf)):
        with pytest.raises(TrajectoryRejected, match='tolerances must be finite') as e:
            bare.start(move(HOME7, HOME7 + 0.1), tol)
        assert e.value.code == INVALID_GOAL and not bare.busy


# ---- Franka's limits ----------------------------------------------------------

def test_a_trajectory_over_the_limits_is_refused_and_nothing_moves(bare):
    target = HOME7 + [0.6, 0.4, 0.0, 0.5, 0.0, 0.0, -0.8]
    traj = move(HOME7, target)
    assert bare.start(traj)['duration'] == traj.duration      # at speed 0.5: taken
    bare.cancel()
    bare.sync()
    q0 = bare.world.joint_positions()
    fast = scaled(traj, 0.3)                                  # ~3x too fast
    with pytest.raises(TrajectoryRejected) as e:
        bare.start(fast)
    assert e.value.code == INVALID_GOAL
    assert re.search(r"over the panda's limits: panda_joint\d: (velocity|acceleration|jerk) [\d.]+ exceeds the "
                     r'panda limit [\d.]+ \(\d+\.\d+x', str(e.value)), str(e.value)
    assert ratio_in(e.value) > 1.5
    assert not bare.busy and np.array_equal(bare.world.joint_positions(), q0)
    bare.settle(0.2)
    assert np.abs(bare.world.joint_positions() - q0).max() < 1e-3


def test_a_position_only_move_from_rest_is_refused(bare):
    traj = {'joint_names': ARM, 'points': [{'positions': list(HOME7 + 0.2), 'time_from_start': 0.5}]}
    with pytest.raises(TrajectoryRejected, match=r'panda_joint\d: (acceleration|jerk)') as e:
        bare.start(traj)
    assert e.value.code == INVALID_GOAL and not bare.busy


def test_a_first_point_at_t0_away_from_the_arm_is_a_jump(bare):
    q0 = bare.world.joint_positions()
    jump = {'joint_names': ARM, 'points': [{'positions': list(HOME7 + [0.3, 0, 0, 0, 0, 0, 0]),
                                            'time_from_start': 0.0}]}
    with pytest.raises(TrajectoryRejected, match=r'panda_joint1: the first point at t = 0 is \+0\.3000 rad from '
                                                 r'where the arm is \(a jump\)') as e:
        bare.start(jump)
    assert e.value.code == INVALID_GOAL and not bare.busy
    bare.settle(0.2)
    assert np.abs(bare.world.joint_positions() - q0).max() < 1e-3
    # A first point at t = 0 where the arm is, at rest, is the controller's own start: taken.
    traj = move(HOME7, HOME7 + 0.2)
    traj.points.insert(0, TrajectoryPoint(list(HOME7), [0.0] * 7, 0.0, [0.0] * 7))
    report = bare.execute(traj)
    assert report.error_code == SUCCESSFUL and report.final_error < 2e-3


def _joint1_move():
    """A move dominated by joint 1's acceleration (Panda 15, FR3 10 rad/s^2)."""
    return HOME7 + [1.0, 0, 0, 0, 0, 0, 0]


def test_an_fr3_twin_refuses_what_the_panda_takes():
    target = _joint1_move()
    # Timed at 90% of the Panda's limits: joint 1 accelerates at 13.5 rad/s^2.
    with World() as world:
        twin = Twin(world)
        report = twin.execute(move(HOME7, target, speed=0.9))
        assert report.error_code == SUCCESSFUL and report.final_error < 2e-3
    with World() as world:
        twin = Twin(world, TwinConfig(robot='fr3'))
        assert twin.joint_state()[0] == FR3.arm_joint_names + FR3.finger_joint_names
        q0 = world.joint_positions()
        for speed in (0.9, 1.0):
            traj = move(HOME7, target, speed=speed, names=FR3.arm_joint_names)
            with pytest.raises(TrajectoryRejected) as e:
                twin.start(traj)
            assert e.value.code == INVALID_GOAL
            assert re.search(r"over the fr3's limits: fr3_joint1: acceleration [\d.]+ exceeds the fr3 limit 10 ",
                             str(e.value)), str(e.value)
            assert ratio_in(e.value) == pytest.approx(1.5 * speed, abs=0.01)      # 15 x speed vs 10 rad/s^2
            assert not twin.busy and np.array_equal(world.joint_positions(), q0)
        # Panda names are not an FR3 controller's joints.
        with pytest.raises(TrajectoryRejected, match="incoming joint 'panda_joint1'") as e:
            twin.start(move(HOME7, target, speed=0.5))
        assert e.value.code == INVALID_JOINTS
        # Timed for the FR3 it goes through.
        report = twin.execute(move(HOME7, target, model=FR3))
        assert report.error_code == SUCCESSFUL and report.final_error < 2e-3
        assert report.joint_names == FR3.arm_joint_names


@pytest.mark.parametrize('model', [PANDA, FR3], ids=['panda', 'fr3'])
def test_a_full_speed_trajectory_is_taken_on_the_limits_it_was_timed_for(model):
    with World() as world:
        twin = Twin(world, TwinConfig(robot=model.name))
        report = twin.execute(move(HOME7, _joint1_move(), speed=1.0, model=model))
        assert report.error_code == SUCCESSFUL and report.final_error < 2e-3


# ---- bad trajectories: the right code and message, nothing moves --------------

GOOD = list(HOME7)


def _pt(pos, t, vel=None, acc=None):
    d = {'positions': pos, 'time_from_start': t}
    if vel is not None:
        d['velocities'] = vel
    if acc is not None:
        d['accelerations'] = acc
    return d


def _with(j, value):
    q = list(GOOD)
    q[j] = value
    return q


BAD = [
    ({'joint_names': ['panda_joint1', 'elbow'], 'points': [_pt([0, 0], 1)]}, INVALID_JOINTS,
     "incoming joint 'elbow' does not match the controller's joints (panda_joint1, "),
    ({'joint_names': list(panda.JOINT_NAMES), 'points': [_pt(list(panda.HOME), 1)]}, INVALID_JOINTS,
     "incoming joint 'panda_finger_joint1' does not match"),
    ({'joint_names': ['panda_joint4', 'panda_joint1'], 'points': [_pt([-2.0, 0.3], 1)]}, INVALID_JOINTS,
     "joint 'panda_joint2' is missing (the controller takes only goals for all of panda_joint1"),
    ({'joint_names': list(FR3.arm_joint_names), 'points': [_pt(GOOD, 1)]}, INVALID_JOINTS,
     "incoming joint 'fr3_joint1'"),
    ({'joint_names': ARM[:6] + ['panda_joint1'], 'points': [_pt(GOOD, 1)]}, INVALID_JOINTS,
     "'panda_joint1' is named twice"),
    ({'joint_names': [], 'points': [_pt([], 1)]}, INVALID_JOINTS, 'non-empty list'),
    ({'points': []}, INVALID_GOAL, 'expected {"joint_names"'),
    ({'joint_names': ARM, 'points': [_pt(_with(3, math.nan), 1)]}, INVALID_GOAL,
     'trajectory point 0 positions: contains NaN or infinity'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, 1, [0.0] * 6 + [math.inf])]}, INVALID_GOAL,
     'trajectory point 0 velocities: contains NaN or infinity'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, math.nan)]}, INVALID_GOAL, 'time_from_start must be a finite'),
    ({'joint_names': ARM, 'points': [_pt(_with(3, 0.5), 1)]}, INVALID_GOAL,
     'panda_joint4 = 0.5000 is outside its limits [-3.0718, -0.0698] (panda)'),
    # Inside the URDF's range (-0.0873) but outside Franka's published one.
    ({'joint_names': ARM, 'points': [_pt(_with(5, -0.05), 1)]}, INVALID_GOAL,
     'panda_joint6 = -0.0500 is outside its limits [-0.0175, 3.7525]'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, 1.0), _pt(GOOD, 1.0)]}, INVALID_GOAL,
     'trajectory point 1: time_from_start 1.0 does not increase'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, 1.0), _pt(GOOD, 0.5)]}, INVALID_GOAL, 'does not increase'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, -0.1)]}, INVALID_GOAL, 'is negative'),
    ({'joint_names': ARM, 'points': []}, INVALID_GOAL, 'has no points'),
    ({'joint_names': ARM, 'points': [_pt(GOOD[:6], 1)]}, INVALID_GOAL, '6 positions for 7 joint names'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, 1, [0.0, 0.0])]}, INVALID_GOAL, '2 velocities for 7 joint names'),
    ({'joint_names': ARM, 'points': [_pt(GOOD, 1, None, [0.0] * 7)]}, INVALID_GOAL,
     '7 accelerations for 7 joint names (all or none, and only with velocities)'),
    ({'joint_names': ARM, 'points': [{'positions': 'a', 'time_from_start': 1}]}, INVALID_GOAL, 'list of numbers'),
    ({'joint_names': ARM, 'points': [_pt(_with(0, -0.3), 0.0)]}, INVALID_GOAL, 'a jump'),
]


@pytest.mark.parametrize('traj, code, message', BAD)
def test_bad_trajectory_is_refused_and_nothing_moves(twin, traj, code, message):
    twin.settle(0.1)
    q0, poses0 = twin.world.joint_positions(), twin.block_poses()
    twin.start(move(q0, q0[:7] + 0.3))                      # the running one must go on untouched
    twin.advance(0.2)
    mid = twin.world.joint_positions()
    with pytest.raises(TrajectoryRejected) as e:
        twin.start(traj)
    assert e.value.code == code and message in str(e.value), str(e.value)
    assert np.array_equal(twin.world.joint_positions(), mid) and twin.busy
    report = run_to_end(twin, 0.25)
    assert not report['preempted'] and report['error_code'] == SUCCESSFUL
    assert np.abs(twin.world.joint_positions()[:7] - q0[:7] - 0.3).max() < 2e-3
    for bid, (pos, _) in twin.block_poses().items():
        assert np.linalg.norm(pos - poses0[bid][0]) < 1e-4


def test_positions_a_hair_past_a_limit_are_clipped_not_refused(bare):
    lo = PANDA.q_min[3]
    traj = parse_trajectory({'joint_names': ARM, 'points': [_pt(_with(3, lo - 5e-4), 1)]})
    assert traj.positions()[0, 3] == lo
    with pytest.raises(TrajectoryRejected, match='panda_joint4 = -3.0738 is outside its limits'):
        parse_trajectory({'joint_names': ARM, 'points': [_pt(_with(3, lo - 2e-3), 1)]})
    # The twin takes the hair and stops at the limit.
    report = bare.execute(rest_move(_with(3, lo - 5e-4), 2.0))
    assert report.error_code == SUCCESSFUL
    assert bare.world.joint_positions()[3] == pytest.approx(lo, abs=2e-3)


# ---- the hand and grasping --------------------------------------------------------------

def test_pick_and_place_puts_the_cube_on_its_target(twin):
    held = []
    grasp, phases = pick_and_place(twin, callback=lambda tw: held.append((tw.time, tw.attached and tw.attached[0])))
    assert grasp.reached_goal and grasp_problem(GRASP, grasp) == ''
    assert grasp.position == pytest.approx(U / 2, abs=1e-3)     # stopped on the faces, not at the command
    twin.settle(0.3)
    pos, quat = twin.world.block_pose('c0')
    assert np.linalg.norm(pos - PLACE) < 0.004
    assert abs(quat[2]) < 0.02                                   # still yaw 0 (or close)
    # Attached from the grasp through the carry; not before closing, not after the release.
    assert all(b is None for t, b in held if t <= phases['grasp'][0])
    assert all(b == 'c0' for t, b in held if phases['lift'][0] < t <= phases['carry'][1])
    assert all(b is None for t, b in held if t > phases['release'][1])
    assert twin.attached is None and twin.current_scene().block('c0').position == pytest.approx(tuple(PLACE))


def test_fingers_closing_on_air_attach_nothing_and_the_grasp_says_so(twin):
    command = GripperCommand('grasp', 0.0, 20.0, 0, U / 2)
    result = twin.execute_gripper(command)
    assert twin.attached is None and twin.gripper_result == result
    assert result.position < 1e-3 and result.effort == 20.0
    assert twin.world.joint_positions()[7:] == pytest.approx([0.0, 0.0], abs=2e-3)
    assert 'nothing is held' in grasp_problem(command, result)
    # Opening is a move at the gripper's speed back to the open width.
    opened = twin.execute_gripper(OPEN)
    assert opened.reached_goal and opened.position == pytest.approx(panda.FINGER_OPEN, abs=5e-4)


def test_a_plan_step_whose_grasp_closes_on_air_fails_at_the_grasp():
    from rad_core.gamp.action import MotionPlanner, SceneAction
    planner = MotionPlanner()
    try:
        result, _, _ = planner(one_cube_scene(), SceneAction('c0', 0, 't', (0, 0, 0), 0))
    finally:
        planner.close()
    assert result.success
    # The cube is gone from where the plan expects it (moved by hand before the step ran).
    with World(one_cube_scene(at=[0.3, -0.45, U / 2])) as world:
        twin = Twin(world)
        why = twin.execute_motion(result.motion)
        assert twin.attached is None
        assert why.startswith('grasp failed:') and 'nothing is held' in why


def test_reloading_a_scene_drops_the_grasp(twin):
    grasp, _ = pick_and_place(twin, stop_after_lift=True)        # the cube held, lifted
    assert grasp.reached_goal
    assert twin.attached is not None and twin.world.block_pose('c0')[0][2] > 0.1
    twin.load_scene(one_cube_scene())
    assert twin.attached is None and not twin.busy
    twin.settle(0.2)
    assert np.linalg.norm(twin.world.block_pose('c0')[0] - PICK) < 1e-3
    assert np.abs(twin.world.joint_positions()[:7] - HOME7).max() < 2e-3
    # Nothing left over from the old grasp: the next trajectory starts from HOME.
    report = twin.execute(move(HOME7, HOME7 + 0.1))
    assert report.error_code == SUCCESSFUL and report.grasp_events == []


def test_a_planned_step_runs_through_execute_motion(twin):
    from rad_core.gamp.action import MotionPlanner, SceneAction
    planner = MotionPlanner()
    try:
        result, position, _ = planner(twin.current_scene(), SceneAction('c0', 0, 't', (0, 0, 0), 0),
                                      start=twin.world.joint_positions())
    finally:
        planner.close()
    # From HOME's full opening the hand first closes empty, then opens to the approach width (a Franka
    # hand's gripper_action only moves when opening).
    assert result.success and [g.action for g in result.motion.gripper] == ['close', 'open', 'grasp', 'release']
    grasps = []
    twin.execute_gripper = (lambda run: lambda c, *a, **k: grasps.append((c, run(c, *a, **k))) or grasps[-1][1])(
        twin.execute_gripper)
    assert twin.execute_motion(result.motion) == ''
    command, grasp = next((c, r) for c, r in grasps if c.action == 'grasp')
    assert grasp.reached_goal and grasp_problem(command, grasp) == ''
    assert grasp.position == pytest.approx(U / 2, abs=1e-3)
    twin.settle(0.3)
    assert twin.attached is None and np.linalg.norm(twin.world.block_pose('c0')[0] - position) < 0.004
    assert twin.current_scene().block('c0').position == pytest.approx(tuple(PLACE))


def test_execute_motion_reports_a_refused_trajectory(twin):
    traj = move(HOME7, HOME7 + [0.6, 0.4, 0, 0.5, 0, 0, -0.8])
    # 'open' to the full opening: the hand is open already (a narrower 'open' would be a grasp on air).
    why = twin.execute_motion(Motion([scaled(traj, 0.3)], [GripperCommand('open', 0.04, 20.0, 0)]))
    assert why.startswith('trajectory refused (error code -1): over the panda\'s limits: panda_joint')
    assert np.abs(twin.world.joint_positions()[:7] - HOME7).max() < 1e-3


def test_gripper_commands_are_checked(bare):
    with pytest.raises(RadError, match='outside the hand'):
        bare.grip(0.05, 20.0)
    with pytest.raises(RadError, match='outside the hand'):
        bare.grip(math.nan, 20.0)
    with pytest.raises(RadError, match='max_effort must be finite'):
        bare.grip(0.02, -1.0)
    assert not bare.busy


# ---- the world as the cell reports it ----------------------------------------------

def test_current_scene_registers_the_world_and_bodies_are_mocap_poses(twin):
    bodies = twin.bodies()
    assert [b.name for b in bodies] == ['c0'] and bodies[0].position == pytest.approx(tuple(PICK), abs=1e-6)
    assert twin.current_scene().to_dict() == one_cube_scene().to_dict()
    names, q, dq = twin.joint_state()
    assert names == panda.JOINT_NAMES and q.shape == dq.shape == (9,)


def test_joint_names_come_from_the_robot_model():
    with World() as world:
        assert Twin(world, TwinConfig(robot='fr3')).joint_names == (
            tuple(f'fr3_joint{k}' for k in range(1, 8)) + ('fr3_finger_joint1', 'fr3_finger_joint2'))
        twin = Twin(world, TwinConfig(joint_prefix='fer'))
        assert twin.joint_state()[0][:7] == tuple(f'fer_joint{k}' for k in range(1, 8))
        with pytest.raises(TrajectoryRejected, match="incoming joint 'panda_joint1'"):
            twin.start(move(HOME7, HOME7 + 0.1))
        report = twin.execute(move(HOME7, HOME7 + 0.1, names=twin.joint_names[:7]))
        assert report.error_code == SUCCESSFUL and report.joint_names == twin.joint_names[:7]


def test_config_is_checked():
    with pytest.raises(RadError):
        TwinConfig(finger_force=math.nan)
    with pytest.raises(RadError):
        TwinConfig(arm_forces=(1.0,))
    with pytest.raises(RadError, match='unknown robot model'):
        TwinConfig(robot='ur5')


@pytest.mark.parametrize('seed', [1, 3])
def test_a_twin_at_rest_reports_the_scene_it_was_loaded_with(seed):
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    scene = generate_scene(GeneratorConfig(grid=4), seed)
    with World() as world:
        twin = Twin(world)
        twin.load_scene(scene)
        twin.settle(2.0)
        assert twin.current_scene(scene).to_dict() == scene.to_dict()


def test_a_path_abort_names_what_the_held_block_touches(twin):
    """The attachment is rigid: a carried block pressed into the table stops the arm, and the report says so."""
    pick_and_place(twin, stop_after_lift=True)
    assert twin.attached is not None and twin.attached[0] == 'c0'
    q = twin.world.joint_positions()[:7]
    below = ik(twin.world, PICK + [0, 0, -0.03], CLOSE_ALONG_X, q)      # 3 cm into the table
    report = twin.execute(move(q, below, speed=0.2), tolerances=Tolerances(path=0.02))
    assert report.error_code == PATH_TOLERANCE_VIOLATED
    assert report.error_string.endswith('holding block c0, which touches the table)'), report.error_string


def test_settling_until_rest_ends_after_two_calm_checks_and_runs_on_while_a_block_falls():
    with World(one_cube_scene()) as world:
        twin = Twin(world)
        ran = twin.settle_until_rest(0.5, 0.1, 0.025, 0.002, 0.05)
        assert ran == pytest.approx(0.15)          # 0.1 s, then two calm checks 25 ms apart
        assert twin.time == pytest.approx(ran)
    dropped = one_cube_scene(at=PICK + (0.0, 0.0, 0.1))    # 10 cm above the table: falls for ~0.14 s
    with World(dropped) as world:
        twin = Twin(world)
        ran = twin.settle_until_rest(0.5, 0.1, 0.025, 0.002, 0.05)
        assert 0.2 <= ran <= 0.5
        assert world.block_pose('c0')[0][2] == pytest.approx(U / 2, abs=2e-3)   # judged where it landed
        assert twin.settle_until_rest(0.05, 0.1, 0.025, 0.002, 0.05) == pytest.approx(0.05)   # capped


@pytest.mark.parametrize('args', [(-1, 0.1, 0.025, 0.002, 0.05), (0.5, 0.1, 0.0, 0.002, 0.05),
                                  (0.5, float('nan'), 0.025, 0.002, 0.05), (0.5, 0.1, 0.025, -1, 0.05)])
def test_settling_until_rest_refuses_bad_arguments(bare, args):
    with pytest.raises(RadError, match='settle_until_rest'):
        bare.settle_until_rest(*args)

"""Motion capture as drivers publish it: body map, calibration, frame check, tracker, bounded waits."""

import json
import math

import numpy as np
import pytest
from rad_core.cell.mocap import RegistrationConfig, RigidBodyPose, register_scene, scene_to_bodies
from rad_core.cell.mocap_input import (
    BodyEntry,
    BodyMap,
    FrameTransform,
    MocapFrames,
    MocapTracker,
    quaternion_multiply,
    wait_for_bodies,
)
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import matrix_from_quaternion, yaw_quaternion

from scenes import scene

TASK = scene()
BLOCKS = {b.id: b.type for b in TASK.blocks}                    # c0, c1 (cubes), i0 (I2 at yaw 90)
# A calibration with every component non-trivial: motion capture is turned 90 deg about z and
# tilted 10 deg about x, and its origin is away from the robot's.
TILT = (math.sin(math.radians(5)), 0.0, 0.0, math.cos(math.radians(5)))
CAL = FrameTransform((0.3, -0.1, 0.72), quaternion_multiply(yaw_quaternion(90), TILT))
FRAMES = MocapFrames('world', 'optitrack', CAL)


class Clock:
    """A fake monotonic clock; sleep() advances it and runs what the test scheduled."""

    def __init__(self, t=100.0):
        self.t = t
        self.on_sleep = None

    def __call__(self):
        return self.t

    def sleep(self, dt):
        self.t += dt
        if self.on_sleep is not None:
            self.on_sleep(self.t)


def as_driver_reports(bodies, body_map: BodyMap, frames: MocapFrames = FRAMES, valid=None):
    """What a motion-capture driver reports for base-frame anchor poses: renamed per the body map,
    at each body's pivot, in the motion-capture frame."""
    inverse = frames.transform.inverse()
    by_block = {e.block: e for e in body_map.entries}
    out = []
    for b in bodies:
        entry = by_block.get(b.name, BodyEntry(b.name, b.name))
        pivot = np.asarray(b.position) + matrix_from_quaternion(b.quaternion) @ np.asarray(entry.pivot)
        p, q = inverse.apply(pivot, b.quaternion)
        out.append(RigidBodyPose(entry.body, p, q, True if valid is None else valid.get(entry.body, True)))
    return out


def registered(bodies, resolved):
    return register_scene(bodies, TASK, RegistrationConfig(body_map=resolved.registration_map))


# ---- calibration and frames ------------------------------------------------------------

def test_transform_applies_rotation_and_translation_to_position_and_orientation():
    t = FrameTransform((1.0, 2.0, 3.0), yaw_quaternion(90))
    p, q = t.apply((1.0, 0.0, 0.0), yaw_quaternion(30))
    assert np.allclose(p, (1.0, 3.0, 3.0))                 # x turned onto y, then shifted
    assert np.allclose(q, yaw_quaternion(120))
    back_p, back_q = t.inverse().apply(p, q)
    assert np.allclose(back_p, (1.0, 0.0, 0.0)) and np.allclose(back_q, yaw_quaternion(30))
    assert FrameTransform().is_identity and not t.is_identity
    # Orientation: R_base = R_cal @ R_body (the body's axes turned into the base frame), not the reverse.
    _, q = CAL.apply((0, 0, 0), yaw_quaternion(90))
    assert np.allclose(matrix_from_quaternion(q), CAL.rotation @ matrix_from_quaternion(yaw_quaternion(90)))


@pytest.mark.parametrize('translation, quaternion, expected', [
    ((0, 0), (0, 0, 0, 1), 'mocap_to_base_translation must be 3 numbers'),
    ((0, 0, float('nan')), (0, 0, 0, 1), 'must be 3 finite numbers'),
    ((0, 0, 0), (0, 0, 0, 2), 'not unit length'),
    ((0, 0, 0), (0, 0, 1), 'must be 4 numbers'),
    ((0, 0, 0), ('a', 0, 0, 1), 'must be 4 numbers'),
])
def test_bad_calibration_parameters_are_refused_naming_them(translation, quaternion, expected):
    with pytest.raises(RadError, match=expected):
        FrameTransform(translation, quaternion)


def test_frame_check_names_both_frames_and_a_calibration_needs_a_frame():
    assert FRAMES.calibrated and FRAMES.expected_frame == 'optitrack'
    with pytest.raises(RadError, match="frame 'world', expected 'optitrack'"):
        FRAMES.check('world', '/rigid_bodies')
    plain = MocapFrames('base', '', in_base_frame=True)
    assert not plain.calibrated and plain.expected_frame == 'base'
    with pytest.raises(RadError, match="in frame 'mocap', expected 'base'"):
        plain.check('mocap', '/rigid_bodies')
    with pytest.raises(RadError, match="mocap_frame is ''"):
        MocapFrames('world', '', CAL)
    with pytest.raises(RadError, match="equals frame_id 'world'"):
        MocapFrames('world', 'world', CAL)
    assert not MocapFrames('world', 'world', in_base_frame=True).calibrated


# ---- the body map ----------------------------------------------------------------------

def test_body_map_from_yaml_and_json_files_with_defaults(tmp_path):
    (tmp_path / 'map.yaml').write_text('bodies:\n  Block_3: {block: c1, pivot: [0, 0, 0.012]}\nignore: [tool]\n')
    (tmp_path / 'map.json').write_text(json.dumps({'bodies': {'Block_3': {'block': 'c1', 'pivot': [0, 0, 0.012]}},
                                                   'ignore': ['tool']}))
    for name in ('map.yaml', 'map.json'):
        m = BodyMap.from_params(str(tmp_path / name), ['wand'])
        assert m.ignore == {'tool', 'wand'}
        r = m.resolve(BLOCKS)
        assert r.registration_map == {'c0': ('c0', 'cube'), 'Block_3': ('c1', 'cube'), 'i0': ('i0', 'I2')}
        assert r.by_body['Block_3'].pivot == (0.0, 0.0, 0.012) and r.by_body['c0'].pivot == (0.0, 0.0, 0.0)
    assert BodyMap.from_params('').resolve(BLOCKS).registration_map == {b: (b, t) for b, t in BLOCKS.items()}


@pytest.mark.parametrize('content, expected', [
    ('bodies: {A: {block: c0}, B: {block: c0}}', "'A' and 'B' are both mapped to block 'c0'"),
    ('bodies: {A: {block: c0}}\nignore: [A]', "'A' is both mapped and ignored"),
    ('bodies: {A: {block: c0, pivot: [0, 0, 12]}}', 'give metres, not millimetres'),
    ('bodies: {A: {block: c0, pivot: [0, 0]}}', "entry 'A': pivot must be 3 numbers"),
    ('bodies: {A: {id: c0}}', "body 'A' must be {block: ID"),
    ('bodys: {A: {block: c0}}', 'unknown keys'),
    ('ignore: tool', '"ignore" must be a list'),
    ('bodies: [A', 'not valid YAML'),
])
def test_bad_body_maps_are_refused_with_the_reason(tmp_path, content, expected):
    path = tmp_path / 'map.yaml'
    path.write_text(content)
    with pytest.raises(RadError, match=expected):
        BodyMap.load(path)


def test_body_map_conflicts_with_the_task_are_refused():
    with pytest.raises(RadError, match='cannot read'):
        BodyMap.load('/nonexistent/map.yaml')
    # A body named like a block that has its own entry elsewhere.
    clash = BodyMap((BodyEntry('c0', 'c1'),))
    with pytest.raises(RadError, match="rigid body 'c0' would be both block 'c0' and block 'c1'"):
        clash.resolve(BLOCKS)
    with pytest.raises(RadError, match="block 'c0' is tracked by rigid body 'c0', which ignore_bodies lists"):
        BodyMap((), frozenset({'c0'})).resolve(BLOCKS)


# ---- the tracker, end to end through registration -----------------------------------------

def test_driver_poses_with_pivots_in_a_calibrated_frame_register_the_task():
    body_map = BodyMap((BodyEntry('Block_3', 'c1', (0.01, -0.02, 0.012)), BodyEntry('Long', 'i0', (0.05, 0, 0))))
    resolved = body_map.resolve(BLOCKS)
    reports = as_driver_reports(scene_to_bodies(TASK), body_map)
    assert {b.name for b in reports} == {'c0', 'Block_3', 'Long'}
    assert not np.allclose(reports[1].position, TASK.blocks[1].position, atol=0.05)   # really another frame
    clock = Clock()
    tracker = MocapTracker(FRAMES, lost_timeout_s=1.0, clock=clock)
    tracker.frame('optitrack', reports)
    bodies = wait_for_bodies(tracker, resolved, sleep=clock.sleep)
    assert registered(bodies, resolved).to_dict()['blocks'] == TASK.to_dict()['blocks']
    # Without the pivot offsets the block lands 1-2 cm off: the offsets are what made it exact.
    unpivoted = BodyMap((BodyEntry('Block_3', 'c1'), BodyEntry('Long', 'i0'))).resolve(BLOCKS)
    snap = tracker.snapshot(unpivoted)
    c1 = next(b for b in snap.bodies if b.name == 'Block_3')
    assert np.linalg.norm(np.subtract(c1.position, TASK.blocks[1].position)) > 0.01


def test_unknown_bodies_are_skipped_and_reported_once_ignored_ones_silently():
    body_map = BodyMap((BodyEntry('Block_9', 'b9'),), frozenset({'tool'}))
    resolved = body_map.resolve(BLOCKS)
    extra = [RigidBodyPose('tool', (0, 0, 1), (0, 0, 0, 1)), RigidBodyPose('wand', (0, 1, 1), (0, 0, 0, 1)),
             RigidBodyPose('Block_9', (0, 2, 1), (0, 0, 0, 1))]
    clock = Clock()
    tracker = MocapTracker(MocapFrames('world', in_base_frame=True), clock=clock)
    tracker.frame('world', scene_to_bodies(TASK) + extra)
    warnings = []
    bodies = wait_for_bodies(tracker, resolved, sleep=clock.sleep, warn=warnings.append)
    assert registered(bodies, resolved).to_dict()['blocks'] == TASK.to_dict()['blocks']
    assert len(warnings) == 2 and "'wand' is not in the body map" in warnings[1]
    assert "'Block_9' is mapped to block 'b9', which the task does not have" in warnings[0]
    assert not any('tool' in w for w in warnings)
    wait_for_bodies(tracker, resolved, sleep=clock.sleep, warn=warnings.append)
    assert len(warnings) == 2                                    # once, not at every registration


def test_a_body_lost_for_some_frames_is_waited_for_and_registers_when_seen_again():
    resolved = BodyMap().resolve(BLOCKS)
    clock = Clock()
    tracker = MocapTracker(MocapFrames('world', in_base_frame=True), lost_timeout_s=1.0, clock=clock)
    full = scene_to_bodies(TASK)
    tracker.frame('world', full)
    clock.t += 0.1
    # c1 drops out of the frame, then i0 is reported with tracking_valid false (pose garbage).
    tracker.frame('world', [b for b in full if b.name != 'c1'])
    garbage = [b if b.name != 'i0' else RigidBodyPose('i0', (9.0, 9.0, 9.0), (0, 0, 0, 1), False) for b in full]
    tracker.frame('world', garbage[:1] + garbage[2:])
    snap = tracker.snapshot(resolved)
    assert set(snap.not_seen) == {'c1', 'i0'} and len(snap.bodies) == 3       # not seen, not removed

    def back_after(t0, frames):
        def on_sleep(t):
            if t - t0 >= 0.5:
                tracker.frame('world', frames)
        return on_sleep
    clock.on_sleep = back_after(clock.t, full)
    t0 = clock.t
    bodies = wait_for_bodies(tracker, resolved, sleep=clock.sleep)
    assert 0.5 <= clock.t - t0 < 0.6                              # it waited until they were seen again
    assert registered(bodies, resolved).to_dict()['blocks'] == TASK.to_dict()['blocks']


def test_a_body_lost_beyond_the_timeout_fails_naming_its_block():
    resolved = BodyMap((BodyEntry('Block_3', 'c1'),)).resolve(BLOCKS)
    clock = Clock()
    tracker = MocapTracker(MocapFrames('world', in_base_frame=True), lost_timeout_s=1.0, clock=clock)
    full = [b if b.name != 'c1' else RigidBodyPose('Block_3', b.position, b.quaternion)
            for b in scene_to_bodies(TASK)]
    tracker.frame('world', full)
    tracker.frame('world', full[:1] + full[2:])
    clock.on_sleep = lambda t: tracker.frame('world', full[:1] + full[2:])   # frames keep coming without c1
    with pytest.raises(RadError) as e:
        wait_for_bodies(tracker, resolved, timeout_s=5.0, sleep=clock.sleep)
    assert "motion capture lost block 'c1' (rigid body 'Block_3') not seen for 1.0" in str(e.value)
    assert "'c0'" not in str(e.value) and 'lost_timeout_s 1' in str(e.value)


def test_never_seen_and_silent_motion_capture_fail_with_their_reason():
    resolved = BodyMap().resolve(BLOCKS)
    clock = Clock()
    tracker = MocapTracker(MocapFrames('world', in_base_frame=True), lost_timeout_s=1.0, clock=clock)
    tracker.frame('world', scene_to_bodies(TASK)[:2])
    clock.on_sleep = lambda t: tracker.frame('world', scene_to_bodies(TASK)[:2])
    with pytest.raises(RadError, match="motion capture has not seen block 'i0' yet"):
        wait_for_bodies(tracker, resolved, timeout_s=0.5, sleep=clock.sleep)
    with pytest.raises(RadError, match="lost block 'i0' never seen"):
        wait_for_bodies(tracker, resolved, sleep=clock.sleep)
    silent = MocapTracker(MocapFrames('world', in_base_frame=True), lost_timeout_s=1.0, clock=clock)
    with pytest.raises(RadError, match='no motion capture since motion capture input started 1.0'):
        wait_for_bodies(silent, resolved, sleep=clock.sleep)


def test_a_frame_in_the_wrong_frame_is_refused_and_named_when_bodies_are_lost():
    resolved = BodyMap().resolve(BLOCKS)
    clock = Clock()
    tracker = MocapTracker(FRAMES, lost_timeout_s=1.0, clock=clock)
    with pytest.raises(RadError, match="/rigid_bodies is in frame 'world', expected 'optitrack'"):
        tracker.frame('world', scene_to_bodies(TASK), source='/rigid_bodies')
    assert tracker.tracks == {}                                     # nothing of it was taken
    clock.t += 1.5
    with pytest.raises(RadError, match="refused .*in frame 'world', expected 'optitrack'"):
        tracker.snapshot(resolved)
    with pytest.raises(RadError, match='reported twice in one frame'):
        tracker.frame('optitrack', scene_to_bodies(TASK) * 2)


def test_per_body_poses_are_seen_while_fresh():
    resolved = BodyMap().resolve(BLOCKS)
    clock = Clock()
    tracker = MocapTracker(MocapFrames('world', in_base_frame=True), lost_timeout_s=2.0, fresh_s=0.2, clock=clock)
    for b in scene_to_bodies(TASK):
        tracker.pose('world', b, source=f'/natnet_ros2/{b.name}/pose')
    assert not tracker.snapshot(resolved).not_seen
    clock.t += 0.1
    tracker.pose('world', scene_to_bodies(TASK)[0])
    clock.t += 0.15                                                # c1, i0: 0.25 s old, c0 0.15 s
    assert set(tracker.snapshot(resolved).not_seen) == {'c1', 'i0'}
    with pytest.raises(RadError, match="pose is in frame 'mocap', expected 'world'"):
        tracker.pose('mocap', scene_to_bodies(TASK)[0], source='pose')
    # A NaN pose (a driver's way of saying 'lost') is not seen, and keeps the last valid one.
    tracker.pose('world', RigidBodyPose('c0', (math.nan, 0, 0), (0, 0, 0, 1)))
    snap = tracker.snapshot(resolved)
    assert 'c0' in snap.not_seen and snap.bodies[0].position == TASK.blocks[0].position

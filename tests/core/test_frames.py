"""Frames that cannot be confused: motion capture whose frame cannot be told from the robot base frame, or
that has no calibration, is refused naming both frames and the fix, unless the cell says it reports in the
base frame; a body map names mocap4r2's numeric rigid bodies."""

import pytest
from rad_core.cell.mocap import RigidBodyPose
from rad_core.cell.mocap_input import BodyMap, FrameTransform, MocapFrames, MocapTracker
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import yaw_quaternion

CAL = FrameTransform((0.5, -0.2, 0.7), yaw_quaternion(90))


@pytest.mark.parametrize('frame_id, mocap_frame', [('world', ''), ('world', 'world'), ('base', ''),
                                                   ('base', 'base')])
def test_motion_capture_in_a_frame_equal_to_the_base_without_calibration_is_refused(frame_id, mocap_frame):
    frames = MocapFrames(frame_id, mocap_frame)
    why = frames.refusal
    assert why and f'frame_id {frame_id!r}' in why and 'mocap_frame' in why, why
    assert 'rad calibrate' in why and 'mocap_in_base_frame: true' in why, why
    assert not frames.calibrated
    with pytest.raises(RadError, match='raw motion-capture coordinates would pass as base coordinates'):
        frames.check(frame_id, '/rigid_bodies')
    # Every message is refused, and a registration then says why.
    tracker = MocapTracker(frames, lost_timeout_s=1.0, clock=lambda: 0.0)
    with pytest.raises(RadError, match='motion capture refused'):
        tracker.pose(frame_id, RigidBodyPose('b0', (0, 0, 0), (0, 0, 0, 1), True))


def test_a_frame_of_its_own_without_calibration_is_refused_naming_both_frames():
    why = MocapFrames('base', 'world').refusal                     # natnet_ros2 / vrpn_mocap's default frame
    assert "mocap_frame 'world'" in why and "frame_id 'base'" in why and 'identity' in why, why
    assert 'rad calibrate --hand-eye' in why


def test_said_explicitly_or_calibrated_motion_capture_is_taken():
    twin = MocapFrames('world', '', in_base_frame=True)
    assert not twin.refusal and not twin.calibrated and twin.expected_frame == 'world'
    twin.check('world', '/rigid_bodies')
    cell = MocapFrames('base', 'optitrack', CAL)
    assert not cell.refusal and cell.calibrated and cell.expected_frame == 'optitrack'
    cell.check('optitrack', '/rigid_bodies')
    # A driver frame named differently but said to be the base frame: taken, published as the identity.
    same = MocapFrames('base', 'world', in_base_frame=True)
    assert not same.refusal and same.calibrated and same.transform.is_identity


def test_contradictory_frame_settings_stop_the_configuration():
    with pytest.raises(RadError, match="mocap_in_base_frame is true .* calibration from mocap_frame 'optitrack'"):
        MocapFrames('base', 'optitrack', CAL, in_base_frame=True)
    with pytest.raises(RadError, match="mocap_frame equals frame_id 'base'"):
        MocapFrames('base', 'base', CAL)
    with pytest.raises(RadError, match='mocap_in_base_frame must be true or false'):
        MocapFrames('base', '', in_base_frame='yes')


def test_a_body_map_names_numeric_rigid_bodies_as_text():
    """mocap4r2's OptiTrack driver names rigid bodies by their Motive ID ('1', '2'); YAML reads 1 as a number."""
    import yaml
    doc = yaml.safe_load('bodies:\n  1: {block: b0}\n  2: {block: b1, pivot: [0.0, 0.0, 0.01]}\nignore: [7]\n')
    body_map = BodyMap.from_dict(doc)
    resolved = body_map.resolve({'b0': 'cube', 'b1': 'cube'})
    assert set(resolved.by_body) == {'1', '2'} and resolved.by_body['2'].block == 'b1'
    assert resolved.ignore == frozenset({'7'})

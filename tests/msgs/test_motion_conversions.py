"""Trajectory and motion-capture conversions on message types alone (no DDS)."""

import math
from types import SimpleNamespace

import pytest
from builtin_interfaces.msg import Time
from rad_ros.motion import (
    duration_to_s,
    pose_from_msg,
    rigid_bodies_msg,
    s_to_duration,
    trajectory_from_msg,
    trajectory_to_msg,
)

TRAJ = {'joint_names': ['panda_joint1', 'panda_joint2'],
        'points': [{'positions': [0.1, 0.2], 'velocities': [0.0, 0.5], 'time_from_start': 0.25},
                   {'positions': [0.3, 0.4], 'velocities': [0.0, 0.0], 'time_from_start': 1.999999999}]}


def test_trajectory_round_trip_keeps_nanoseconds():
    msg = trajectory_to_msg(TRAJ, frame_id='world')
    assert msg.points[0].time_from_start.sec == 0 and msg.points[0].time_from_start.nanosec == 250_000_000
    back = trajectory_from_msg(msg)
    assert back['joint_names'] == TRAJ['joint_names']
    for a, b in zip(back['points'], TRAJ['points']):
        assert a['positions'] == pytest.approx(b['positions'])
        assert a['time_from_start'] == pytest.approx(b['time_from_start'], abs=1e-9)


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_durations_refuse_negative_and_non_finite(bad):
    with pytest.raises(ValueError, match='time_from_start'):
        s_to_duration(bad)


def test_duration_rounding_carries_into_seconds():
    d = s_to_duration(0.9999999999)
    assert (d.sec, d.nanosec) == (1, 0) and duration_to_s(d) == 1.0


def test_rigid_bodies_message_like_mocap4r2():
    bodies = [SimpleNamespace(name='block_b0', position=[0.4, -0.2, 0.025], quaternion=[0, 0, 0.7071068, 0.7071068],
                              tracking_valid=True)]
    msg = rigid_bodies_msg(bodies, 17, stamp=Time(sec=5), frame_id='world')
    assert msg.frame_number == 17 and msg.header.frame_id == 'world' and msg.header.stamp.sec == 5
    assert msg.rigidbodies[0].rigid_body_name == 'block_b0'
    pos, quat = pose_from_msg(msg.rigidbodies[0].pose)
    assert pos == pytest.approx([0.4, -0.2, 0.025]) and quat[3] == pytest.approx(0.7071068)


def test_blocks_moved_aside_round_trip_and_mismatched_lengths_are_refused():
    from rad_core.domain.errors import RadError
    from rad_ros.motion import moved_aside_from_msgs, moved_aside_to_msgs
    moves = [{'block': 'b1', 'position': [0.35, 0.22, 0.02], 'yaw': 270},
             {'block': 'b7', 'position': [0.5, -0.18, 0.025], 'yaw': 0}]
    blocks, poses = moved_aside_to_msgs(moves)
    assert blocks == ['b1', 'b7'] and poses[0].position.y == pytest.approx(0.22)
    assert moved_aside_from_msgs(blocks, poses) == moves
    assert moved_aside_to_msgs([]) == ([], [])
    with pytest.raises(RadError, match='2 moved-aside blocks but 1 poses'):
        moved_aside_from_msgs(blocks, poses[:1])

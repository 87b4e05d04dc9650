"""rad_msgs/Sequence conversions, on message types alone: no rclpy.init, no DDS."""

import math

import pytest
from rad_core.allocation import solve
from rad_core.domain.errors import RadError
from rad_core.gamp.action import SceneAction
from rad_core.sequencing.decide.sequencer import Ranking, Sequencer, SequencerConfig
from rad_msgs.srv import Sequence
from rad_ros.sequencer_msgs import (
    action_from_msg,
    action_to_msg,
    fill_sequence_response,
    ranking_from_response,
    sequence_inputs,
    sequence_request,
)

from scenes import scene


def test_an_action_round_trips_through_the_message():
    action = SceneAction('b3', 2, 'front', (1, 0, 2), 3)
    msg = action_to_msg(action)
    assert (msg.block_id, msg.unit, msg.target, msg.cell.k, msg.rotation) == ('b3', 2, 'front', 2, 3)
    assert action_from_msg(msg) == action


def test_a_request_carries_scene_allocation_start_and_limit():
    s = scene()
    placements = solve(s).placements
    request = sequence_request(s, placements, start=[0.0] * 9, max_actions=3)
    back, got, start, limit = sequence_inputs(request)
    assert back.to_dict() == s.to_dict() and list(got) == list(placements)
    assert start == [0.0] * 9 and limit == 3
    assert sequence_inputs(sequence_request(s, placements))[2] is None   # empty = home


def test_a_request_without_a_valid_scene_is_a_rad_error():
    with pytest.raises(RadError, match='not valid JSON'):
        sequence_inputs(Sequence.Request(scene_json='{"format": '))
    with pytest.raises(RadError, match='no scene given'):
        sequence_inputs(Sequence.Request())


def test_a_ranking_round_trips_through_the_response():
    s = scene()
    placements = solve(s).placements
    ranking = Sequencer(SequencerConfig(policy='heur')).rank(s, placements)
    assert ranking.actions
    response = fill_sequence_response(Sequence.Response(), ranking, 'heur')
    assert response.success and response.policy == 'heur'
    back = ranking_from_response(response)
    assert back.actions == ranking.actions and back.values == ranking.values
    assert back.terminate is False and back.timings['sequencing'] == ranking.timings['sequencing']


def test_termination_infinite_values_and_failures():
    ranking = Ranking([SceneAction('c0', 0, 'front', (0, 0, 0), 0)], [-math.inf], False, '', {})
    assert ranking_from_response(fill_sequence_response(Sequence.Response(), ranking, 'heur')).values == [-math.inf]
    stop = fill_sequence_response(Sequence.Response(), Ranking([], [], True, 'every allocated pose is built', {}),
                                  'milp-dqn')
    back = ranking_from_response(stop)
    assert back.terminate and back.actions == [] and back.reason == 'every allocated pose is built'
    # How many of the actions, at the end, are valued below stopping (a verified caller's last resort).
    actions = [SceneAction('c0', 0, 'front', (0, 0, 0), 0), SceneAction('c1', 0, 'front', (1, 0, 0), 0)]
    shy = fill_sequence_response(Sequence.Response(), Ranking(actions, [-1.0, -2.0], True, 'shy', {}, fallbacks=2),
                                 'milp-dqn')
    assert shy.fallbacks == 2 and ranking_from_response(shy).fallbacks == 2
    shy.fallbacks = 3
    with pytest.raises(RadError, match='3 fallbacks among 2 actions'):
        ranking_from_response(shy)
    with pytest.raises(RadError, match='sequencer: allocation names unknown target region'):
        ranking_from_response(Sequence.Response(success=False, reason="allocation names unknown target region 'x'"))

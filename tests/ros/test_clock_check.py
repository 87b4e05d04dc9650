"""The joint-state clock check (`rad_planner.assembly_node.stamp_problem`): a stamp a little off this node's
clock is taken (clock_skew_tolerance_s); further off, the reason says whether it looks like another clock
(simulated time, unsynchronised computers) and the fix."""

import pytest
from rad_planner.assembly_node import stamp_problem

NOW = 1_780_000_000.0          # wall-clock time, 2026
STALE, SKEW = 2.0, 0.5


def problem(stamp, now=NOW, sim_time=False):
    return stamp_problem('/joint_states', stamp, now, STALE, SKEW, sim_time, arrived_s=0.01)


@pytest.mark.parametrize('offset', [0.0, -0.4, 2.4, 1.0])
def test_stamps_within_the_stale_bound_and_the_tolerated_skew_are_taken(offset):
    assert problem(NOW - offset) == ''


def test_a_robot_clock_a_little_behind_or_ahead_is_refused_with_the_limit_and_the_fix():
    behind = problem(NOW - 10.0)
    assert 'is stale' in behind and '10.0 s old' in behind and 'clock_skew_tolerance_s 0.5' in behind, behind
    assert 'chrony' in behind and 'PTP' in behind and 'use_sim_time' in behind, behind
    ahead = problem(NOW + 3.0)
    assert '3.0 s ahead of this node' in ahead and 'clock_skew_tolerance_s 0.5' in ahead and 'chrony' in ahead


@pytest.mark.parametrize('offset, span', [(600.0, '10.0 min'), (-3 * 86400.0, '3.0 days'),
                                          (3 * 365.25 * 86400, '3.0 years')])
def test_stamps_minutes_to_years_off_are_another_clock(offset, span):
    why = problem(NOW - offset)
    assert f'stamped {span}' in why and 'another clock' in why and 'chrony' in why, why


def test_simulated_time_against_the_wall_clock_is_named_either_way():
    why = problem(12.5)                         # a simulator's /clock, this node on the wall clock
    assert 'looks like simulated time' in why and 'use_sim_time:=true' in why, why
    why = problem(NOW, now=40.0, sim_time=True)    # this node on /clock, the robot stamping wall time
    assert 'wall-clock time' in why and 'use_sim_time' in why, why
    assert problem(39.9, now=40.0, sim_time=True) == ''


def test_an_unstamped_message_is_named():
    assert 'carries no stamp' in problem(0.0)

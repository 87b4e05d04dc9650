"""parse_trajectory's all-at-once path (`_parse_regular`) against the point-by-point parse: the
same points out of every trajectory, the same refusal (code and words) of every bad one."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from rad_core.cell import trajectory as tr
from rad_core.cell.robot_model import FR3, PANDA, PLANNING_LOWER, PLANNING_UPPER
from rad_core.cell.trajectory import Trajectory, TrajectoryPoint, TrajectoryRejected, parse_trajectory
from rad_core.gamp.trajectory import retime


def _outcome(doc, model):
    try:
        return 'ok', parse_trajectory(doc, model)
    except TrajectoryRejected as e:
        return 'refused', (e.code, str(e))


def _both(doc, model, monkeypatch):
    fast = _outcome(copy.deepcopy(doc), model)
    with monkeypatch.context() as m:
        m.setattr(tr, '_parse_regular', lambda *a, **k: None)
        slow = _outcome(copy.deepcopy(doc), model)
    return fast, slow


def _variants(traj: Trajectory, rng: np.random.Generator):
    """The trajectory as planners send it, in dict form, with joints shuffled, without accelerations
    or velocities, and broken in the ways a goal can be."""
    doc = traj.to_dict()
    yield traj
    yield doc
    names = list(doc['joint_names'])
    perm = rng.permutation(len(names))
    shuffled = {'joint_names': [names[i] for i in perm],
                'points': [{**p, 'positions': [p['positions'][i] for i in perm],
                            'velocities': [p['velocities'][i] for i in perm],
                            'accelerations': [p['accelerations'][i] for i in perm]} for p in doc['points']]}
    yield shuffled
    yield {**doc, 'points': [{**p, 'accelerations': []} for p in doc['points']]}
    yield {**doc, 'points': [{'positions': p['positions'], 'time_from_start': p['time_from_start']}
                             for p in doc['points']]}
    k = int(rng.integers(len(doc['points'])))
    j = int(rng.integers(7))

    def broken(change):
        d = copy.deepcopy(doc)
        change(d['points'][k])
        return d
    yield broken(lambda p: p['positions'].__setitem__(j, math.nan))
    yield broken(lambda p: p['velocities'].__setitem__(j, math.inf))
    yield broken(lambda p: p['positions'].__setitem__(j, 9.0))                       # outside the joint range
    yield broken(lambda p: p['positions'].__setitem__(j, PANDA.q_max[j] + 5e-4))     # clipped: planner rounding
    yield broken(lambda p: p['positions'].pop())                                       # six positions
    yield broken(lambda p: p.__setitem__('velocities', []))                           # velocities at some points only
    yield broken(lambda p: p.__setitem__('accelerations', p['accelerations'][:3]))
    yield broken(lambda p: p.__setitem__('time_from_start', -1.0 if k == 0 else 0.0))
    yield broken(lambda p: p.__setitem__('time_from_start', True))
    yield broken(lambda p: p.__setitem__('time_from_start', np.float64(p['time_from_start'])))
    yield broken(lambda p: p.__setitem__('time_from_start', 4000.0))
    yield broken(lambda p: p.__setitem__('positions', 'abc'))
    yield broken(lambda p: p.__setitem__('positions', [str(v) for v in p['positions']]))
    yield broken(lambda p: p.pop('time_from_start'))


@pytest.mark.parametrize('model', [PANDA, FR3], ids=['panda', 'fr3'])
def test_all_at_once_parse_matches_the_point_by_point_parse(model, monkeypatch):
    rng = np.random.default_rng(5)
    seen = {'ok': 0, 'refused': 0}
    for _ in range(12):
        path = [rng.uniform(PLANNING_LOWER, PLANNING_UPPER) for _ in range(int(rng.integers(2, 5)))]
        for doc in _variants(retime(path, model, 1.0), rng):
            fast, slow = _both(doc, model, monkeypatch)
            assert fast[0] == slow[0], (fast, slow)
            seen[fast[0]] += 1
            if fast[0] == 'refused':
                assert fast[1] == slow[1]
            else:
                assert fast[1].joint_names == slow[1].joint_names
                assert [p.to_dict() for p in fast[1].points] == [p.to_dict() for p in slow[1].points]
                assert all(type(v) is float for p in fast[1].points for v in p.positions + p.velocities)
    assert seen['ok'] > 50 and seen['refused'] > 50


def test_the_all_at_once_parse_takes_what_planners_send():
    """A retimed trajectory is parsed all at once (not handed to the point-by-point parse)."""
    lo, hi = np.asarray(PANDA.q_min), np.asarray(PANDA.q_max)
    traj = retime([lo + 0.25 * (hi - lo), lo + 0.75 * (hi - lo)], PANDA, 1.0)
    order = list(range(7))
    points = tr._parse_regular(traj.points, 7, order, np.asarray(PANDA.q_min), np.asarray(PANDA.q_max), 1e-3)
    assert points is not None and len(points) == len(traj.points)
    assert tr._parse_regular(traj.to_dict()['points'], 7, order, np.asarray(PANDA.q_min),
                             np.asarray(PANDA.q_max), 1e-3) is not None
    assert [TrajectoryPoint(**p.to_dict()) for p in points] == points

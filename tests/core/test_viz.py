"""rad_core.view.viz: the visualizer's geometry and plan parsing without ROS, and what it logs to an .rrd."""

import json
import subprocess

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.placements import Placement
from rad_core.domain.colours import type_colour
from rad_core.domain.errors import RadError
from rad_core.domain.transforms import yaw_quaternion
from rad_core.sequencing.planning.plan import PlanStep
from rad_core.view import viz

from scenes import U, scene


def test_block_shape_is_the_type_in_its_own_frame_with_its_colour():
    s = scene()
    shape = viz.block_shape(s, 'L3_up')
    assert np.allclose(shape.centers, U * np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1]]))
    assert np.allclose(shape.half_sizes, U * 0.94 / 2)
    assert tuple(shape.colors[0]) == viz.rgba8(type_colour('L3_up'))
    assert viz.rgba8(type_colour('L3_up')) != viz.rgba8(type_colour('cube'))


def test_block_boxes_match_the_scene_and_follow_a_given_pose():
    s = scene()
    boxes = viz.block_boxes(s)
    assert set(boxes) == {'c0', 'c1', 'i0'}
    for block in s.blocks:
        assert np.allclose(boxes[block.id].centers, s.unit_positions(block))   # yaw 90 for i0 included
    moved = viz.block_boxes(s, {'i0': ((0.1, 0.2, U / 2), yaw_quaternion(0))})
    assert np.allclose(moved['i0'].centers, [[0.1, 0.2, U / 2], [0.1 + U, 0.2, U / 2]])
    assert np.allclose(moved['c0'].centers, boxes['c0'].centers)


def test_cell_points_split_target_and_other_cells_at_region_origin_plus_unit_times_index():
    s = scene()
    target, other = viz.cell_points(s)['front']
    region = s.target('front')
    assert len(target) == 4 and len(other) == 3 * 1 * 2 - 4
    assert any(np.allclose(t, np.asarray(region.origin) + U * np.array([2, 0, 0])) for t in target)
    assert any(np.allclose(o, np.asarray(region.origin) + U * np.array([1, 0, 1])) for o in other)
    pink, green = viz.cell_boxes(s)['front']
    assert pink.colors[0][:3].tolist() != green.colors[0][:3].tolist()
    assert pink.half_sizes[0, 0] > green.half_sizes[0, 0]


def test_placement_boxes_are_translucent_ghosts_in_region_cells_and_bad_regions_are_named():
    s = scene()
    ghost = viz.placement_boxes(s, Placement('I2', 'front', 0, ((0, 0, 0), (1, 0, 0))))
    assert np.allclose(ghost.centers, [s.target('front').origin, np.asarray(s.target('front').origin) + [U, 0, 0]])
    assert 0 < ghost.colors[0][3] < 255
    with pytest.raises(RadError, match="target region 'back'"):
        viz.placement_boxes(s, Placement('I2', 'back', 0, ((0, 0, 0),)))


def test_table_holds_the_scene_with_its_top_at_zero():
    t = viz.table_box(scene())
    (c,), (h,) = t.centers, t.half_sizes
    assert c[2] + h[2] == pytest.approx(0.0)
    far = scene(blocks=[{'id': 'f', 'type': 'cube', 'position': [1.9, 0.0, U / 2], 'yaw': 0}])
    (c,), (h,) = viz.table_box(far).centers, viz.table_box(far).half_sizes
    assert c[0] + h[0] > 1.9


def _plan_doc(s):
    alloc = solve(s, AllocationParams(time_limit_s=5.0, num_workers=1))
    steps = [{'block': f'b{i}', 'type': p.type, 'target': p.target, 'yaw': p.yaw,
              'cells': [list(c) for c in p.cells], 'unit': 0} for i, p in enumerate(alloc.placements)]
    return {'allocation': alloc.to_dict(), 'steps': steps, 'timings': {'allocate': 0.01, 'sequence': 0.2},
            'predicted_coverage': 0.75}


def test_parse_plan_reads_allocation_steps_timings_coverage():
    s = scene()
    doc = _plan_doc(s)
    plan = viz.parse_plan(json.dumps(doc))
    assert plan.allocation is not None and len(plan.allocation.placements) == len(doc['steps']) > 0
    assert plan.steps[0].cells == doc['steps'][0]['cells'] and plan.steps[0].motion is None
    assert plan.timings == {'allocate': 0.01, 'sequence': 0.2} and plan.predicted_coverage == 0.75
    text = viz.plan_summary(plan)
    assert 'allocate' in text and '0.750' in text and plan.allocation.status in text
    empty = viz.parse_plan('{}')
    assert empty.allocation is None and empty.steps == () and empty.timings == {}


def test_re_allocations_in_plan_json_are_read_and_shown_in_the_summary():
    from rad_core.sequencing.planning.reallocation import Reallocation
    event = Reallocation(2, 'no feasible next action (1 tried): b3: placement: hand hits block b1',
                         [{'type': 'cube', 'target': 'front', 'cells': [[1, 0, 0]],
                           'reason': 'b3: hand hits block b1'}],
                         'OPTIMAL', 3.0, 3.0, 0.02, [Placement('I2', 'front', 0, ((1, 0, 0), (2, 0, 0)))], True,
                         [{'block': 'b7', 'type': 'I3', 'reason': 'grasp: all 3 grasps blocked'}])
    plan = viz.parse_plan(json.dumps({'reallocations': [event.to_dict()]}))
    assert plan.reallocations[0]['step'] == 2
    text = viz.plan_summary(plan)
    assert '1 re-allocations' in text and 'after step 2' in text and 'hand hits block b1' in text
    assert '1 new poses (OPTIMAL)' in text
    assert '1 blocks that cannot be picked (b7: grasp: all 3 grasps blocked)' in text
    with pytest.raises(RadError, match='reallocations must be a list'):
        viz.parse_plan(json.dumps({'reallocations': [{'step': 'two'}]}))


def test_plan_json_steps_are_read_back_as_the_planners_plan_steps():
    """One PlanStep: what sequencing.planning.plan makes and plan_json carries is what viz reads back."""
    step = PlanStep('b0', 'L3_up', 'front', 90, [[0, 0, 0], [0, 1, 0]], 2, [0, 0, 0], 1, (1, 180, 1),
                    [0.4, 0.1, 0.025], {'trajectories': [{'joint_names': ['j'], 'points': []}],
                                        'gripper': [{'before': 1, 'action': 'release', 'position': 0.03,
                                                     'max_effort': 20.0}]})
    assert PlanStep.from_dict(json.loads(json.dumps(step.to_dict()))) == step
    # rad_ros.plan_msgs.plan_json leaves the motion out
    published = {k: v for k, v in step.to_dict().items() if k not in ('trajectories', 'gripper')}
    (read,) = viz.parse_plan(json.dumps({'steps': [published]})).steps
    assert isinstance(read, PlanStep) and read.motion is None
    assert read.to_dict() == {**step.to_dict(), 'trajectories': [], 'gripper': []}
    with pytest.raises(RadError, match=r'steps\[0\]: not a plan step'):
        viz.parse_plan(json.dumps({'steps': [{**published, 'grasp': [1, 2]}]}))


@pytest.mark.parametrize('text, expected', [
    ('not json', 'not valid JSON'),
    ('[]', 'JSON object'),
    ('{"steps": {}}', 'steps must be a list'),
    ('{"steps": [{"block": "b"}]}', 'steps[0] lacks type, target, yaw, cells'),
    ('{"steps": [{"block": "b", "type": "I2", "target": "t", "yaw": 0, "cells": [[0, 0]]}]}', 'steps[0]: cells'),
    ('{"timings": {"a": "fast"}}', 'timings'),
    ('{"predicted_coverage": NaN}', 'predicted_coverage'),
    ('{"allocation": {"status": "OPTIMAL"}}', 'rad-allocation/1'),
])
def test_parse_plan_names_what_is_wrong(text, expected):
    with pytest.raises(RadError) as e:
        viz.parse_plan(text)
    assert expected in str(e.value)


def _entities(path) -> set[str]:
    """Entity paths of an .rrd, from `rerun rrd stats` ("Num chunks per entity")."""
    def rrd(*args):
        return subprocess.run(['rerun', 'rrd', *args, str(path)], capture_output=True, text=True, timeout=60,
                              check=False)
    verify = rrd('verify')
    assert verify.returncode == 0, verify.stderr
    out = rrd('stats')
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split('Num chunks per entity')[1].split('\n\n')[0].splitlines()
    return {line.rsplit(':', 1)[0] for line in lines if line.startswith('/')}


def test_logging_a_scene_plan_and_robot_writes_every_entity(tmp_path):
    import rerun as rr
    s = scene()
    plan = viz.parse_plan(json.dumps(_plan_doc(s)))
    bad = viz.PlanDoc(None, (viz.PlanStep('x', 'I2', 'nowhere', 0, ((0, 0, 0),)),))
    path = tmp_path / 'rec.rrd'
    rec = rr.RecordingStream('rad_test')
    rec.save(path, default_blueprint=viz.default_blueprint())
    robot = viz.PandaModel()
    viz.log_world(rec)
    robot.log_model(rec)
    viz.set_ros_time(rec, 100.0)
    viz.log_scene(rec, s)
    assert robot.log_joints(rec, ['panda_joint1', 'panda_joint2', 'elbow', 'panda_finger_joint1'],
                            [0.1, float('nan'), 0.0, 0.02]) == 2
    assert viz.log_block_poses(rec, [('c0', (0.4, -0.2, U / 2), (0, 0, 0, 1)), ('ghost', (0, 0, 0), (0, 0, 0, 1))],
                               {b.id for b in s.blocks}) == 1
    assert viz.log_plan(rec, s, plan, 101.0) == []
    assert viz.log_plan(rec, s, bad, 102.0) == [
        "steps[0]: placement of a I2 names target region 'nowhere', which the scene does not have"]
    rec.flush()
    rec.disconnect()
    entities = _entities(path)
    expected = {'/world/table', '/world/blocks/c0', '/world/blocks/i0', '/world/targets/front/target_cells',
                '/world/targets/front/other_cells', '/world/plan/allocation/0', '/world/plan/step',
                '/world/plan/done', '/plan/step_text', '/plan/timings/allocate', '/plan/summary',
                '/plan/predicted_coverage', '/world/panda/base', '/world/panda/joints/panda_joint1',
                '/world/panda/joints/panda_finger_joint1', '/world/panda/tf_static'}
    expected |= {f'/world/panda/visual_geometries/{link}/visual_0' for link in
                 ('panda_link0', 'panda_link1', 'panda_link7', 'panda_hand', 'panda_leftfinger')}
    assert expected <= entities, sorted(expected - entities)
    assert '/world/panda/joints/elbow' not in entities and '/world/blocks/ghost' not in entities
    assert path.stat().st_size > 1_000_000    # the meshes are in it, not just their names


def test_a_new_scene_or_plan_clears_only_what_it_does_not_log_again(tmp_path):
    """Rerun hides data logged at the same time as a Clear of it: clear only the leftovers."""
    import rerun as rr
    s = scene()
    fewer = scene(blocks=[{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0}])
    plan = viz.parse_plan(json.dumps(_plan_doc(s)))
    shorter = viz.PlanDoc(None, plan.steps[:1])
    path = tmp_path / 'rec.rrd'
    rec = rr.RecordingStream('rad_test')
    rec.save(path)
    viz.set_ros_time(rec, 1.0)
    viz.log_scene(rec, s)
    viz.log_plan(rec, s, plan, 1.5)
    viz.set_ros_time(rec, 2.0)
    viz.log_scene(rec, fewer, previous=s)
    viz.log_plan(rec, fewer, shorter, 2.5, previous=plan)
    rec.flush()
    rec.disconnect()

    def cleared(entity):
        out = subprocess.run(['rerun', 'rrd', 'print', '--entity', entity, str(path)], capture_output=True,
                             text=True, timeout=60, check=True).stdout
        assert 'Chunk(' in out, entity
        return 'Clear:' in out
    assert cleared('/world/blocks/c1') and cleared('/world/blocks/i0')
    assert not cleared('/world/blocks/c0') and not cleared('/world/targets/front/target_cells')
    assert cleared('/world/plan/allocation/0')          # the shorter plan has no allocation at all


def test_a_step_that_moves_blocks_aside_says_so():
    step = {'block': 'b4', 'type': 'cube', 'target': 'front', 'yaw': 0, 'cells': [[0, 0, 0]],
            'moved_aside': [{'block': 'b1', 'position': [0.35, 0.22, 0.02], 'yaw': 270}]}
    plan = viz.parse_plan(json.dumps({'steps': [step]}))
    assert plan.steps[0].moved_aside[0]['block'] == 'b1'
    assert '(first moves b1 aside)' in viz.step_text(0, plan.steps[0])
    assert '1. b4 (cube) -> front yaw 0 (first moves b1 aside)' in viz.plan_summary(plan)


def test_anytime_points_are_read_shown_and_bad_ones_refused():
    doc = {'anytime': [{'t': 0.8, 'coverage': 0.83, 'plan': 'scorer'}, {'t': 2.9, 'coverage': 0.9, 'plan': 'search'}]}
    plan = viz.parse_plan(json.dumps(doc))
    assert [a['coverage'] for a in plan.anytime] == [0.83, 0.9]
    text = viz.plan_summary(plan)
    assert 'scorer plan best at 0.80 s, coverage 0.830' in text and 'search plan best at 2.90 s' in text
    with pytest.raises(RadError, match='anytime must be a list'):
        viz.parse_plan(json.dumps({'anytime': [{'t': 'soon', 'coverage': 1.0}]}))


def test_the_vacuum_gripper_is_drawn_in_the_hands_place(tmp_path):
    import rerun as rr
    path = tmp_path / 'suction.rrd'
    rec = rr.RecordingStream('rad_test')
    rec.save(path)
    viz.PandaModel(effector='suction').log_model(rec)
    rec.flush()
    rec.disconnect()
    entities = _entities(path)
    assert '/world/panda/visual_geometries/panda_hand/visual_0' in entities       # the pump housing
    assert not any('finger' in e and 'visual_geometries' in e for e in entities)   # no fingers drawn
    with pytest.raises(RadError, match='effector'):
        viz.PandaModel(effector='magnet')

"""The /allocate service of the installed allocation_node, over real DDS on loopback."""

import json
import math
import time

import pytest
from rad_core.allocation import validate_allocation
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from ros_harness import call_service, ros_args, wait_for_service

from scenes import U, doc


@pytest.fixture
def allocation(node_process, ros_node):
    from rad_msgs.srv import Allocate
    proc = node_process('rad_planner', 'allocation_node', *ros_args({'time_limit_s': 5.0, 'seed': 3}))
    client = wait_for_service(ros_node, Allocate, 'allocate', timeout=20.0)

    def call(scene_json='', scene_msg=None, time_limit_s=0.0):
        request = Allocate.Request(scene_json=scene_json, time_limit_s=time_limit_s)
        if scene_msg is not None:
            request.scene = scene_msg
        return call_service(ros_node, client, request, timeout=30.0)

    yield proc, call
    assert proc.stop() == 0, proc.output_tail()


def test_allocates_from_json_and_from_message_alike(allocation):
    from rad_ros.conversions import allocation_from_response, scene_to_msg
    proc, call = allocation
    scene = generate_scene(GeneratorConfig(grid=5), 7)
    by_json = call(scene.dumps())
    assert by_json.success, by_json.reason
    assert by_json.status == 'OPTIMAL' and by_json.objective == scene.num_target_cells
    assert by_json.bound == by_json.objective and by_json.solve_time_s > 0
    by_msg = call(scene_msg=scene_to_msg(scene))
    assert by_msg.success and by_msg.objective == by_json.objective
    assert validate_allocation(scene, allocation_from_response(by_msg)) == []


def _bad_cases():
    big = doc(targets=[{'name': 't', 'origin': [0.3, 0.3, U / 2], 'size': [24, 24, 24], 'filled': [[0, 0, 0]]}])
    overlapping = doc()
    overlapping['blocks'][1]['position'] = overlapping['blocks'][0]['position']
    return {
        'malformed JSON': ('{"format": "rad-scene/1", "unit"', 'not valid JSON'),
        'unknown block type': (json.dumps(doc()).replace('"type": "I2"', '"type": "Z7"'), 'unknown block type'),
        'non-integer cell': (json.dumps(doc()).replace('[2, 0, 0]', '[2.5, 0, 0]'), 'expected an integer'),
        'cell outside the box': (json.dumps(doc()).replace('[2, 0, 0]', '[7, 0, 0]'), 'outside the box'),
        'yaw not a multiple of 90': (json.dumps(doc()).replace('"yaw": 90', '"yaw": 30'), 'not a multiple of 90'),
        'overlapping blocks': (json.dumps(overlapping), 'overlaps block'),
        'empty target': (json.dumps(doc()).replace(
            '"filled": [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 1]]', '"filled": []'), 'is empty'),
        'NaN': (json.dumps(doc()).replace('0.45,', 'NaN,'), 'must be finite'),
        'Infinity': (json.dumps(doc()).replace('0.45,', 'Infinity,'), 'must be finite'),
        'huge grid': (json.dumps(big), 'exceed the limit'),
        'no scene': ('', 'no scene given'),
    }


def test_every_bad_input_gets_a_reason_and_the_node_keeps_serving(allocation):
    proc, call = allocation
    good = Scene.from_dict(doc()).dumps()
    for name, (text, expected) in _bad_cases().items():
        t0 = time.monotonic()
        response = call(text)
        assert not response.success, name
        assert expected in response.reason, (name, response.reason)
        assert response.status == 'INVALID_REQUEST' and not response.placements
        assert time.monotonic() - t0 < 5.0, f'{name} took too long'
        assert proc.is_running(), proc.output_tail()
        assert call(good).success, f'node stopped serving after {name}'


def test_message_and_json_together_and_bad_time_limits_are_refused(allocation):
    from rad_ros.conversions import scene_to_msg
    proc, call = allocation
    scene = Scene.from_dict(doc())
    assert 'not both' in call(scene.dumps(), scene_msg=scene_to_msg(scene)).reason
    for bad in (-1.0, math.nan, math.inf):
        response = call(scene.dumps(), time_limit_s=bad)
        assert not response.success and 'time_limit_s' in response.reason
    bad_msg = scene_to_msg(scene)
    bad_msg.blocks[0].position.z = math.nan
    assert 'must be finite' in call(scene_msg=bad_msg).reason
    assert call(scene.dumps(), time_limit_s=1.0).success


def test_a_bad_default_from_the_parameters_stops_the_node_with_the_reason(node_process):
    proc = node_process('rad_planner', 'allocation_node', *ros_args({'time_limit_s': -2.0}))
    assert proc.wait(timeout=30.0) == 1
    assert 'cannot start: time_limit_s must be a positive number of seconds, got -2.0' in proc.stderr(), \
        proc.output_tail()


def test_ros2run_script_starts_the_node_with_a_params_file(process, ros_node, tmp_path):
    from rad_msgs.srv import Allocate
    from ros_harness import REPO_ROOT
    params = REPO_ROOT / 'ros_ws/install/rad_planner/share/rad_planner/config/planner.yaml'
    assert params.is_file()
    proc = process([str(REPO_ROOT / 'scripts' / 'ros2run'), 'rad_planner', 'allocation_node',
                    '--ros-args', '--params-file', str(params)], name='ros2run')
    client = wait_for_service(ros_node, Allocate, 'allocate', timeout=20.0)
    response = call_service(ros_node, client, Allocate.Request(scene_json=Scene.from_dict(doc()).dumps()),
                            timeout=30.0)
    assert response.success, response.reason
    assert proc.stop() == 0, proc.output_tail()


def test_a_request_sets_support_prefer_and_no_goods(node_process, ros_node):
    from rad_core.allocation import AllocationParams, Placement, solve
    from rad_msgs.srv import Allocate
    from rad_ros.conversions import placement_from_msg, placement_to_msg
    proc = node_process('rad_planner', 'allocation_node')
    client = wait_for_service(ros_node, Allocate, 'allocate', timeout=20.0)
    scene = generate_scene(GeneratorConfig(grid=4), 2)

    def call(**kw):
        exclude = kw.pop('exclude', [])
        request = Allocate.Request(scene_json=scene.dumps(), **kw)
        request.exclude = [placement_to_msg(p) for p in exclude]
        return call_service(ros_node, client, request, timeout=30.0)

    stable = call(support='stable', prefer='fewer')
    assert stable.success, stable.reason
    local = solve(scene, AllocationParams(support='stable', prefer='fewer'))
    assert [placement_from_msg(p) for p in stable.placements] == list(local.placements)
    banned = placement_from_msg(stable.placements[0])
    again = call(support='stable', exclude=[banned])
    assert again.success and banned not in [placement_from_msg(p) for p in again.placements]
    for kw, words in (({'support': 'sturdy'}, 'support must be one of'),
                      ({'prefer': 'fewer'}, "needs support='stable'"),
                      ({'exclude': [Placement('cube', 'nowhere', 0, ((0, 0, 0),))]}, "'nowhere'")):
        bad = call(**kw)
        assert not bad.success and bad.status == 'INVALID_REQUEST' and words in bad.reason, bad.reason
    assert call().success      # still serving, the paper's MILP by default
    assert proc.stop() == 0, proc.output_tail()

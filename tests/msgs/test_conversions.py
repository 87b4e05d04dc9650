"""Message conversions, on message types alone: no rclpy.init, no DDS."""

import math

import pytest
from rad_core.allocation import solve
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_msgs.msg import Scene as SceneMsg
from rad_msgs.srv import Allocate
from rad_ros.conversions import (
    allocation_from_response,
    fill_allocation_response,
    scene_from_msg,
    scene_from_request,
    scene_to_msg,
)

from scenes import scene


def test_scene_round_trips_through_the_message():
    s = generate_scene(GeneratorConfig(grid=5), 4)
    msg = scene_to_msg(s, frame_id='panda_link0')
    assert msg.header.frame_id == 'panda_link0'
    assert list(msg.targets[0].size) == [5, 1, 5]
    assert scene_from_msg(msg).to_dict() == s.to_dict()


def test_allocation_round_trips_through_the_response():
    s = scene()
    result = solve(s)
    response = fill_allocation_response(Allocate.Response(), result)
    assert response.success and response.reason == '' and response.status == 'OPTIMAL'
    back = allocation_from_response(response)
    assert back.placements == result.placements and back.objective == result.objective


def test_bad_message_gets_the_json_field_names():
    msg = scene_to_msg(scene())
    msg.blocks[1].yaw_deg = 45
    with pytest.raises(RadError, match=r'blocks\[1\].yaw: 45 is not a multiple of 90'):
        scene_from_msg(msg)
    msg = scene_to_msg(scene())
    msg.blocks[0].position.y = math.nan
    with pytest.raises(RadError, match=r'blocks\[0\].position\[1\]: must be finite'):
        scene_from_msg(msg)
    msg = scene_to_msg(scene())
    msg.block_types.append(msg.block_types[0])
    with pytest.raises(RadError, match='appears twice'):
        scene_from_msg(msg)


def test_request_takes_message_or_json_but_not_both_or_neither():
    s = scene()
    assert scene_from_request(scene_to_msg(s), '').to_dict() == s.to_dict()
    assert scene_from_request(SceneMsg(), s.dumps()).to_dict() == s.to_dict()
    with pytest.raises(RadError, match='not both'):
        scene_from_request(scene_to_msg(s), s.dumps())
    with pytest.raises(RadError, match='no scene given'):
        scene_from_request(SceneMsg(), '  ')
    with pytest.raises(RadError, match='bytes, more than the limit'):
        scene_from_request(SceneMsg(), ' ' * (11 * 1024 * 1024) + '{}')


def test_scene_clearance_travels_in_the_message():
    s = generate_scene(GeneratorConfig(grid=3, clearance=0.2), 1)
    flush = generate_scene(GeneratorConfig(grid=3), 1)
    assert scene_to_msg(s).clearance == pytest.approx(0.2)
    assert scene_from_msg(scene_to_msg(s)).to_dict() == s.to_dict()
    assert scene_from_msg(scene_to_msg(flush)).to_dict() == flush.to_dict()
    assert 'clearance' not in scene_from_msg(scene_to_msg(flush)).to_dict()
    bad = scene_to_msg(s)
    bad.clearance = 0.7
    with pytest.raises(RadError, match='clearance'):
        scene_from_msg(bad)


@pytest.mark.parametrize('order', ['request', 'queue'])
def test_a_feeder_travels_in_the_scene_message(order):
    s = generate_scene(GeneratorConfig(grid=3, supply='feeder', feeder_order=order, feeder_window=2), 2)
    msg = scene_to_msg(s)
    assert len(msg.feeder) == 1 and list(msg.feeder[0].blocks) == list(s.feeder.blocks)
    back = scene_from_msg(msg)
    assert back == s and back.feeder == s.feeder
    assert list(scene_to_msg(generate_scene(GeneratorConfig(grid=3), 2)).feeder) == []
    msg.feeder[0].blocks = ['nope']
    with pytest.raises(RadError, match="feeder.blocks: unknown block id 'nope'"):
        scene_from_msg(msg)


def test_a_stud_system_travels_in_the_scene_message():
    from pathlib import Path

    from rad_core.allocation.brick_scenes import scene_from_design
    from rad_core.domain.brick_designs import read_design
    design = read_design(Path(__file__).resolve().parents[2] / 'scenes' / 'bricks' / 'duplo_bridge_tower.ldr')
    s, _ = scene_from_design(design, unit=0.03)
    msg = scene_to_msg(s)
    assert len(msg.studs) == 1 and msg.studs[0].system == 'duplo' and msg.studs[0].course == pytest.approx(0.036)
    back = scene_from_msg(msg)
    # All but the design, which travels in a request's scene_json only (as measured offsets do).
    assert s.design and not back.design
    assert back.studs == s.studs and back.to_dict() == {k: v for k, v in s.to_dict().items() if k != 'design'}
    assert list(scene_to_msg(scene()).studs) == []
    assert not msg.studs[0].baseplate
    on_plate, _ = scene_from_design(design, unit=0.03, baseplate=True)
    plate_msg = scene_to_msg(on_plate)
    assert plate_msg.studs[0].baseplate and scene_from_msg(plate_msg).studs == on_plate.studs
    msg.studs[0].clutch = -1.0
    with pytest.raises(RadError, match='studs.clutch'):
        scene_from_msg(msg)

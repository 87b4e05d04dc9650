"""Parameters on running nodes over DDS: every parameter of the allocation, sequencer, twin and assembly
nodes is described; read-only ones and values out of range are refused with the reason; a change a
node applies takes effect (the allocation's next request, the twin's simulated time rate)."""

import time

import pytest
from ros_harness import call_service, ros_args, spin_until, wait_for_service


class Params:
    """A running node's parameter services."""

    def __init__(self, ros_node, node: str):
        from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
        self.ros_node = ros_node
        self.set_client = wait_for_service(ros_node, SetParameters, f'/{node}/set_parameters', timeout=30.0)
        self.describe_client = wait_for_service(ros_node, DescribeParameters, f'/{node}/describe_parameters')
        self.list_client = wait_for_service(ros_node, ListParameters, f'/{node}/list_parameters')

    def set(self, name: str, value):
        from rcl_interfaces.msg import Parameter
        from rclpy.parameter import Parameter as RclpyParameter
        msg = Parameter(name=name, value=RclpyParameter(name, value=value).get_parameter_value())
        from rcl_interfaces.srv import SetParameters
        return call_service(self.ros_node, self.set_client, SetParameters.Request(parameters=[msg])).results[0]

    def describe(self) -> dict:
        from rcl_interfaces.srv import DescribeParameters, ListParameters
        names = call_service(self.ros_node, self.list_client, ListParameters.Request()).result.names
        names = [n for n in names if n not in ('use_sim_time', 'start_type_description_service')]
        got = call_service(self.ros_node, self.describe_client, DescribeParameters.Request(names=names))
        return dict(zip(names, got.descriptors))


def assert_described(descriptors: dict, dynamic: set[str]) -> None:
    undescribed = [n for n, d in descriptors.items() if not d.description]
    assert not undescribed, f'parameters without a description: {undescribed}'
    changeable = {n for n, d in descriptors.items() if not d.read_only}
    assert changeable == dynamic, changeable ^ dynamic


def test_allocation_parameters_apply_to_the_next_request_or_are_refused(node_process, ros_node):
    proc = node_process('rad_planner', 'allocation_node')
    p = Params(ros_node, 'allocation')
    assert_described(p.describe(), {'time_limit_s', 'seed', 'num_workers', 'support', 'prefer', 'effector'})
    refused = p.set('support', 'sideways')
    assert not refused.successful and "support must be one of" in refused.reason, refused.reason
    refused = p.set('prefer', 'fewer')        # prefer needs a support rule
    assert not refused.successful and 'needs support' in refused.reason, refused.reason
    refused = p.set('num_workers', 0)
    assert not refused.successful and 'num_workers' in refused.reason, refused.reason
    from rad_core.allocation import AllocationParams, solve
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_msgs.srv import Allocate
    from rad_ros.conversions import placement_from_msg
    scene = generate_scene(GeneratorConfig(grid=4), 0)
    stable = list(solve(scene, AllocationParams(support='stable', prefer='fewer')).placements)
    assert stable != list(solve(scene, AllocationParams()).placements)    # the change is visible
    assert p.set('support', 'stable').successful
    assert p.set('prefer', 'fewer').successful   # now it has one
    client = wait_for_service(ros_node, Allocate, 'allocate')
    r = call_service(ros_node, client, Allocate.Request(scene_json=scene.dumps()), timeout=60.0)
    assert r.success, r.reason
    assert [placement_from_msg(m) for m in r.placements] == stable
    assert proc.is_running()


def test_sequencer_parameters_are_read_only_and_described(node_process, ros_node):
    node_process('rad_planner', 'sequencer_node')
    p = Params(ros_node, 'sequencer')
    assert_described(p.describe(), set())
    refused = p.set('budget', 5)
    assert not refused.successful and 'read-only' in refused.reason.lower(), refused.reason


def test_a_range_violation_at_start_stops_the_node_with_one_line(node_process):
    proc = node_process('rad_sim', 'twin_node', *ros_args({'publish_rate_hz': 0.5}))
    assert proc.wait(timeout=30.0) == 1
    assert 'cannot start' in proc.stderr() and 'publish_rate_hz' in proc.stderr(), proc.output_tail()
    assert 'Traceback' not in proc.stderr()


def test_twin_real_time_factor_applies_at_once_and_the_rest_is_read_only(node_process, ros_node):
    from rosgraph_msgs.msg import Clock
    node_process('rad_sim', 'twin_node', *ros_args({'publish_clock': True, 'real_time_factor': 1.0}))
    p = Params(ros_node, 'twin')
    assert_described(p.describe(), {'real_time_factor'})
    clocks = []
    ros_node.create_subscription(Clock, '/clock', lambda m: clocks.append((time.monotonic(), m.clock)), 10)
    assert spin_until(ros_node, lambda: len(clocks) > 5, timeout=30.0)

    def rate(seconds: float = 1.5) -> float:
        clocks.clear()
        spin_until(ros_node, lambda: False, timeout=seconds)
        (w0, c0), (w1, c1) = clocks[0], clocks[-1]
        return ((c1.sec - c0.sec) + (c1.nanosec - c0.nanosec) * 1e-9) / (w1 - w0)

    assert rate() == pytest.approx(1.0, rel=0.25)
    refused = p.set('real_time_factor', 0.0)
    assert not refused.successful and 'range' in refused.reason.lower(), refused.reason
    refused = p.set('publish_rate_hz', 10.0)
    assert not refused.successful and 'read-only' in refused.reason.lower(), refused.reason
    assert p.set('real_time_factor', 3.0).successful
    assert rate() == pytest.approx(3.0, rel=0.25)


def test_assembly_parameters_are_described_ranged_and_read_only_where_read_at_configure(node_process, ros_node):
    node_process('rad_planner', 'assembly_node')
    p = Params(ros_node, 'assembly')
    dynamic = {'time_limit_s', 'anytime_deadline_s', 'allocation_time_limit_s', 'seed', 'service_timeout_s',
               'settle_s', 'position_tol', 'max_replans', 'step_timeout_factor', 'sequencer_timeout_s',
               'max_reallocations', 'improve_time_s', 'gripper_result_is_width', 'path_tolerance', 'goal_tolerance',
               'goal_time_tolerance', 'require_joint_states'}
    assert_described(p.describe(), dynamic)
    refused = p.set('time_limit_s', -1.0)
    assert not refused.successful and 'range' in refused.reason.lower(), refused.reason
    refused = p.set('robot', 'fr3')
    assert not refused.successful and 'read-only' in refused.reason.lower(), refused.reason
    assert p.set('max_replans', 5).successful

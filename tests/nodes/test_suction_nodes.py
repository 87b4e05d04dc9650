"""The vacuum gripper through the node graph, over real DDS: franka_vacuum_gripper's actions on the twin,
every result checked by the assembly node, and a solid box the hand cannot finish built whole."""

import json

import numpy as np
import pytest
from control_msgs.action import GripperCommand
from franka_vacuum_gripper.action import DropOff, Vacuum
from rad_core.allocation.supply import SupplyParams, supply
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.voxels import Model, place_regions
from rclpy.action import ActionClient
from ros_harness import send_goal

from test_assembly_node import execute, start_graph, stop_graph

SUCTION = {'effector': 'suction'}


def solid_box(unit: float = 0.04):
    targets = place_regions([Model('box', '', np.ones((4, 2, 2), dtype=bool))], unit)
    scene, report = supply(targets, unit, dict(DEFAULT_LIBRARY), params=SupplyParams(time_limit_s=20.0,
                                                                                     effector='suction'))
    assert report.hand_covered == 16
    return scene


@pytest.fixture
def suction_graph(node_process, ros_node, tmp_path):
    g = start_graph(node_process, ros_node, tmp_path, scene=solid_box(), twin=SUCTION, gamp=SUCTION,
                    assembly=SUCTION)
    yield g
    stop_graph(g)


def test_the_twin_serves_the_vacuum_gripper_and_no_hand(suction_graph):
    node = suction_graph.node
    assert not ActionClient(node, GripperCommand, 'franka_gripper/gripper_action').wait_for_server(timeout_sec=1.0)
    vacuum = ActionClient(node, Vacuum, 'franka_vacuum_gripper/vacuum')
    # The cup in the air at home: the goal aborts, its result says why.
    status, result = send_goal(node, vacuum, Vacuum.Goal(vacuum=50, timeout=100), timeout=20.0)
    assert not result.success and 'touches no block' in result.error, result.error
    status, result = send_goal(node, ActionClient(node, DropOff, 'franka_vacuum_gripper/dropoff'),
                               DropOff.Goal(timeout=100), timeout=20.0)
    assert result.success


def test_a_solid_box_is_built_whole_with_vacuum_and_drop_off_commands(suction_graph):
    from rad_msgs.action import ExecuteAssembly
    result = execute(suction_graph, ExecuteAssembly.Goal(scene_json='', replan=True))
    assert result.success and result.coverage == 1.0, result.reason
    doc = json.loads(result.result_json)
    assert all([g['action'] for g in step['gripper']] == ['vacuum', 'drop_off'] for step in doc['steps'])
    assert doc['execution']['faults'] == []
    assert all(p.is_running() for p in suction_graph.procs.values())

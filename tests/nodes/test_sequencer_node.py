"""sequencer_node over real DDS: rankings, refusals, a bad checkpoint, and /plan_assembly
when the sequencer dies mid-plan and comes back."""

import json
import time

import pytest
import rclpy
from rad_core.allocation import solve
from rad_core.allocation.placements import Placement
from rad_core.cell.panda import HOME
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from ros_harness import call_service, ros_args, wait_for_service

from scenes import U, doc

DEMO_SCENE = generate_scene(GeneratorConfig(grid=4), 8)


def test_serves_a_ranking_and_a_bad_request_gets_a_reason_then_the_next_is_served(node_process, ros_node):
    from rad_msgs.srv import Sequence
    from rad_ros.sequencer_msgs import ranking_from_response, sequence_request
    # An agent that searches (the default agent is the greedy network, which does not), shipped network.
    proc = node_process('rad_planner', 'sequencer_node',
                        *ros_args({'agent': 'milp-dqn-mixed+lookahead:5+verify+realloc+support:arm'}))
    client = wait_for_service(ros_node, Sequence, 'sequence', timeout=60.0)
    placements = solve(DEMO_SCENE).placements

    def ask(request):
        return call_service(ros_node, client, request, timeout=60.0)
    good = sequence_request(DEMO_SCENE, placements, max_actions=3)
    r = ask(good)
    assert r.success, r.reason
    assert r.policy.startswith('milp-dqn-mixed+lookahead:5') and not r.terminate
    ranking = ranking_from_response(r)
    assert 1 <= len(ranking.actions) <= 3 and len(ranking.values) == len(ranking.actions)
    assert {a.block_id for a in ranking.actions} <= {b.id for b in DEMO_SCENE.blocks}
    assert ranking.timings['sequencing'] > 0 and 'search' in ranking.timings
    assert ask(good).actions == r.actions   # seeded: the same question, the same answer

    other = Placement(placements[0].type, 'nosuch', 0, placements[0].cells)
    outside = Placement(placements[0].type, placements[0].target, 0, ((40, 0, 0),))
    bad = {
        'not valid JSON': Sequence.Request(scene_json='{"format": "rad-scene/1", '),
        'unknown target region': sequence_request(DEMO_SCENE, [other]),
        'has a cell outside region': sequence_request(DEMO_SCENE, [outside]),
        'start_positions needs': sequence_request(DEMO_SCENE, placements, start=[0.0] * 4),
    }
    for expected, request in bad.items():
        r = ask(request)
        assert not r.success and expected in r.reason, (expected, r.reason)
        assert ask(good).success
    # Everything built: nothing to rank, the policy stops (a valid answer, not a failure).
    done = ask(sequence_request(SMALL_BUILT, solve(SMALL).placements))
    assert done.success and done.terminate and not done.actions and done.reason
    assert proc.is_running()
    assert proc.stop() == 0, proc.output_tail()


SMALL = Scene.from_dict(doc(blocks=[{'id': 'c0', 'type': 'cube', 'position': [0.4, -0.2, U / 2], 'yaw': 0}],
                            targets=[{'name': 'front', 'origin': [0.45, 0.1, U / 2], 'size': [1, 1, 1],
                                      'filled': [[0, 0, 0]]}]))
SMALL_BUILT = Scene.from_dict(json.loads(SMALL.dumps().replace('[0.4, -0.2,', '[0.45, 0.1,')))


@pytest.mark.parametrize('params,expected', [
    ({'policy': 'milp-dqn', 'checkpoint': 'BAD'}, 'is corrupt or not a rad model file'),
    ({'policy': 'mcts'}, 'policy must be one of milp-dqn-mcts'),
    ({'torch_threads': 0}, 'torch_threads must be at least 1, got 0'),
])
def test_a_bad_checkpoint_or_policy_stops_the_node_with_one_line_naming_it(node_process, tmp_path, params,
                                                                           expected):
    bad = tmp_path / 'model.pt'
    bad.write_bytes(b'not a model')
    params = {k: str(bad) if v == 'BAD' else v for k, v in params.items()}
    proc = node_process('rad_planner', 'sequencer_node', *ros_args(params))
    assert proc.wait(timeout=60) == 1
    lines = [line for line in proc.stderr().splitlines() if 'sequencer_node' in line]
    assert len(lines) == 1 and expected in lines[0], proc.stderr()
    assert 'Traceback' not in proc.stderr()
    if 'checkpoint' in params:
        assert str(bad) in lines[0]


def test_sequencer_killed_mid_plan_fails_the_plan_in_bounded_time_and_planning_recovers(node_process, ros_node):
    from rad_msgs.srv import PlanAssembly, Sequence
    timeout = 3.0
    sequencer_args = ros_args({'policy': 'milp-dqn'})
    procs = [node_process('rad_planner', 'allocation_node'), node_process('rad_gamp', 'gamp_node'),
             node_process('rad_planner', 'assembly_node', *ros_args({'sequencer_timeout_s': timeout}))]
    sequencer = node_process('rad_planner', 'sequencer_node', *sequencer_args)
    client = wait_for_service(ros_node, PlanAssembly, 'plan_assembly', timeout=30.0)
    wait_for_service(ros_node, Sequence, 'sequence', timeout=60.0)
    # No robot in this graph: the request gives the start joints (home) instead of /joint_states.
    request = PlanAssembly.Request(scene_json=DEMO_SCENE.dumps(), start_positions=[float(v) for v in HOME])
    assert call_service(ros_node, client, request, timeout=120.0).success

    # Mid-plan: the sequencer has answered the first step of a new plan, three are left.
    answered = len(sequencer.stdout().splitlines() + sequencer.stderr().splitlines())
    future = client.call_async(request)
    t0 = time.monotonic()
    deadline = t0 + 30.0
    while time.monotonic() < deadline:
        lines = sequencer.stdout().splitlines() + sequencer.stderr().splitlines()
        if any('ranked' in line for line in lines[answered:]):
            break
        rclpy.spin_once(ros_node, timeout_sec=0.02)
    sequencer.popen.kill()
    killed = time.monotonic()
    rclpy.spin_until_future_complete(ros_node, future, timeout_sec=60.0)
    r = future.result()
    assert r is not None, 'no answer from /plan_assembly'
    print(f'after the kill, in {time.monotonic() - killed:.1f} s: {r.reason}')
    assert not r.success and r.reason.startswith('the sequencer node (service sequence)'), r.reason
    assert time.monotonic() - killed < timeout + 10.0

    sequencer = node_process('rad_planner', 'sequencer_node', *sequencer_args)
    sequencer.wait_for_output('sequencer ready', timeout=60.0)
    deadline, r = time.monotonic() + 30.0, None
    while time.monotonic() < deadline:
        r = call_service(ros_node, client, request, timeout=120.0)
        if r.success:
            break
        time.sleep(0.5)
    assert r.success, f'planning after the sequencer restarted: {r.reason}'
    for proc in procs + [sequencer]:
        assert proc.stop() == 0, proc.output_tail()

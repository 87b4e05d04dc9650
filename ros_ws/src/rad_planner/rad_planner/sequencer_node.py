"""/sequence: the learned sequencer of the node graph (rad_core.sequencing.decide.sequencer).

Loads the policy once at start-up (a Q-network, or HEUR) and, for search, keeps its
own in-process planning twin; for each request ranks the allocation's next actions
from the given scene state, best first. /plan_assembly asks it at every step and
takes the first action GAMP finds feasible, so the policy never commands anything.

  srv  sequence  rad_msgs/Sequence

Parameters: agent (an agent's text, `rad_core.sequencing.decide.agents`: a preset such as `default`, or
scorer+search:budget...; the sequencer uses its scorer, search and budget), seed; and, on
top of it, checkpoint (a model file replacing the agent's network, '' = none), budget
(search simulations per decision, 0 = the agent's), search_time_s (bnb seconds per search,
0 = the agent's). policy: one of the older names (milp-dqn-lookahead, milp-dqn-halving,
milp-dqn-mcts, milp-dqn-dfs, milp-dqn, heur) instead of agent ('' = use agent).
torch_threads (1): the threads torch runs the network on. One is no slower on an idle
machine (the graphs are small) and far faster when the cores are shared, as here with the
gamp and assembly nodes (measured: a g = 5 ranking in 16.5 ms on one thread, 73 ms on two
while another job ran); rad eval's Dask workers use one thread too, so the node ranks as they do.
A bad agent, policy, checkpoint or torch_threads: the node does not start (one line on
stderr, exit 1).
"""

from __future__ import annotations

import time

from rad_core.domain.errors import RadError
from rad_core.sequencing.decide.sequencer import DEFAULT_AGENT, Sequencer, SequencerConfig
from rad_msgs.srv import Sequence
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare
from rad_ros.sequencer_msgs import fill_sequence_response, sequence_inputs
from rclpy.node import Node

# All read when the node starts (the agent and its network are loaded then): read-only.
PARAMS = [Param('agent', DEFAULT_AGENT, 'the ranking agent (rad_core.sequencing.decide.agents)'),
          Param('policy', '', "a learned policy's name ('' = the agent's)"),
          Param('checkpoint', '', "a learned policy's weights file ('' = the shipped ones)"),
          Param('budget', 0, 'MCTS simulations per decision (0 = the agent\'s)', range=(0, 100000)),
          Param('seed', 0, 'seed of the search', range=(0, 2 ** 31 - 1)),
          Param('search_time_s', 0.0, 'time per decision for the search (s; 0 = the agent\'s)', range=(0.0, 600.0)),
          Param('torch_threads', 1, 'threads torch may use (at least 1)')]


class SequencerNode(Node):
    def __init__(self):
        super().__init__('sequencer')
        declare(self, PARAMS)
        threads = int(self.param('torch_threads'))
        if threads < 1:
            raise RadError(f'torch_threads must be at least 1, got {threads}')
        import torch
        torch.set_num_threads(threads)
        budget, search_time = int(self.param('budget')), float(self.param('search_time_s'))
        config = SequencerConfig(agent=str(self.param('agent')), policy=str(self.param('policy')),
                                 checkpoint=str(self.param('checkpoint')), budget=budget or None,
                                 seed=int(self.param('seed')), search_time_s=search_time or None)
        t0 = time.perf_counter()
        self.sequencer = Sequencer(config)   # RadError (a bad checkpoint names its file): the node does not start
        agent = self.sequencer.agent
        self.policy = agent if not self.sequencer.spec.learned else f'{agent} ({self.sequencer.source})'
        self.create_service(Sequence, 'sequence', self.sequence_callback)
        self.get_logger().info(f'sequencer ready: {self.policy}, loaded in {time.perf_counter() - t0:.1f} s')

    def param(self, name):
        return self.get_parameter(name).value

    def destroy_node(self):
        self.sequencer.close()
        super().destroy_node()

    def sequence_callback(self, request, response):
        response.policy = self.policy
        try:
            scene, placements, start, max_actions = sequence_inputs(request)
            ranking = self.sequencer.rank(scene, placements, start=start, max_actions=max_actions,
                                          scorer_only=bool(request.scorer_only))
            fill_sequence_response(response, ranking, self.policy)
        except RadError as e:
            response.success, response.reason = False, str(e)
            self.get_logger().warning(f'sequence refused: {e}')
            return response
        except Exception as e:  # noqa: BLE001 - a service must answer, never die
            self.get_logger().error(f'sequence failed: {type(e).__name__}: {e}')
            response.success, response.reason = False, f'internal error: {e}'
            return response
        best = f'best {ranking.actions[0].block_id}' if ranking.actions else f'stop: {ranking.reason}'
        self.get_logger().info(f'ranked {len(ranking.actions)} actions ({best}) in '
                               f'{ranking.timings.get("sequencing", 0.0) * 1e3:.0f} ms')
        return response


main = main_for(SequencerNode)

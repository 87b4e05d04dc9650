"""The sequencer: for a scene state and its allocation, which actions to try next.

This is what the `sequencer_node` serves and what `/plan_assembly` asks at every
step. It owns the policy (a trained Q-network, or HEUR) and, for search, its own
in-process planning twin (`RobotAssemblyEnv`, teleporting execution: GAMP plans
every expanded action and physics judges it), so a search can try actions for
real and come back. It answers a *ranking*: the caller (plan_assembly) still takes
the first action that GAMP finds feasible from its own planning copy, so whatever
the policy, nothing is commanded that fails there.

The agent (`rad_core.sequencing.decide.agents`, text form): the sequencer uses its scorer (a network or
HEUR), its search and the search's budget. `default` is what the node runs: the mixed
network, no search (`agents.PRESETS`). Verification, re-allocation and the allocation's
support are the caller's (/plan_assembly always takes the first action GAMP finds
feasible). Every search is one of `sequencing.decide.search.SEARCHES`; one that plans whole
lines (the branch and bound, `bnb`) has its line kept, so later requests along it
answer at once (a state off the line searches again).

The node's older `policy` names still work: milp-dqn-mcts (the paper's MCTS),
milp-dqn-halving, milp-dqn-lookahead, milp-dqn-dfs (bnb), milp-dqn (no search) with
the shipped mixed network or `checkpoint`, and heur.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from rad_core.allocation.cpsat import pose_key
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
from rad_core.gamp.action import SceneAction, start_joints
from rad_core.gamp.planner import GampConfig
from rad_core.sequencing.decide import policy as ranking_rules
from rad_core.sequencing.decide.actions import AllocationActions, mdp_actions, scene_action
from rad_core.sequencing.decide.agents import SIMULATION_SEARCHES, AgentSpec, label, parse
from rad_core.sequencing.decide.policy import ranked_indices, standing_fallbacks
from rad_core.sequencing.decide.search import SEARCHES, EnvModel, line_result

# The sequencer node's older policy names (a search over the shipped mixed network, or HEUR).
POLICIES = ('milp-dqn-mcts', 'milp-dqn-halving', 'milp-dqn-lookahead', 'milp-dqn-dfs', 'milp-dqn', 'heur')
_POLICY_SEARCH = {'milp-dqn-mcts': 'mcts', 'milp-dqn-halving': 'halving', 'milp-dqn-lookahead': 'lookahead',
                  'milp-dqn-dfs': 'bnb', 'milp-dqn': ''}
DEFAULT_AGENT = 'default'
# The shipped network the older policy names load when no checkpoint is given.
DEFAULT_NETWORK = 'milp-dqn-mixed'


@dataclass(frozen=True)
class SequencerConfig:
    """agent: an agent's text (`rad_core.sequencing.decide.agents`); the sequencer uses its scorer, search and
    budget. policy: one of the older POLICIES instead (then agent is ignored). checkpoint:
    a model file replacing the scorer's network; budget: the search's simulations per
    decision; search_time_s: the branch and bound's seconds per search (None: the agent's).
    epsilon: the search's exploration (None: the paper's 0.05 for mcts, 0 otherwise).
    seed: seeds the policy's and the search's generator, together with the state's step
    count, so one request always gets the same answer."""

    agent: str = DEFAULT_AGENT
    policy: str = ''
    checkpoint: str = ''
    budget: int | None = None
    seed: int = 0
    epsilon: float | None = None
    search_time_s: float | None = None

    def spec(self) -> AgentSpec:
        """The agent this configuration runs (RadError naming what does not fit)."""
        if self.policy:
            if self.policy not in POLICIES:
                raise RadError(f'policy must be one of {", ".join(POLICIES)}, got {self.policy!r}')
            if self.policy == 'heur':
                if self.checkpoint:
                    raise RadError('checkpoint applies to the learned policies, not heur')
                spec = AgentSpec('heur')
            else:
                search = _POLICY_SEARCH[self.policy]
                spec = AgentSpec(self.checkpoint or DEFAULT_NETWORK, search, verify=search == 'bnb')
        else:
            spec = parse(self.agent)
            if self.checkpoint:
                if not spec.learned:
                    raise RadError(f'checkpoint applies to learned agents, not {label(spec)!r}')
                spec = replace(spec, scorer=self.checkpoint)
        if self.budget is not None:
            if not isinstance(self.budget, int) or isinstance(self.budget, bool) or self.budget < 1:
                raise RadError(f'budget must be a positive integer, got {self.budget!r}')
            if spec.search in SIMULATION_SEARCHES:
                spec = replace(spec, budget=self.budget)
        if self.search_time_s is not None:
            if not (isinstance(self.search_time_s, (int, float)) and 0 < self.search_time_s < 3600):
                raise RadError(f'search_time_s must be a positive number of seconds under 3600, '
                               f'got {self.search_time_s!r}')
            if spec.search == 'bnb':
                spec = replace(spec, budget=float(self.search_time_s))
        return spec

    def validate(self) -> None:
        self.spec()
        if self.epsilon is not None and not 0.0 <= self.epsilon <= 1.0:
            raise RadError(f'epsilon must be in [0, 1], got {self.epsilon!r}')


@dataclass
class Ranking:
    """What to try next, best first: the agent's own choice first. terminate: the agent's
    choice is to stop (reason says why); actions is then empty, or lists what a verified
    caller may still try. The last `fallbacks` actions are those the agent values below
    stopping, for a verified caller to try where nothing else is left
    (`sequencing.decide.policy.FALLBACKS`); an unverified one takes the first action, or stops on
    terminate."""

    actions: list[SceneAction] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    terminate: bool = False
    reason: str = ''
    timings: dict = field(default_factory=dict)
    search: dict | None = None     # the search tree (SearchResult.to_dict), when one ran
    fallbacks: int = 0             # how many of the actions, at the end, are valued below stopping


class Sequencer:
    def __init__(self, config: SequencerConfig = SequencerConfig(), policy=None):
        """policy: the agent's scorer when the caller has already loaded it (default: loaded here)."""
        config.validate()
        self.config = config
        self.spec = config.spec()
        self.agent = label(self.spec)
        self._renv = None   # the planning twin, made on the first search
        # bnb: state -> (the rest of its best line, the coverage the line reaches)
        self._lines: dict[tuple, tuple[list[SceneAction], float]] = {}
        self.policy = policy if policy is not None else self.spec.make_policy()
        if self.spec.learned:
            if self.policy.actions != 'milp':
                raise RadError(f'{self.policy.source} was trained on the {self.policy.actions!r} action space; '
                               f'the sequencer chooses among the allocation\'s actions (a milp-dqn network)')

    @property
    def source(self) -> str:
        return getattr(self.policy, 'source', self.agent)

    @property
    def search_epsilon(self) -> float:
        if self.config.epsilon is not None:
            return self.config.epsilon
        return 0.05 if self.spec.search == 'mcts' else 0.0

    def forget(self) -> None:
        """Drop the best lines the branch and bound keeps (e.g. between benchmark runs of one scene)."""
        self._lines.clear()

    def close(self) -> None:
        if self._renv is not None:
            self._renv.close()
            self._renv = None

    def rank(self, scene: Scene, placements, start=None, max_actions: int = 0, scorer_only: bool = False) -> Ranking:
        """Rank the allocation's next actions in `scene` (blocks already placed sit in
        their cells). start: the arm's joints (7 or 9 values) or None for home.
        scorer_only: rank by the agent's scorer alone, without its search (anytime
        planning's first plan, `plan_for_agent`).
        Raises RadError when the request does not fit (placements outside the scene's
        regions, unknown block types, bad joints)."""
        t0 = time.perf_counter()
        if max_actions < 0:
            raise RadError(f'max_actions must be >= 0, got {max_actions}')
        q0 = start_joints([] if start is None else start)
        env = AssemblyEnv(scene)
        _check_placements(scene, placements)
        space = AllocationActions(env, placements)
        guide = space.guide
        rng = np.random.default_rng([self.config.seed, env.state.steps, len(env.state.placed)])
        allowed = space(env)
        ranking = Ranking()
        left = len(guide.open_poses(env.state))
        if not allowed:
            ranking.terminate = True
            ranking.reason = ('every allocated pose is built' if left == 0
                              else f'{left} allocated poses left, no unplaced block of their types')
        elif self.spec.search and not scorer_only:
            self._search(scene, env, space, q0, rng, ranking, left)
        else:
            ts = time.perf_counter()
            scores = np.asarray(self.policy.scores(env, allowed, rng), dtype=float)
            above = ranked_indices(scores)
            ranked = ranked_indices(scores, ranking_rules.FALLBACKS)    # then a verified caller's fallbacks
            kept = set(standing_fallbacks(env, [allowed[i] for i in ranked[len(above):]]))
            ranked = above + [i for i in ranked[len(above):] if allowed[i] in kept]
            ranking.fallbacks = len(ranked) - len(above)
            ranking.actions = [scene_action(env, allowed[i]) for i in ranked]
            ranking.values = [float(scores[i]) for i in ranked]
            ranking.timings['policy'] = time.perf_counter() - ts
            if not above:
                ranking.terminate = True
                why = getattr(self.policy, 'why_none', f'{self.agent} values stopping more')
                ranking.reason = f'{left} allocated poses left, none of them can be built next ({why})'
        if max_actions:
            preferred = len(ranking.actions) - ranking.fallbacks
            ranking.actions, ranking.values = ranking.actions[:max_actions], ranking.values[:max_actions]
            ranking.fallbacks = max(0, len(ranking.actions) - preferred)
        ranking.timings['sequencing'] = time.perf_counter() - t0
        return ranking

    def _search(self, scene: Scene, env: AssemblyEnv, space: AllocationActions, q0, rng, ranking: Ranking,
                left: int) -> None:
        """The search's ranking; a search that plans whole lines (bnb) has its line kept, so a
        later request along it answers with the line's next action without searching again."""
        key = _line_key(env, space.guide.placements)
        known = self._lines.get(key)
        if known is not None:
            line, value = known
            model = EnvModel(env, self.policy, space, rng_seed=int(rng.integers(2**31)))
            actions = model.actions()
            result = line_result(actions, np.asarray(model.q_values(actions), dtype=float),
                                 mdp_actions(env, line[:1], actions), value, info={'known_line': True})
        else:
            ts = time.perf_counter()
            renv = self._twin_at(scene, q0)
            ranking.timings['twin'] = time.perf_counter() - ts
            ts = time.perf_counter()
            model = EnvModel(renv, self.policy, space)   # the space is stateless: it serves the twin's env too
            result = SEARCHES[self.spec.search](model, rng, budget=self.spec.budget, epsilon=self.search_epsilon)
            ranking.timings['search'] = time.perf_counter() - ts
            if result.line is not None:
                if len(self._lines) > 10_000:
                    self._lines.clear()
                self._remember_line(scene, space, result.line, float(result.info.get('coverage', 0.0)))
        ranking.search = result.to_dict()
        above = result.proposals()
        below = result.proposals(ranking_rules.FALLBACKS)[len(above):]
        kept = set(standing_fallbacks(env, [a for a, _ in below]))
        below = [(a, v) for a, v in below if a in kept]
        ranking.fallbacks = len(below)
        for action, value in above + below:
            ranking.actions.append(scene_action(env, action))
            ranking.values.append(float(value))
        move = result.action
        if not move.is_terminate and (not ranking.actions or ranking.actions[0] != scene_action(env, move)):
            # The search's own choice leads, even one whose simulated step failed: an unverified
            # caller takes the move (and fails with it, as the paper's agents do); a verified one
            # checks it first like any other.
            value = next((c.value for c in result.children if c.action == move), float('nan'))
            ranking.actions.insert(0, scene_action(env, move))
            ranking.values.insert(0, float(value))
        if move.is_terminate and ranking.actions:
            ranking.terminate = True      # the agent would stop; the actions are what a verified caller may try
            ranking.reason = f'{left} allocated poses left; the search values stopping above building them'
        if not ranking.actions:
            ranking.terminate = True
            tried = sum(1 for c in result.children if not c.action.is_terminate)
            if result.line is not None:
                why = 'the search found no order that fills more of the target from here'
            elif tried:
                why = f'the {tried} the search tried failed in the planning twin or are valued below stopping'
            else:
                why = 'stopping is valued above all of them'
            ranking.reason = f'{left} allocated poses left, none of them can be built next ({why})'

    def _remember_line(self, scene: Scene, space: AllocationActions, actions, coverage: float) -> None:
        """The rest of the line for its first state and for every state along it
        (bookkeeping only: the line's steps were judged by the search)."""
        env = AssemblyEnv(scene, EnvConfig(stability='none'))
        for n in range(len(actions) + 1):
            self._lines[_line_key(env, space.guide.placements)] = ([scene_action(env, a) for a in actions[n:]],
                                                                   float(coverage))
            if n < len(actions):
                env.step(actions[n])

    def _twin_at(self, scene: Scene, q0):
        """The planning twin reset to the scene, the arm at q0 (None: home)."""
        renv = self._twin(scene)
        renv.reset()
        if q0 is not None:
            renv.world.set_joint_positions(q0)
            renv.twin.sync()
        return renv

    def _twin(self, scene: Scene):
        """The planning twin, one PyBullet world reused across requests. Its hand sets blocks down, as the
        plans its searches rank for do (`agent.stages.Planning.plan`; `GampConfig.drop`)."""
        if self._renv is None:
            self._renv = RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport', gamp=GampConfig(drop=False)))
        else:
            self._renv.load(scene)
        return self._renv


def _line_key(env: AssemblyEnv, placements) -> tuple:
    """What a best line depends on: the allocation, what is placed where, and where the
    blocks still on the table lie."""
    placed = env.state.placed
    return (frozenset(pose_key(p.type, p.target, p.cells) for p in placements),
            frozenset((env.scene.blocks[b].id, tuple(sorted(int(c) for c in cells)))
                      for b, (cells, _) in placed.items()),
            tuple((blk.id, blk.type, blk.position, blk.yaw) for b, blk in enumerate(env.scene.blocks)
                  if b not in placed))


def _check_placements(scene: Scene, placements) -> None:
    names = {t.name for t in scene.targets}
    for p in placements:
        if p.type not in scene.block_types:
            raise RadError(f'allocation names block type {p.type!r}, which the scene does not define')
        if p.target not in names:
            raise RadError(f'allocation names unknown target region {p.target!r}')
    AllocationGuide(scene, placements)   # cells inside their regions, or RadError

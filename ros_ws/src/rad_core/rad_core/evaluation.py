"""The paper's evaluation (Sec. V, Tables I and II) for any sequencer.

An agent is a `Policy` (it scores the allocation's allowed actions) plus two
choices that decide which row of Table II it reproduces:

- where it acts: with the robot in the loop (`RobotAssemblyEnv`: GAMP decides
  grasp and placement, the twin executes, physics judges) or without it
  (`AssemblyEnv` with physical stability, the paper's "HEUR wo robot" oracle);
- how the ranking becomes an action: the best-ranked one blindly (the paper's
  HEUR, which therefore fails with f_g / f_p), or the best one GAMP finds
  feasible from the current state (what /plan_assembly does: `heur-verified`).

Nothing ranked (above terminating) means the termination action, as in the
paper. Every episode starts from the scene with a fresh CP-SAT allocation
(deterministic: one worker, fixed seed), and episode i gets the random
generator default_rng(seed + i), so a run is reproducible from (agent, scenes,
robot, seed).

The learned sequencers (milp-dqn, dqn, dqn-rel) are agents whose policy is a
trained Q-network (`rad_core.learning`), each choosing among its own action
space; they load their shipped weights by name or any checkpoint file.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, TextIO

import numpy as np

from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.errors import RadError
from rad_core.mdp import AssemblyEnv, EnvConfig, Outcome
from rad_core.scene import Scene
from rad_core.sequencing.actions import ActionSpace, action_space
from rad_core.sequencing.episode import Decide, Decision, run_episode, stop
from rad_core.sequencing.policy import HeurPolicy, Policy, first_feasible, ranked_actions

KEYS = ('R', 'R_std', 'd', 'e', 'f', 'f_g', 'f_p', 'coverage', 'coverage_rel', 'n', 'scenes')
FAIL_GRASP = (Outcome.INVALID_GRASP,)
FAIL_PLACE = (Outcome.INVALID_PLACEMENT, Outcome.INVALID_DISTURBED)


@dataclass(frozen=True)
class Agent:
    """A sequencer under evaluation.

    make_policy: builds the policy (once per run; policies keep no per-episode
        state, each episode gets its own seeded generator).
    robot: None follows `evaluate`'s robot flag; False never uses the robot
        (the oracle), True always does (GAMP checks need the robot's world),
        whatever the flag says.
    verified: take the best-ranked action the planning copy finds feasible (with
        the robot: GAMP; without: the physics stability check), not the best one.
    actions: the action space it chooses among (`sequencing.actions`): 'milp'
        (the allocation's actions), 'all' (the DQN baseline), 'rel' (DQN-REL).
    support: the allocation it expects (`AllocationParams.support`): 'none'
        (the paper's MILP) or 'stable'; `evaluate`'s allocation argument overrides.
    search: '' (act on the policy's ranking) or a test-time search of
        `sequencing.search` ('mcts', 'halving', 'lookahead') on the acting env itself (snapshot,
        simulate, restore), with `budget` simulations per decision and exploration
        `epsilon` (None: the search's default, 0.05 for mcts as the paper, 0 for halving).
    reallocate: when the episode would stop with allocated poses open, check them (with
        the robot: a simulated step; without: stability), exclude those that fail as
        no-goods and re-solve the allocation over the free cells (each event in the row).
    """

    name: str
    make_policy: Callable[[], Policy]
    robot: bool | None = None
    verified: bool = False
    actions: str = 'milp'
    support: str = 'none'
    search: str = ''
    budget: int = 5
    epsilon: float | None = None
    reallocate: bool = False
    """Re-solve the allocation when sequencing stalls (`sequencing.reallocation`)."""
    time_limit_s: float = 60.0
    """Search time per scene of the branch and bound (search='exact' or 'dfs')."""


def _learned(name: str, actions: str, checkpoint=None, support: str = 'none', network: str | None = None,
             **kw) -> Agent:
    def make_policy():
        from rad_core.learning.policy import QPolicy
        return QPolicy.load(checkpoint if checkpoint is not None else (network or name))
    return Agent(name, make_policy, actions=actions, support=support, **kw)


AGENTS = {
    'heur': Agent('heur', HeurPolicy),
    'heur-verified': Agent('heur-verified', HeurPolicy, robot=True, verified=True),
    'heur-norobot': Agent('heur-norobot', HeurPolicy, robot=False),
    'milp-dqn': _learned('milp-dqn', 'milp'),
    'dqn': _learned('dqn', 'all'),
    'dqn-rel': _learned('dqn-rel', 'rel'),
    'milp-dqn-mixed': _learned('milp-dqn-mixed', 'milp', support='stable'),
    # The paper's MILP-DQN-MCTS (budget 5) and rad's sequential halving at the same budget.
    'milp-dqn-mcts': _learned('milp-dqn-mcts', 'milp', network='milp-dqn', search='mcts'),
    'milp-dqn-halving': _learned('milp-dqn-halving', 'milp', network='milp-dqn', search='halving'),
    'milp-dqn-mixed-mcts': _learned('milp-dqn-mixed-mcts', 'milp', support='stable', network='milp-dqn-mixed',
                                    search='mcts'),
    'milp-dqn-mixed-halving': _learned('milp-dqn-mixed-halving', 'milp', support='stable',
                                       network='milp-dqn-mixed', search='halving'),
    'milp-dqn-lookahead': _learned('milp-dqn-lookahead', 'milp', network='milp-dqn', search='lookahead'),
    # milp-dqn-mixed fine-tuned with the robot in the loop (docs/results/robot_training.md).
    'milp-dqn-robot': _learned('milp-dqn-robot', 'milp', support='stable'),
    'milp-dqn-robot-lookahead': _learned('milp-dqn-robot-lookahead', 'milp', support='stable',
                                         network='milp-dqn-robot', search='lookahead'),
    # The robot-feasible ceiling: branch and bound over orders and re-allocations (`sequencing.exact`).
    'exact': Agent('exact', HeurPolicy, robot=True, verified=True, support='stable', search='exact',
                   reallocate=True),
    # The same branch and bound as a time-bounded test-time search, children in the network's order.
    'milp-dqn-mixed-dfs': _learned('milp-dqn-mixed-dfs', 'milp', support='stable', network='milp-dqn-mixed',
                                   search='dfs', robot=True, verified=True, time_limit_s=10.0),
    'milp-dqn-mixed-lookahead': _learned('milp-dqn-mixed-lookahead', 'milp', support='stable',
                                         network='milp-dqn-mixed', search='lookahead'),
}
LEARNED = tuple(name for name, a in AGENTS.items() if a.name.startswith(('milp-dqn', 'dqn')))


def get_agent(agent: str | Agent, checkpoint: str | None = None, verify: bool = False,
              budget: int | None = None, reallocate: bool = False) -> Agent:
    """An agent by name; learned agents load `checkpoint` instead of their shipped
    weights; verify makes it take the best-ranked action the planning copy finds
    feasible (`Agent.verified`); budget sets a search agent's simulations per decision;
    reallocate makes it re-solve the allocation when it stalls (`Agent.reallocate`)."""
    from dataclasses import replace
    if isinstance(agent, Agent):
        return agent
    if reallocate:
        base = get_agent(agent, checkpoint, verify, budget)
        if base.actions != 'milp':
            raise RadError(f'--reallocate applies to agents choosing among the allocation\'s actions, '
                           f'not {base.name!r} ({base.actions!r})')
        return replace(base, name=f'{base.name}+realloc', reallocate=True)
    if verify:
        base = get_agent(agent, checkpoint, budget=budget)
        return replace(base, name=f'{base.name}+verify', verified=True)
    if agent not in AGENTS:
        raise RadError(f'unknown agent {agent!r}; one of {", ".join(AGENTS)}')
    found = AGENTS[agent]
    if budget is not None:
        if found.search not in ('mcts', 'halving', 'lookahead'):
            raise RadError(f'--budget applies to the search agents with a simulation budget (*-mcts, *-halving, '
                           f'*-lookahead), not {agent!r}')
        if budget < 1:
            raise RadError(f'--budget must be >= 1, got {budget}')
        found = replace(found, name=f'{agent}@{budget}', budget=budget)
    if checkpoint is not None:
        if agent not in LEARNED:
            raise RadError(f'--checkpoint applies to the learned agents ({", ".join(LEARNED)}), not {agent!r}')
        found = replace(found, make_policy=_learned(agent, found.actions, checkpoint).make_policy)
    return found


def uses_robot(agent: str | Agent, robot: bool) -> bool:
    """Whether the agent's episodes run with the robot, given the caller's flag."""
    agent = get_agent(agent)
    return robot if agent.robot is None else agent.robot


def coverage_opt(env: AssemblyEnv, guide: AllocationGuide) -> float:
    """Target coverage the allocation optimum achieves: target cells already
    filled or covered by an allocated pose, over all target cells."""
    filled = env.state.occupancy >= 0
    for cells in guide.pose_cells:
        filled[cells] = True
    total = int(env.grid.is_target.sum())
    return float((filled & env.grid.is_target).sum()) / total if total else 1.0


class Check(NamedTuple):
    success: bool
    reason: str = ''
    plan: object = None     # the motion plan the check found, when it planned one


def stability_check(env: AssemblyEnv):
    """A verify() for no-robot agents: would the action be valid now (geometry and
    physics, on the env's own cached stability check)? Acting is left to the env."""
    def check(action) -> Check:
        outcome, reason, _, _ = env.evaluate(action)
        return Check(outcome is None, reason)
    return check


def policy_decider(policy: Policy, actions: ActionSpace, verify=None) -> Decide:
    """decide() for the episode loop: the best-ranked action, or with verify
    (a GAMP check, `RobotAssemblyEnv.plan`) the best one it finds feasible,
    carrying its motion plan; nothing ranked (or feasible) means terminate."""
    def decide(env: AssemblyEnv, rng: np.random.Generator) -> Decision:
        ranked = ranked_actions(policy, env, actions(env), rng)
        if verify is None:
            return Decision(ranked[0]) if ranked else stop()
        action, plan, _ = first_feasible(env, ranked, verify)
        return Decision(action, plan) if action is not None else stop()
    return decide


def search_decider(policy: Policy, actions: ActionSpace, stepper, agent: Agent, verify=None) -> Decide:
    """decide() that searches before every decision (`Agent.search`) on `stepper`, the env
    that acts (RobotAssemblyEnv with the robot, the AssemblyEnv without); the search
    leaves it as it was. Unverified: the search's move. Verified: the best of the
    search's ranking that is known to work: a searched child whose simulated step
    succeeded needs no further check (it was a real step of the planning copy, GAMP
    and physics included; its motion plan is reused), an unsearched one is checked by
    simulating it (`simulated_check`); failed children are never taken."""
    from rad_core.sequencing.search import SEARCHES, EnvModel
    search = SEARCHES[agent.search]
    kwargs = {} if agent.epsilon is None else {'epsilon': agent.epsilon}
    check = simulated_check(stepper) if verify is not None else None

    def decide(env: AssemblyEnv, rng: np.random.Generator) -> Decision:
        if not actions(env):
            return stop()
        model = EnvModel(stepper, policy, actions)
        result = search(model, rng, budget=agent.budget, **kwargs)
        plans = {a: plan for (steps, a), plan in model.plans.items() if steps == env.state.steps}
        if verify is None:
            if result.action.is_terminate:
                return stop()
            return Decision(result.action, plans.get(result.action))
        worked = {c.action for c in result.children if not c.invalid}

        def known_or_simulated(action) -> Check:
            return Check(True, '', plans.get(action)) if action in worked else check(action)
        action, ok, _ = first_feasible(env, [a for a, _ in result.proposals()], known_or_simulated)
        return Decision(action, ok.plan) if action is not None else stop()
    return decide


def policy_order(policy: Policy, rng: np.random.Generator):
    """order(env, actions) for a search: all actions, best score first (ties keep their order)."""
    def order(env: AssemblyEnv, actions: list) -> list:
        scores = np.asarray(policy.scores(env, actions, rng), dtype=float)[:-1]
        return [actions[i] for i in np.argsort(-scores, kind='stable')]
    return order


def simulated_check(stepper):
    """A check that steps the action in a snapshot of the planning copy and goes back:
    success when the step is valid (with the robot: GAMP, execution and physics)."""
    def check(action) -> Check:
        snap = stepper.snapshot()
        try:
            result = stepper.step(action)
            plan = getattr(stepper, 'last_plan', None)
        finally:
            stepper.restore(snap)
        return Check(not result.outcome.is_invalid, result.reason, plan)
    return check


def scene_episode(agent: str | Agent, scene: Scene, robot: bool, seed: int, execution: str = 'teleport',
                  policy: Policy | None = None, allocation: AllocationParams | None = None,
                  stability=None, reallocation=None) -> dict:
    """One episode from the scene as given; the row `evaluate` reports for it.

    allocation: CP-SAT settings (default: 10 s, one worker, seed 0: deterministic
    unless the time limit cuts the search). stability: a shared no-robot
    stability check (one PyBullet client for a whole run); default: a fresh one.
    reallocation: a `ReallocationConfig` for agents that re-allocate (default: its defaults).
    """
    agent = get_agent(agent)
    with_robot = uses_robot(agent, robot)
    policy = policy if policy is not None else agent.make_policy()
    placements = solve(scene, allocation or AllocationParams(support=agent.support)).placements
    renv, own_stability = None, None
    if with_robot:
        from rad_core.robot_env import RobotAssemblyEnv, RobotEnvConfig
        renv = RobotAssemblyEnv(scene, RobotEnvConfig(execution=execution))
        env = renv.env
    else:
        if stability is None:
            from rad_core.physics import PhysicsStability
            stability = own_stability = PhysicsStability()
        env = AssemblyEnv(scene, EnvConfig(stability='physics'), stability=stability)
    try:
        guide = AllocationGuide(scene, placements, env.grid)
        opt = coverage_opt(env, guide)
        space = action_space(agent.actions, env, placements)
        verify = None
        if agent.verified:
            verify = renv.plan if with_robot else stability_check(env)
        if agent.search in ('exact', 'dfs'):
            decide, exact = exact_decider(renv, space, agent, policy if agent.search == 'dfs' else None,
                                          reallocation)
        elif agent.search:
            decide = search_decider(policy, space, renv if with_robot else env, agent, verify)
        else:
            decide = policy_decider(policy, space, verify)
        reallocator = None
        if agent.reallocate and agent.search not in ('exact', 'dfs'):
            from rad_core.sequencing.reallocation import ReallocationConfig, Reallocator, with_reallocation
            reallocator = Reallocator(space, simulated_check(renv) if with_robot else stability_check(env),
                                      reallocation or ReallocationConfig())
            decide = with_reallocation(decide, reallocator)
        act = (lambda d: renv.step(d.action, plan=d.plan)) if with_robot else None
        episode = run_episode(env, decide, np.random.default_rng(seed), act)
    finally:
        if renv is not None:
            renv.close()
        if own_stability is not None:
            own_stability.close()
    row = {**episode.row(), 'coverage_opt': opt}
    if with_robot:
        row['reason'] = episode.reason if episode.outcome.is_invalid else ''
    if reallocator is not None:
        row['reallocations'] = [e.to_dict() for e in reallocator.events]
        row['reallocation_s'] = reallocator.seconds
    if agent.search in ('exact', 'dfs'):
        found = exact['result']
        row.update(exact_coverage=found.coverage, exact_complete=found.complete, exact_bound=found.bound,
                   exact_states=found.states, exact_s=found.elapsed_s, exact_reason=found.reason)
    return row


def exact_decider(renv, space, agent: Agent, policy: Policy | None = None, reallocation=None):
    """decide() that plays the best line of the branch and bound (`sequencing.exact.exact_search`,
    with re-allocation at dead ends when the agent re-allocates), searched on the first call within
    `agent.time_limit_s`; and the dict that then holds its result. policy: the children's order
    (best score first; None: the search's default, most target cells then lowest first)."""
    from rad_core.sequencing.actions import AllocationActions
    from rad_core.sequencing.exact import exact_search
    from rad_core.sequencing.reallocation import ReallocationConfig, Reallocator
    if renv is None:
        raise RadError('the exact planner needs the robot (it searches with GAMP and physics)')
    config = reallocation or ReallocationConfig()
    env, holder = renv.env, {}

    def on_dead_end(_renv, current):
        # A copy of the line's space (its parent keeps its own), with the no-goods found on the line.
        sub = AllocationActions(env, current.guide.placements)
        reallocator = Reallocator(sub, simulated_check(renv), config)
        reallocator.no_goods = dict(getattr(current, 'no_goods', {}))
        event = reallocator.stalled(env, 'exact search: dead end')
        sub.no_goods = reallocator.no_goods
        return sub if event.changed else None

    def bound_of(_renv) -> float:   # re-allocating: what any allocation of the free cells could cover
        from rad_core.allocation.cpsat import coverage_bound
        from rad_core.sequencing.reallocation import placed_scene
        return coverage_bound(placed_scene(env))

    def decide(env_: AssemblyEnv, rng: np.random.Generator) -> Decision:
        if 'line' not in holder:
            holder['result'] = exact_search(renv, space, agent.time_limit_s,
                                            order=None if policy is None else policy_order(policy, rng),
                                            on_dead_end=on_dead_end if agent.reallocate else None,
                                            bound_of=bound_of if agent.reallocate else None)
            holder['line'] = list(holder['result'].actions)
        return Decision(holder['line'].pop(0)) if holder['line'] else stop()
    return decide, holder


def summarize(rows: list[dict]) -> dict:
    """The paper's numbers over episode rows (see `evaluate`)."""
    n = len(rows)
    if n == 0:
        raise RadError('no scenes to evaluate')
    returns = np.array([r['return'] for r in rows])
    outcomes = [Outcome(r['outcome']) for r in rows]

    def frac(pred) -> float:
        return sum(1 for o in outcomes if pred(o)) / n

    rel = [r['coverage'] / r['coverage_opt'] if r['coverage_opt'] > 0 else 1.0 for r in rows]
    return {
        'R': float(returns.mean()), 'R_std': float(returns.std()),
        'd': frac(lambda o: o == Outcome.COMPLETED),
        'e': frac(lambda o: o == Outcome.TERMINATED),
        'f': frac(lambda o: o.is_invalid),
        'f_g': frac(lambda o: o in FAIL_GRASP),
        'f_p': frac(lambda o: o in FAIL_PLACE),
        'coverage': float(np.mean([r['coverage'] for r in rows])),
        'coverage_rel': float(np.mean(rel)),
        'n': n,
        'scenes': rows,
    }


def evaluate(agent: str | Agent, scenes: Iterable[tuple[str, Scene]], robot: bool, seed: int,
             progress: Callable[[dict], None] | None = None, execution: str = 'teleport',
             policy: Policy | None = None, allocation: AllocationParams | None = None,
             reallocation=None) -> dict:
    """Run the agent once on every (name, scene); scene i seeds the policy with seed + i.

    Returns exactly KEYS: R, R_std (mean and std of the discounted return), d, e, f
    (fractions that ended completed / terminated / on an invalid action; the rest
    ran out of blocks), f_g, f_p (grasp / placement failures with the robot; a
    motion that moved another block counts as f_p), coverage (target-cell
    coverage, the paper's a-bar), coverage_rel (coverage over the allocation
    optimum's coverage, the paper's corrected a-bar), n, and scenes (one row each).
    progress(row) is called after each episode. policy: an already built policy
    (default: the agent's, built once for the run). allocation: CP-SAT settings,
    e.g. AllocationParams(support='stable') (default: the agent's, usually the paper's MILP).
    reallocation: the `ReallocationConfig` of re-allocating agents (default: its defaults).
    """
    agent = get_agent(agent)
    policy = policy if policy is not None else agent.make_policy()
    trained_on = getattr(policy, 'actions', agent.actions)
    if trained_on != agent.actions:
        raise RadError(f'{getattr(policy, "source", agent.name)} was trained on the {trained_on!r} action space; '
                       f'agent {agent.name!r} chooses among {agent.actions!r} (pick the agent of that method)')
    stability = None
    if not uses_robot(agent, robot):
        from rad_core.physics import PhysicsStability
        stability = PhysicsStability()
    rows = []
    try:
        for i, (name, scene) in enumerate(scenes):
            row = {'name': name, **scene_episode(agent, scene, robot, seed + i, execution, policy,
                                                 allocation=allocation, stability=stability,
                                                 reallocation=reallocation)}
            rows.append(row)
            if progress is not None:
                progress(row)
    finally:
        if stability is not None:
            stability.close()
    return summarize(rows)


# ---- where scenes come from, and progress ---------------------------------------
def generated_scenes(grid: int, sides: int, n: int, seed: int) -> Iterator[tuple[str, Scene]]:
    """n generator scenes with seeds seed .. seed + n - 1, made as they are needed."""
    from rad_core.generator import GeneratorConfig, generate_scene
    config = GeneratorConfig(grid=grid, sides=sides)
    config.validate()
    for s in range(seed, seed + n):
        yield f'g{grid}-sides{sides}-seed{s}', generate_scene(config, s)


def scene_dir(path: str | Path) -> list[tuple[str, Scene]]:
    """Every *.json in a folder, sorted by name, all read before any episode runs,
    so a bad file stops the run at once with its name."""
    folder = Path(path)
    if not folder.is_dir():
        raise RadError(f'scene folder {str(folder)!r} does not exist or is not a folder')
    files = sorted(folder.glob('*.json'))
    if not files:
        raise RadError(f'scene folder {str(folder)!r} holds no *.json files')
    scenes = []
    for f in files:
        try:
            scenes.append((f.stem, Scene.load(f)))
        except RadError as e:
            raise RadError(f'bad scene file {str(f)!r}: {e}') from None
    return scenes


class ProgressBar:
    """A one-line bar on a terminal (nothing when the stream is not one), so a
    long run shows it is alive without filling logs; no tqdm dependency."""

    def __init__(self, total: int, label: str = '', stream: TextIO | None = None, width: int = 30):
        self.total, self.label, self.width, self.done = max(total, 1), label, width, 0
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = hasattr(self.stream, 'isatty') and self.stream.isatty()
        self.t0 = time.perf_counter()

    def __call__(self, row: dict | None = None) -> None:
        self.done += 1
        if not self.enabled:
            return
        filled = self.width * self.done // self.total
        elapsed = time.perf_counter() - self.t0
        eta = elapsed / self.done * (self.total - self.done)
        self.stream.write(f'\r{self.label} [{"#" * filled}{"." * (self.width - filled)}] '
                          f'{self.done}/{self.total} {elapsed:.0f}s, ~{eta:.0f}s left ')
        if self.done >= self.total:
            self.stream.write('\n')
        self.stream.flush()

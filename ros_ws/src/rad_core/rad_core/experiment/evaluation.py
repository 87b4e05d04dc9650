"""The paper's evaluation (Sec. V, Tables I and II) for any agent: episodes and their metrics.

An agent is an `agents.AgentSpec` (scorer, search, verification, re-allocation,
allocation support; `rad_core.sequencing.decide.agents` has its text form and presets). Here it runs
episodes with the robot in the loop or without it.

With the robot, an episode is what the node graph does with the scene: the agent plans
it as /plan_assembly does (`sequencing.agent.agent_plan.AgentPlanner`: CP-SAT, the sequencer
and its search, GAMP; `plan_assembly`'s episode gives the return and the outcome), and the
plan is built in a fresh PyBullet twin (`sequencing.execution.twin_build`: teleporting, or the arm
simulated through /execute_assembly's loop); coverage is what the twin's registration
finds built. Unverified, the plan takes the best-ranked action blindly (the paper's agents:
one GAMP or the stability check refuses ends the episode with f_g / f_p); verified, the
best one GAMP finds feasible.

Without the robot (`AssemblyEnv` with physical stability, the paper's "HEUR wo robot"
oracle and Table I), the episode loop runs the agent's ranking, search and checks directly.

Nothing ranked (above terminating) means the termination action, as in the
paper. Every episode starts from the scene with a fresh CP-SAT allocation
(deterministic: one worker, fixed seed), and episode i gets the random
generator default_rng(seed + i), so a run is reproducible from (agent, scenes,
robot, seed). Every row and result records the agent's canonical text (`agent`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np

from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.coverage import measured_coverage, optimum_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.env.mdp import AssemblyEnv, EnvConfig, Outcome
from rad_core.sequencing.agent.agent_plan import AgentPlanner
from rad_core.sequencing.decide.actions import action_space
from rad_core.sequencing.decide.agents import SIMULATION_SEARCHES, AgentSpec, label, parse, parse_with_robot
from rad_core.sequencing.decide.deciders import policy_decider, search_decider, stability_check, with_fallbacks
from rad_core.sequencing.decide.episode import Episode, run_episode
from rad_core.sequencing.decide.policy import Policy
from rad_core.sequencing.execution.twin_build import build_simulated, build_teleported
from rad_core.sequencing.planning.reallocation import ReallocationConfig, Reallocator, with_reallocation
from rad_core.sim.physics import PhysicsStability

KEYS = ('agent', 'R', 'R_std', 'd', 'e', 'f', 'f_g', 'f_p', 'coverage', 'coverage_rel', 'n', 'scenes')
FAIL_GRASP = (Outcome.INVALID_GRASP,)
FAIL_PLACE = (Outcome.INVALID_PLACEMENT, Outcome.INVALID_DISTURBED)


@dataclass(frozen=True)
class Agent:
    """An `AgentSpec` ready to run episodes: its policy factory and what its parts imply here.

    name: the spec's canonical text (`agents.label`). robot: None follows `evaluate`'s robot
    flag; True / False whatever it says (legacy names fixed it; the branch and bound needs the
    robot). search: '' or a search of `sequencing.decide.search.SEARCHES`, with its budget (seconds for
    bnb). actions and support: the scorer's action space and the allocation it runs with (a
    model file records both).
    """

    name: str
    make_policy: Callable[[], Policy]
    robot: bool | None = None
    verified: bool = False
    actions: str = 'milp'
    support: str = 'none'
    search: str = ''
    budget: float = 5
    epsilon: float | None = None
    reallocate: bool = False

    @property
    def spec(self) -> AgentSpec:
        return parse(self.name)


def agent_from_spec(spec: AgentSpec, robot: bool | None = None) -> Agent:
    """The runnable agent of a spec (loads a network to read what its file records)."""
    policy = spec.make_policy() if spec.learned else None
    actions = getattr(policy, 'actions', 'milp')
    support = spec.resolved_support(policy)
    budget = spec.budget if spec.search else 5
    if spec.search == 'bnb':
        if robot is False:
            raise RadError(f'{label(spec)}: the branch and bound searches with GAMP and physics: it needs the robot')
        robot = True
    if spec.realloc and actions != 'milp':
        raise RadError(f'realloc applies to agents choosing among the allocation\'s actions, not {label(spec)!r} '
                       f'({actions!r})')

    def make_policy():
        return policy if policy is not None else spec.make_policy()
    return Agent(label(spec), make_policy, robot=robot, verified=spec.verify, actions=actions,
                 support=support, search=spec.search, budget=budget, reallocate=spec.realloc)


def get_agent(agent: str | AgentSpec | Agent, checkpoint: str | None = None, verify: bool = False,
              budget: int | None = None, reallocate: bool = False) -> Agent:
    """An agent by its text (`agents.parse`: a preset, scorer+parts, or a legacy name), spec or
    itself. The keyword arguments are the command line's older switches, applied on top:
    checkpoint replaces a learned agent's network by a model file; verify, budget and
    reallocate set those parts."""
    if isinstance(agent, Agent):
        return agent
    spec, robot = (agent, None) if isinstance(agent, AgentSpec) else parse_with_robot(agent)
    if checkpoint is not None:
        if not spec.learned:
            raise RadError(f'--checkpoint applies to learned agents (a network scorer), not {label(spec)!r}')
        spec = replace(spec, scorer=str(checkpoint))
    if budget is not None:
        if spec.search not in SIMULATION_SEARCHES:
            raise RadError(f'--budget applies to agents with a simulation search ({", ".join(SIMULATION_SEARCHES)}), '
                           f'not {label(spec)!r}')
        if budget < 1:
            raise RadError(f'--budget must be >= 1, got {budget}')
        spec = replace(spec, budget=budget)
    if verify:
        spec = replace(spec, verify=True)
    if reallocate:
        spec = replace(spec, realloc=True)
    return agent_from_spec(spec, robot)


def uses_robot(agent: str | AgentSpec | Agent, robot: bool) -> bool:
    """Whether the agent's episodes run with the robot, given the caller's flag."""
    agent = get_agent(agent)
    return robot if agent.robot is None else agent.robot


PLAN_TIME_LIMIT_S = 600.0
"""The longest an episode's plan may take with the robot (the branch and bound's searches included)."""


def robot_planner(agent: str | Agent, allocation: AllocationParams | None = None, reallocation=None,
                  effector: str = 'hand'):
    """The in-process planner of the agent's robot episodes (`AgentPlanner`: what /plan_assembly
    runs); allocation and reallocation as `scene_episode` takes them; effector: what the arm carries
    (`cell.panda.EFFECTORS`). Close it when done."""
    agent = get_agent(agent)
    return AgentPlanner(agent.spec, time_limit_s=PLAN_TIME_LIMIT_S, allocation=allocation, reallocation=reallocation,
                        policy=agent.make_policy(),     # the network get_agent loaded, not a second copy
                        effector=effector)


def scene_episode(agent: str | Agent, scene: Scene, robot: bool, seed: int, execution: str = 'teleport',
                  policy: Policy | None = None, allocation: AllocationParams | None = None,
                  stability=None, reallocation=None, planner=None) -> dict:
    """One episode from the scene as given; the row `evaluate` reports for it.

    allocation: CP-SAT settings (default: 10 s, one worker, seed 0: deterministic
    unless the time limit cuts the search). stability: a shared no-robot
    stability check (one PyBullet client for a whole run); default: a fresh one.
    reallocation: a `ReallocationConfig` for agents that re-allocate (default: its defaults).
    planner: with the robot, the `robot_planner` to plan with (default: a fresh one).
    """
    agent = get_agent(agent)
    if uses_robot(agent, robot):
        own = planner is None
        planner = planner if planner is not None else robot_planner(agent, allocation, reallocation)
        try:
            return robot_episode(planner, scene, seed, execution)
        finally:
            if own:
                planner.close()
    policy = policy if policy is not None else agent.make_policy()
    placements = solve(scene, allocation or AllocationParams(support=agent.support)).placements
    own_stability = None
    if stability is None:
        stability = own_stability = PhysicsStability()
    env = AssemblyEnv(scene, EnvConfig(stability='physics'), stability=stability)
    try:
        guide = AllocationGuide(scene, placements, env.grid)
        opt = optimum_coverage(env, guide)
        space = action_space(agent.actions, env, placements)
        check = stability_check(env) if agent.verified else None
        if agent.search:
            decide = search_decider(policy, space, env, agent.search, int(agent.budget), agent.epsilon, check)
        else:
            decide = policy_decider(policy, space, check)
        reallocator, decided = None, decide
        if agent.reallocate:
            reallocator = Reallocator(space, stability_check(env), reallocation or ReallocationConfig())
            decided = with_reallocation(decide, reallocator)
        if check is not None:
            decided = with_fallbacks(decide, decided)   # below stopping only where nothing else is left
        episode = run_episode(env, decided, np.random.default_rng(seed))
    finally:
        if own_stability is not None:
            own_stability.close()
    row = {**episode.row(), 'coverage_opt': opt}
    if reallocator is not None:
        row['reallocations'] = [e.to_dict() for e in reallocator.events]
        row['reallocation_s'] = reallocator.seconds
    return row


def robot_episode(planner, scene: Scene, seed: int, execution: str = 'teleport') -> dict:
    """The row of one robot episode: the planner's plan (seeded with `seed`), built in a fresh
    twin (`execution`: 'teleport' or 'simulate'). return, outcome: the plan's MDP episode;
    coverage: what the twin's registration finds built; predicted_coverage: what the plan
    expected; reason: why an invalid action failed; stop_reason: why the plan stopped short."""
    if execution == 'teleport':
        plan = planner(scene, None, seed)
        registered = build_teleported(scene, plan.steps, effector=planner.effector)
        coverage, lost, steps, replans = measured_coverage(registered.scene), registered.set_aside, len(plan.steps), 0
    elif execution == 'simulate':
        plans = []

        def plan_from(now: Scene, start):
            plans.append(planner(now, start, seed))
            return plans[-1]
        built = build_simulated(scene, plan_from, planner.motion, effector=planner.effector).result
        if not plans:
            raise RadError(f'execution ended before a plan was made: {built.reason}')
        plan = plans[0]
        coverage, lost, steps, replans = built.coverage, built.lost_blocks, len(built.steps), built.replans
    else:
        raise RadError(f"execution must be 'teleport' or 'simulate', got {execution!r}")
    episode = plan.episode or Episode(outcome=Outcome.TERMINATED, reason=plan.reason)
    invalid = episode.outcome is not None and episode.outcome.is_invalid
    row = {'return': episode.ret, 'outcome': (episode.outcome or Outcome.TERMINATED).value, 'coverage': coverage,
           'steps': steps, 'coverage_opt': _optimum(scene, plan.allocation),
           'predicted_coverage': plan.predicted_coverage, 'reason': episode.reason if invalid else '',
           'stop_reason': plan.reason, 'lost': dict(lost)}
    if execution == 'simulate':
        row['replans'] = replans
    if planner.spec.realloc:
        row['reallocations'] = [e.to_dict() for e in plan.reallocations]
        row['reallocation_s'] = plan.timings.get('reallocation', 0.0)
    return row


def _optimum(scene: Scene, allocation) -> float:
    """The coverage the allocation's poses would give, all built (0 without an allocation)."""
    if allocation is None or not allocation.has_solution:
        return 0.0
    env = AssemblyEnv(scene, EnvConfig(stability='none'))
    return optimum_coverage(env, AllocationGuide(scene, allocation.placements, env.grid))


def summarize(rows: list[dict], agent: str = '') -> dict:
    """The paper's numbers over episode rows (see `evaluate`); agent: its canonical text."""
    n = len(rows)
    if n == 0:
        raise RadError('no scenes to evaluate')
    returns = np.array([r['return'] for r in rows])
    outcomes = [Outcome(r['outcome']) for r in rows]

    def frac(pred) -> float:
        return sum(1 for o in outcomes if pred(o)) / n

    rel = [r['coverage'] / r['coverage_opt'] if r['coverage_opt'] > 0 else 1.0 for r in rows]
    return {
        'agent': agent,
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
             reallocation=None, effector: str = 'hand') -> dict:
    """Run the agent once on every (name, scene); scene i seeds the policy with seed + i.

    Returns exactly KEYS: agent (its canonical text, `agents.label`), R, R_std (mean and std
    of the discounted return), d, e, f (fractions that ended completed / terminated / on an invalid action; the rest
    ran out of blocks), f_g, f_p (grasp / placement failures with the robot; a
    motion that moved another block counts as f_p), coverage (target-cell
    coverage, the paper's a-bar), coverage_rel (coverage over the allocation
    optimum's coverage, the paper's corrected a-bar), n, and scenes (one row each).
    progress(row) is called after each episode. policy: an already built policy for runs
    without the robot (default: the agent's, built once for the run; with the robot the
    planner uses the agent's own). allocation: CP-SAT settings,
    e.g. AllocationParams(support='stable') (default: the agent's, usually the paper's MILP).
    reallocation: the `ReallocationConfig` of re-allocating agents (default: its defaults).
    effector: what the arm carries in robot runs (`cell.panda.EFFECTORS`): GAMP, the allocation and
    the twin all take it.
    """
    agent = get_agent(agent)
    with_robot = uses_robot(agent, robot)
    stability = planner = None
    if with_robot:
        planner = robot_planner(agent, allocation, reallocation, effector)
    else:
        policy = policy if policy is not None else agent.make_policy()
        trained_on = getattr(policy, 'actions', agent.actions)
        if trained_on != agent.actions:
            raise RadError(f'{getattr(policy, "source", agent.name)} was trained on the {trained_on!r} action space; '
                           f'agent {agent.name!r} chooses among {agent.actions!r} (pick the agent of that method)')
        stability = PhysicsStability()
    rows = []
    try:
        for i, (name, scene) in enumerate(scenes):
            row = {'name': name, **scene_episode(agent, scene, robot, seed + i, execution, policy,
                                                 allocation=allocation, stability=stability,
                                                 reallocation=reallocation, planner=planner)}
            rows.append(row)
            if progress is not None:
                progress(row)
    finally:
        if stability is not None:
            stability.close()
        if planner is not None:
            planner.close()
    return summarize(rows, agent.name)

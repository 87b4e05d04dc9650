"""An agent: what decides the next step of an assembly, as one value made of parts.

    scorer [+ search[:budget]] [+ verify] [+ realloc] [+ repair] [+ ceiling:S] [+ support:S]

- scorer: what ranks the allocation's actions. `heur` (the paper's heuristic), a
  shipped network by name (`milp-dqn-mixed`, `milp-dqn`, `dqn`, `dqn-rel`,
  `milp-dqn-robot`), or a model file (a path: it has a `/` or ends in `.pt`).
- search: a test-time search over the planning twin before every decision, with its
  budget per decision: `mcts` (the paper's MCTS), `halving` (sequential halving),
  `lookahead` (verified greedy with a look-ahead veto) in simulations (default 5, the
  paper's), or `bnb` (the branch and bound of `sequencing.decide.exact`) in seconds
  (default 10).
- verify: take the best-ranked action found feasible (with the robot: GAMP; without:
  the stability check), not the best-ranked one blindly (the paper's agents fail then).
- realloc: when nothing can be built next while allocated poses remain, exclude the
  poses that fail (no-goods) and solve the allocation again over the free cells.
- repair: order repair (needs verify). A plan that leaves cells unfilled because
  the arm hit a block the plan had placed earlier ('hand hits block b3') is planned
  again, trying last the actions that would place such a block while the cells it
  kept the arm from are still open (`allocation.order.Precedence`); the better plan
  is kept (`sequencing.agent.agent_plan.plan_for_agent`). It learns from GAMP, so it acts
  only with the robot in the loop; without it the agent plans as it would without repair.
- ceiling:S: where the plans leave target cells unfilled, spend up to S seconds on the
  robot-feasible ceiling's search (`sequencing.bounds.robot_ceiling.robot_ceiling`: the allocations' orders,
  then every pose) from the best plan's coverage, and plan the line it finds, kept where it
  fills more (needs verify; with the robot in the loop only). Time for coverage: off by default.
- support: the allocation's support rule, `none` (the paper's MILP), `stable`
  (every allocated block can rest on something), `arm` (stable, and nothing the
  arm can never do: no type the hand cannot take, no block it cannot pick, no pose
  out of reach; `allocation.arm`) or `hand` (arm, and an allocation a top-down hand
  can place in some order, `allocation.cpsat`); left out: the scorer's own (a model
  file records the allocation it was trained on; `none` for heur).

The text form is the value: `parse(label(a)) == a` for every agent, `label` prints
the canonical text that result documents record, and `rad eval --agent <that
text>` runs the same agent. Named presets stand for what people ask for (`PRESETS`);
`parse` also reads the names rad used before agents had parts (`LEGACY`), so old
result documents stay readable.

This module is pure: it imports neither torch nor pybullet, so a command line can
parse and print agents at once; `make_policy` loads a network when it is called.
"""

from __future__ import annotations

from dataclasses import dataclass

from rad_core.domain.errors import RadError
from rad_core.sequencing.decide.policy import HeurPolicy

SEARCHES = ('mcts', 'halving', 'lookahead', 'bnb')
SIMULATION_SEARCHES = ('mcts', 'halving', 'lookahead')
SUPPORTS = ('none', 'stable', 'arm', 'hand')
DEFAULT_BUDGET = {'mcts': 5, 'halving': 5, 'lookahead': 5, 'bnb': 10.0}
NETWORKS = ('milp-dqn', 'milp-dqn-mixed', 'milp-dqn-robot', 'dqn', 'dqn-rel')


@dataclass(frozen=True)
class AgentSpec:
    """An agent's parts (see the module docstring). budget: simulations per decision for
    mcts / halving / lookahead (an int), seconds per search for bnb; filled in with the
    search's default when left out, and only allowed with a search."""

    scorer: str = 'milp-dqn-mixed'
    search: str = ''
    budget: float | None = None
    verify: bool = False
    realloc: bool = False
    support: str | None = None
    repair: bool = False
    ceiling: float = 0.0
    """Seconds of the ceiling's search where cells are left (0: none)."""

    def __post_init__(self):
        if not isinstance(self.scorer, str) or not self.scorer or any(c in self.scorer for c in '+ \t\n'):
            raise RadError(f'an agent\'s scorer is heur, a network name or a model file path without "+" or '
                           f'spaces, got {self.scorer!r}')
        if self.search not in ('', *SEARCHES):
            raise RadError(f'unknown search {self.search!r}; one of {", ".join(SEARCHES)}')
        budget = self.budget
        if not self.search:
            if budget is not None:
                raise RadError(f'a budget ({budget:g}) needs a search ({", ".join(SEARCHES)})')
        else:
            if budget is None:
                budget = DEFAULT_BUDGET[self.search]
            if isinstance(budget, bool) or not isinstance(budget, (int, float)) or not budget > 0 \
                    or budget != budget or budget == float('inf'):
                raise RadError(f'the {self.search} budget must be a positive number, got {budget!r}')
            if self.search in SIMULATION_SEARCHES:
                if int(budget) != budget:
                    raise RadError(f'the {self.search} budget counts simulations: a whole number, got {budget!r}')
                budget = int(budget)
            else:
                budget = float(budget)
                if budget > 3600:
                    raise RadError(f'the bnb budget is seconds per search, under 3600, got {budget:g}')
            object.__setattr__(self, 'budget', budget)
        if self.support is not None and self.support not in SUPPORTS:
            raise RadError(f'unknown allocation support {self.support!r}; one of {", ".join(SUPPORTS)}')
        if self.search == 'bnb' and not self.verify:
            raise RadError('the bnb search plays only lines it verified: add +verify')
        if self.repair and not self.verify:
            raise RadError('order repair learns from the verified plan\'s refusals: add +verify')
        ceiling = self.ceiling
        if isinstance(ceiling, bool) or not isinstance(ceiling, (int, float)) or not 0 <= ceiling <= 3600:
            raise RadError(f'the ceiling part is seconds of search, 0 to 3600, got {ceiling!r}')
        object.__setattr__(self, 'ceiling', float(ceiling))
        if self.ceiling and not self.verify:
            raise RadError('the ceiling\'s line is planned as a verified plan: add +verify')

    # ---- what the parts imply -------------------------------------------------
    @property
    def learned(self) -> bool:
        return self.scorer != 'heur'

    def make_policy(self):
        """The scorer as a `Policy` (a network is loaded here; a bad file is a RadError naming it)."""
        if not self.learned:
            return HeurPolicy()
        from rad_core.learning.policy import QPolicy  # torch: only a learned scorer needs it
        return QPolicy.load(self.scorer)

    def resolved_support(self, policy=None) -> str:
        """The allocation support the agent runs with: its own, else the scorer's (a model file's
        `support`, 'none' for heur and for files that do not record one)."""
        if self.support is not None:
            return self.support
        if not self.learned:
            return 'none'
        policy = policy if policy is not None else self.make_policy()
        return getattr(policy, 'support', 'none')


def label(spec: AgentSpec) -> str:
    """The canonical text of an agent (what result documents record)."""
    parts = [spec.scorer]
    if spec.search:
        parts.append(f'{spec.search}:{spec.budget:g}')
    if spec.verify:
        parts.append('verify')
    if spec.realloc:
        parts.append('realloc')
    if spec.repair:
        parts.append('repair')
    if spec.ceiling:
        parts.append(f'ceiling:{spec.ceiling:g}')
    if spec.support is not None:
        parts.append(f'support:{spec.support}')
    return '+'.join(parts)


# Named agents for what people ask for. `default` is what the sequencer node and /plan_assembly
# run (the node graph always verifies with GAMP, re-allocates and allocates with support): the
# greedy mixed network with order repair, on an allocation the hand can place in some order
# (support:hand). Both parts raise coverage on g = 5, g = 6 and the hard shapes (docs/search.md).
# It has no look-ahead search: tried after the network's plan, that changed no plan's coverage in
# 111 measured and cost up to improve_time_s each time.
PRESETS = {
    'default': 'milp-dqn-mixed+verify+realloc+repair+support:hand',
    'greedy': 'milp-dqn-mixed+verify+realloc+support:arm',   # the network alone, verified
    'paper': 'milp-dqn+mcts:5+support:none',         # the paper's MILP-DQN-MCTS
    'heur': 'heur',                                   # the paper's HEUR
    'heur-verified': 'heur+verify',
    'exact': 'heur+bnb:60+verify+realloc+support:arm',   # the robot-feasible ceiling
}

# The names rad used before agents had parts: (text, robot), robot None = as the caller says.
LEGACY = {
    'heur-norobot': ('heur', False),
    'milp-dqn-mcts': ('milp-dqn+mcts:5', None),
    'milp-dqn-halving': ('milp-dqn+halving:5', None),
    'milp-dqn-lookahead': ('milp-dqn+lookahead:5', None),
    'milp-dqn-mixed-mcts': ('milp-dqn-mixed+mcts:5', None),
    'milp-dqn-mixed-halving': ('milp-dqn-mixed+halving:5', None),
    'milp-dqn-mixed-lookahead': ('milp-dqn-mixed+lookahead:5', None),
    'milp-dqn-robot-lookahead': ('milp-dqn-robot+lookahead:5', None),
    'milp-dqn-mixed-dfs': ('milp-dqn-mixed+bnb:10+verify', True),
}
# Before presets, these two names ran with the robot whatever the caller said.
LEGACY_ROBOT = {'heur-verified': True, 'exact': True}


def parse(text: str) -> AgentSpec:
    """The agent a text names: a preset, a legacy name, or `scorer+part+...` (module docstring).
    Legacy names may carry the old modifiers: `+verify`, `+realloc`, `+stable` and `@N` (budget)."""
    return parse_with_robot(text)[0]


def parse_with_robot(text: str) -> tuple[AgentSpec, bool | None]:
    """parse(), and whether the name fixes the robot (legacy names did: heur-norobot never used it,
    heur-verified, exact and milp-dqn-mixed-dfs always did); None: as the caller says."""
    if not isinstance(text, str) or not text.strip():
        raise RadError(f'an agent is a preset ({", ".join(PRESETS)}) or scorer+parts, got {text!r}')
    text = text.strip()
    head, *rest = text.split('+')
    robot = None
    budget_override = None
    if '@' in head and not ('/' in head or head.endswith('.pt')):
        head, _, n = head.partition('@')
        try:
            budget_override = float(n)
        except ValueError:
            raise RadError(f'bad budget {n!r} in agent {text!r}') from None
    if head in PRESETS:
        base = _parse_parts(PRESETS[head], text)
        robot = LEGACY_ROBOT.get(head)
    elif head in LEGACY:
        base_text, robot = LEGACY[head]
        base = _parse_parts(base_text, text)
    else:
        return _parse_parts(text, text), None
    spec = _apply(base, rest, text)
    if budget_override is not None:
        spec = AgentSpec(spec.scorer, spec.search, budget_override, spec.verify, spec.realloc, spec.support,
                         spec.repair, spec.ceiling)
    return spec, robot


def _parse_parts(text: str, whole: str) -> AgentSpec:
    head, *rest = text.split('+')
    if (head in PRESETS and head != 'heur') or head in LEGACY or not head:
        raise RadError(f'agent {whole!r}: {head!r} is not a scorer (heur, a network name or a model file)')
    if head != 'heur' and head not in NETWORKS and not ('/' in head or head.endswith('.pt')):
        raise RadError(f'unknown scorer {head!r} in agent {whole!r}: heur, a shipped network '
                       f'({", ".join(NETWORKS)}), a model file path, or a preset ({", ".join(PRESETS)})')
    return _apply(AgentSpec(head), rest, whole)


def _apply(spec: AgentSpec, parts: list[str], whole: str) -> AgentSpec:
    fields = {'scorer': spec.scorer, 'search': spec.search, 'budget': spec.budget, 'verify': spec.verify,
              'realloc': spec.realloc, 'support': spec.support, 'repair': spec.repair, 'ceiling': spec.ceiling}
    for part in parts:
        name, _, value = part.partition(':')
        if name in SEARCHES:
            if fields['search'] and fields['search'] != name:
                raise RadError(f'agent {whole!r} names two searches ({fields["search"]}, {name})')
            fields['search'] = name
            if value:
                try:
                    fields['budget'] = float(value)
                except ValueError:
                    raise RadError(f'bad {name} budget {value!r} in agent {whole!r}') from None
            elif fields['budget'] is None:
                fields['budget'] = None
        elif part in ('verify', 'realloc', 'repair'):
            fields[part] = True
        elif name == 'support' and value:
            fields['support'] = value
        elif name == 'ceiling' and value:
            try:
                fields['ceiling'] = float(value)
            except ValueError:
                raise RadError(f'bad ceiling seconds {value!r} in agent {whole!r}') from None
        elif part == 'stable':     # the old modifier
            fields['support'] = 'stable'
        else:
            raise RadError(f'unknown part {part!r} in agent {whole!r}: a search ({", ".join(SEARCHES)}, '
                           f'with :budget), verify, realloc, repair, ceiling:S or support:none|stable|arm|hand')
    return AgentSpec(**fields)

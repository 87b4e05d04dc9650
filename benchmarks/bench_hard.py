"""The hard hand-made cases (rad_core.domain.hard_shapes), robot in the loop: issue 17's shape target.

    python benchmarks/bench_hard.py [--agents TEXT,...] [--split holdout|train|all] [--limit N]
        [--seed 0] [--results DIR] [--force | --cached-only]

Every agent (a preset or an agent text, `rad_core.sequencing.decide.agents`) runs through
`rad_core.experiment.evaluation.evaluate` with the robot, the code behind `rad eval --robot`: it plans
each scene as /plan_assembly does and the plan is built in a fresh twin (teleporting
execution). The scenes are the split's cases at layout seed --seed (held-out cases by
default: the ones reported); --limit N takes the split's first N, for a smoke run.

Columns: a-bar (coverage of the whole target, the issue's figure), f (episodes that ended on
an invalid action: a grasp or placement GAMP refused or a block that fell), completed (d),
re-allocations per scene, seconds per scene, then each scene's coverage.

Writes <results>/hard.md and <results>/hard.rows.jsonl (results: docs/results by default;
hard-prefer-P.md and its rows with --prefer P);
results are cached per (agent, split, seed, limit) under out/cache/hard/; --force recomputes.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from common import RESULTS, cache_path, cached_evaluation, fmt, write_page
from rad_core.domain import hard_shapes
from rad_core.sequencing.decide.agents import parse

DEFAULT_AGENTS = ('default', 'milp-dqn-mixed+verify+realloc+support:stable', 'greedy', 'heur-verified')
ROW_KEYS = ('name', 'return', 'outcome', 'coverage', 'coverage_opt', 'steps', 'stop_reason')


def case_names(split: str, limit: int | None) -> list[str]:
    names = list(hard_shapes.CASES) if split == 'all' else list(hard_shapes.HARD_SPLITS[split])
    return names[:limit] if limit else names


def set_name(split: str, seed: int, limit: int | None) -> str:
    return f'hard-{split}-seed{seed}' + (f'-first{limit}' if limit else '')


def run(agent: str, split: str, seed: int, limit: int | None, force: bool, prefer: str = 'none') -> dict:
    """The agent's evaluation on the set, from the cache when there is one. prefer: a CP-SAT
    tie-break for the first allocation (`AllocationParams.prefer`; 'none': the agent's own)."""
    allocation = None
    if prefer != 'none':
        from rad_core.allocation import AllocationParams
        allocation = AllocationParams(support=parse(agent).support or 'stable', prefer=prefer)
    return cached_evaluation('hard', agent, cache_set(split, seed, limit, prefer),
                             lambda: [(name, hard_shapes.hard_scene(name, seed)) for name in case_names(split, limit)],
                             force, allocation=allocation)


def cache_set(split: str, seed: int, limit: int | None, prefer: str) -> str:
    """The cache's name for the set and the first allocation's tie-break."""
    return ('' if prefer == 'none' else f'prefer-{prefer}-') + set_name(split, seed, limit)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--agents', default=','.join(DEFAULT_AGENTS), help='presets or agent texts, comma-separated')
    p.add_argument('--split', default='holdout', choices=('holdout', 'train', 'all'))
    p.add_argument('--limit', type=int, default=None, help="only the split's first N cases (a smoke run)")
    p.add_argument('--seed', type=int, default=0, help='layout seed of every scene')
    p.add_argument('--results', default=str(RESULTS), help='folder of hard.md and hard.rows.jsonl')
    p.add_argument('--prefer', default='none', choices=('none', 'fewer', 'flat', 'open'),
                   help="a tie-break for every agent's first allocation (AllocationParams.prefer)")
    p.add_argument('--force', action='store_true')
    p.add_argument('--cached-only', action='store_true', help='only write the table from results already cached')
    args = p.parse_args()
    agents = [a for a in args.agents.split(',') if a]
    stem = 'hard' if args.prefer == 'none' else f'hard-prefer-{args.prefer}'   # the table a run writes
    names = case_names(args.split, args.limit)
    cell = set_name(args.split, args.seed, args.limit)
    results = []
    for agent in agents:
        if args.cached_only and not cache_path('hard', agent, cache_set(args.split, args.seed, args.limit,
                                                                        args.prefer)).exists():
            continue
        try:
            r = run(agent, args.split, args.seed, args.limit, args.force, args.prefer)
        except Exception as e:  # noqa: BLE001 - one agent's failure should not lose the others
            print(f'{agent} {cell}: {type(e).__name__}: {e}', file=sys.stderr)
            continue
        results.append((agent, r))
        per = ' '.join(f'{row["name"]}={row["coverage"]:.2f}' for row in r['scenes'])
        print(f'{agent:52s} {cell} cov={r["coverage"]:.3f} f={r["f"]:.2f} {r["seconds"] / r["n"]:.0f} s/scene  {per}',
              flush=True)
    headers = ['agent', 'canonical text', 'a-bar', 'f', 'd', 're-alloc/scene', 's/scene', *names]
    table, rows = [], []
    for agent, r in results:
        by_name = {row['name']: row for row in r['scenes']}
        events = np.mean([len(row.get('reallocations', ())) for row in r['scenes']])
        table.append([agent, f'`{r["agent"]}`', f'{r["coverage"]:.3f}', fmt(r['f']), fmt(r['d']), f'{events:.1f}',
                      f'{r["seconds"] / r["n"]:.0f}', *(fmt(by_name[n]['coverage']) if n in by_name else ''
                                                        for n in names)])
        rows += [{'agent': r['agent'], 'set': cell, **{k: row[k] for k in ROW_KEYS if k in row},
                  'reallocations': len(row.get('reallocations', ()))} for row in r['scenes']]
    note = (f'The {args.split} cases of `rad_core.domain.hard_shapes` ({len(names)} scenes, layout seed {args.seed}, '
            'what makes each hard: its docstrings); each agent plans as /plan_assembly does and the plan is built in '
            'a fresh twin (teleporting execution). a-bar: coverage of the whole target; f: episodes ended on a '
            'failed action; d: completed. s/scene: wall time on 2 shared cores.')
    page = write_page(stem, 'Hard hand-made shapes, robot in the loop', headers, table, note, rows,
                      results=args.results)
    print(f'wrote {page}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

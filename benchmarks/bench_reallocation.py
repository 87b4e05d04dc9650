"""Re-allocation on stall, the branch and bound and the robot-feasible ceiling, robot in the loop.

    python benchmarks/bench_reallocation.py [--scenes 30] [--grids 4,5] [--clearances 0]
        [--shapes holdout,tight] [--agents TEXT,...] [--ceiling-s 60] [--force | --cached-only]

Every agent (a preset or an agent text, `rad_core.sequencing.decide.agents`) runs through
`rad_core.experiment.evaluation.evaluate` with the robot, the code behind `rad eval --robot`: it plans
each scene as /plan_assembly does and the plan is built in a fresh twin (teleporting
execution). Scenes: generated two-sided scenes, seeds 0..N-1, and hand-made shape sets
('train', 'holdout', or 'tight': the held-out shapes with their blocks packed at least 2 cm apart,
2.5 cm on the layout's lattice).
The ceiling is `sequencing.bounds.robot_ceiling.robot_ceiling` (the branch and bound over orders and
re-allocations from the empty scene, the arm's allocation, the hand's, then every pose while time
is left, --ceiling-s per scene). Its rows say how each search ended (`proof`): 'bound',
the ceiling over every allocation (the best reached what any allocation could cover with poses the
arm might build); 'all poses', every sequence of those poses searched, the true ceiling too;
'exhausted', every order of the allocations searched (and their re-allocations at dead ends) tried
below that bound, the best found and not a proof over others; '' (cut), a lower bound. Its search starts
from the best coverage the agents' plans built on the scene (the incumbent: the robot is known to
reach it, moving blocks aside included, which the search's own steps do not do), so it prunes from
the start and ends at once where an agent reached the bound; --no-incumbent searches from nothing.

Columns: coverage of the whole target, f (episodes ended on a failed action), how many ceilings
are known and cut, the ceiling minus the agent on the scenes where it is known, re-allocations per
scene.

Writes one page, docs/results/<--name>.md (ceiling by default), and its rows (`common.write_page`):
one table, a line per (scene set, agent) and one for the ceiling, made from the rows, so
`--from-rows` rebuilds the page from a rows file without running anything. Results are cached per
(agent, scene set) under out/cache/reallocation/; --force recomputes.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from common import (
    RESULTS,
    cache_dir,
    cache_path,
    cached_evaluation,
    page_meta,
    read_rows,
    scenes,
    shape_scenes,
    write_page,
)

DEFAULT_AGENTS = ('heur-verified', 'heur+verify+support:stable', 'heur+verify+realloc', 'milp-dqn+mcts:5+verify',
                  'milp-dqn+mcts:5+verify+realloc', 'milp-dqn-mixed+verify+support:stable', 'greedy',
                  'milp-dqn-mixed+lookahead:5+verify+support:stable', 'default',
                  'milp-dqn-mixed+bnb:10+verify+support:stable', 'milp-dqn-mixed+bnb:10+verify+realloc+support:stable',
                  'exact')
ROW_KEYS = ('name', 'return', 'outcome', 'coverage', 'predicted_coverage', 'coverage_opt', 'steps', 'stop_reason')


def cell_scenes(grid, n: int, clearance: float):
    """A cell's scenes: generated at grid g (an int), or a shape split (a str)."""
    return scenes(grid, n, clearance) if isinstance(grid, int) else shape_scenes(grid)


def cell_name(grid, n: int, clearance: float) -> str:
    return f'g{grid}-c{clearance:g}-n{n}' if isinstance(grid, int) else f'shapes-{grid}'


# How a ceiling's search ended (`ExactResult.proof`), in words.
ENDED = {'bound': 'at its bound', 'all poses': 'exhausted over every pose', 'exhausted': 'exhausted below its bound',
         '': 'lower bound (cut)'}


def run(agent: str, grid, n: int, clearance: float, force: bool) -> dict:
    return cached_evaluation('reallocation', agent, cell_name(grid, n, clearance),
                             lambda: cell_scenes(grid, n, clearance), force)


def ceiling(grid, n: int, clearance: float, seconds: float, force: bool, incumbents=None) -> list[dict]:
    """Per scene: the robot-feasible ceiling's coverage, whether it is proven, its states and time.
    incumbents: per scene, the best coverage an agent built there (the search's incumbent)."""
    from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling
    tag = ('-inc' if incumbents is not None else '') + '-proof2'   # rows with 'proof' and 'bound', every pose searched
    path = cache_dir('reallocation') / f'ceiling-{seconds:g}s{tag}-{cell_name(grid, n, clearance)}.json'
    if path.exists() and not force:
        return json.loads(path.read_text())
    out = []
    for k, (name, scene) in enumerate(cell_scenes(grid, n, clearance)):
        known = float(incumbents[k]) if incumbents is not None else 0.0
        found = robot_ceiling(scene, seconds, incumbent=known)
        out.append({'name': name, 'coverage': found.coverage, 'complete': found.complete, 'proof': found.proof,
                    'bound': found.bound, 'states': found.states, 'seconds': found.elapsed_s,
                    'reason': found.reason, 'incumbent': known})
        print(f'ceiling {name}: {found.coverage:.3f} {ENDED[found.proof]} (bound {found.bound:.3f}, '
              f'{found.states} states, {found.elapsed_s:.0f} s)', flush=True)
    path.write_text(json.dumps(out))
    return out


HEADERS = ('scene set', 'agent', 'scenes', 'coverage', 'f', 'ceiling known', 'cut', 'below the known ceiling',
           're-alloc/scene')
NOTE = ('Each agent plans as /plan_assembly does and the plan is built in a fresh twin (teleporting execution); '
        'f: episodes ended on a failed action. The ceiling (`robot_ceiling`: the allocations\' orders, then every '
        'pose, bounded by what a cover with an order the hand can keep could fill) is known where its search '
        'ended; "below the known ceiling" is its mean lead over the agent on those scenes. A search cut by the '
        'time limit is a lower bound, left out.')
FAILED = ('invalid_placement', 'invalid_grasp', 'invalid_unstable')


def table(rows: list[dict]) -> list[list]:
    """The page's table from the rows: per scene set, a line per agent, then the ceiling's."""
    sets = list(dict.fromkeys(r['set'] for r in rows))
    out = []
    for cell in sets:
        here = [r for r in rows if r['set'] == cell]
        roof = {r['name']: r for r in here if r['agent'] == 'ceiling'}
        known = {n: c for n, c in roof.items() if c.get('complete')}
        for agent in dict.fromkeys(r['agent'] for r in here if r['agent'] != 'ceiling'):
            mine = [r for r in here if r['agent'] == agent]
            gaps = [known[r['name']]['coverage'] - r['coverage'] for r in mine if r['name'] in known]
            out.append([cell, f'`{agent}`', len(mine), f'{np.mean([r["coverage"] for r in mine]):.3f}',
                        f'{np.mean([r.get("outcome") in FAILED for r in mine]):.2f}', '', '',
                        f'{np.mean(gaps):.4f}' if gaps else '',
                        f'{np.mean([r.get("reallocations", 0) for r in mine]):.1f}'])
        if roof:
            cut = sum(1 for c in roof.values() if not c.get('proof'))
            out.append([cell, 'ceiling', len(roof), f'{np.mean([c["coverage"] for c in roof.values()]):.3f}', '',
                        f'{len(known)} of {len(roof)}', cut, '', ''])
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=30)
    p.add_argument('--grids', default='4,5')
    p.add_argument('--clearances', default='0')
    p.add_argument('--shapes', default='holdout,tight', help="hand-made shape sets too: train,holdout,tight")
    p.add_argument('--agents', default=','.join(DEFAULT_AGENTS), help='presets or agent texts, comma-separated')
    p.add_argument('--ceiling-s', type=float, default=60.0, help='seconds per scene of the ceiling; 0: none')
    p.add_argument('--no-incumbent', dest='incumbent', action='store_false',
                   help="the ceiling's search starts from nothing, not from the agents' best built coverage")
    p.add_argument('--force', action='store_true')
    p.add_argument('--results', default=str(RESULTS), help='folder of the page and its rows')
    p.add_argument('--name', default='ceiling', help='the page: <results>/<name>.md and <name>.rows.jsonl')
    p.add_argument('--cached-only', action='store_true', help='only write the table from results already cached')
    p.add_argument('--from-rows', type=Path, help='rebuild the page from this rows file, running nothing')
    p.add_argument('--command', help='with --from-rows: the command that measured them (default: the page says)')
    p.add_argument('--commit', help='with --from-rows: the commit that measured them (default: the page says)')
    p.add_argument('--date', help='with --from-rows: the date of that run (default: what the page states)')
    args = p.parse_args()
    out = Path(args.results)
    if args.from_rows:
        rows = read_rows(args.from_rows)
        meta = page_meta(out / f'{args.name}.md')
        page = write_page(args.name, TITLE, HEADERS, table(rows), NOTE, rows, results=out,
                          **{k: getattr(args, k) or meta.get(k) for k in ('command', 'commit', 'date')})
        print(f'wrote {page}')
        return 0
    grids = [int(g) for g in args.grids.split(',') if g] + [s for s in args.shapes.split(',') if s]
    clearances = [float(c) for c in args.clearances.split(',')]
    agents = [a for a in args.agents.split(',') if a]
    rows = []
    for clearance in clearances:
        for grid in grids:
            if not isinstance(grid, int) and clearance != clearances[0]:
                continue   # the shapes are flush
            cell = cell_name(grid, args.scenes, clearance)
            results = []
            for agent in agents:
                if args.cached_only and not cache_path('reallocation', agent, cell).exists():
                    continue
                try:
                    results.append((agent, run(agent, grid, args.scenes, clearance, args.force)))
                except Exception as e:  # noqa: BLE001 - one agent's failure should not lose the others
                    print(f'{agent} {cell}: {type(e).__name__}: {e}', file=sys.stderr)
            roof = None
            if args.ceiling_s > 0 and not args.cached_only:
                # The agents' plans, built in the twin, are what the robot is known to reach: the
                # ceiling's search starts from the best of them (--no-incumbent: from nothing).
                incumbents = None
                if results and args.incumbent:
                    incumbents = [max(r['scenes'][k]['coverage'] for _, r in results)
                                  for k in range(len(results[0][1]['scenes']))]
                roof = ceiling(grid, args.scenes, clearance, args.ceiling_s, args.force, incumbents)
            for agent, r in results:
                rows += [{'agent': r['agent'], 'set': cell, **{k: row[k] for k in ROW_KEYS if k in row},
                          'reallocations': len(row.get('reallocations', ()))} for row in r['scenes']]
                print(f'{agent:52s} {cell} cov={r["coverage"]:.3f}', flush=True)
            if roof is not None:
                rows += [{'agent': 'ceiling', 'set': cell, **c} for c in roof]
            page = write_page(args.name, TITLE, HEADERS, table(rows), NOTE, rows, results=out)
    print(f'wrote {page}')
    return 0


TITLE = 'The robot-feasible ceiling and re-allocation, robot in the loop'

if __name__ == '__main__':
    raise SystemExit(main())

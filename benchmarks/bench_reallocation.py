"""Re-allocation on stall, the branch and bound and the robot-feasible ceiling, robot in the loop.

    python benchmarks/bench_reallocation.py [--scenes 30] [--grids 4,5] [--clearances 0]
        [--shapes holdout,tight] [--agents TEXT,...] [--ceiling-s 60] [--force | --cached-only]

Every agent (a preset or an agent text, `rad_core.agents`) runs through
`rad_core.evaluation.evaluate` with the robot, the code behind `rad eval --robot`: it plans
each scene as /plan_assembly does and the plan is built in a fresh twin (teleporting
execution). Scenes: generated two-sided scenes, seeds 0..N-1, and hand-made shape sets
('train', 'holdout', or 'tight': the held-out shapes with their blocks packed at least 2 cm apart,
2.5 cm on the layout's lattice).
The ceiling is `sequencing.exact.robot_ceiling` (the branch and bound over orders and
re-allocations from the empty scene, the arm's allocation, the hand's, then every pose while time
is left, --ceiling-s per scene). Its rows say how each search ended (`proof`): 'bound',
the ceiling over every allocation (the best reached what any allocation could cover with poses the
arm might build); 'all poses', every sequence of those poses searched, the true ceiling too;
'exhausted', every order of the allocations searched (and their re-allocations at dead ends) tried
below that bound, the best found and not a proof over others; '' (cut), a lower bound. Its search starts
from the best coverage the agents' plans built on the scene (the incumbent: the robot is known to
reach it, moving blocks aside included, which the search's own steps do not do), so it prunes from
the start and ends at once where an agent reached the bound; --no-incumbent searches from nothing.

Columns: the paper's metrics, a-bar (coverage of the whole target), 'of paper' (coverage
over what the paper's unconstrained allocation fills), 'to ceiling' (the ceiling's
coverage minus the agent's, on the scenes where the ceiling's search is complete), re-allocations
per scene and the share of episode time spent re-allocating (checks + CP-SAT).

Writes docs/results/reallocation.md and docs/results/reallocation.rows.jsonl; results are
cached per (agent, scene set) under out/cache/reallocation/; --force recomputes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from rad_core.allocation import AllocationParams, solve

from common import (RESULTS, agent_legend, cache_dir, cache_path, cached_evaluation, command_line, fmt, scenes,
                    shape_scenes, write_rows)

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
    from rad_core.sequencing.exact import robot_ceiling
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


def paper_fill(grid, n: int, clearance: float) -> list[float]:
    """Per scene: the target fraction the paper's unconstrained allocation fills."""
    path = cache_dir('reallocation') / f'paper-fill-{cell_name(grid, n, clearance)}.json'
    if path.exists():
        return json.loads(path.read_text())
    from rad_core.coverage import placements_coverage
    out = [placements_coverage(scene, solve(scene, AllocationParams()).placements)
           for _, scene in cell_scenes(grid, n, clearance)]
    path.write_text(json.dumps(out))
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
    p.add_argument('--results', default=str(RESULTS),
                   help='folder of reallocation.md and its rows (a run of a few agents elsewhere keeps the full table)')
    p.add_argument('--cached-only', action='store_true', help='only write the table from results already cached')
    args = p.parse_args()
    out = Path(args.results)
    grids = [int(g) for g in args.grids.split(',') if g] + [s for s in args.shapes.split(',') if s]
    clearances = [float(c) for c in args.clearances.split(',')]
    agents = [a for a in args.agents.split(',') if a]
    lines = ['# Re-allocation on stall, the branch and bound and the robot-feasible ceiling', '',
             f'Made by `{command_line()}` ({time.strftime("%Y-%m-%d")}). Generated two-sided scenes, seeds '
             f'0..{args.scenes - 1}, and hand-made shapes; each agent plans as /plan_assembly does and the plan is '
             'built in a fresh twin (teleporting execution); see the benchmark\'s docstring for the columns. '
             's/scene: wall time on the shared 2-core machine. Per-scene rows: '
             '[reallocation.rows.jsonl](reallocation.rows.jsonl).', ''] + agent_legend(agents)
    rows = []
    for clearance in clearances:
        for grid in grids:
            if not isinstance(grid, int) and clearance != clearances[0]:
                continue   # the shapes are flush
            cell = cell_name(grid, args.scenes, clearance)
            fill = paper_fill(grid, args.scenes, clearance)
            title = (f'## g = {grid}, clearance {clearance:g}' + (' (flush)' if not clearance else '')
                     if isinstance(grid, int) else f'## shapes: {grid}')
            lines += [title, '',
                      f'The paper\'s allocation fills {np.mean(fill):.3f} of the target on average.', '',
                      '| agent | R | e | f | a-bar | of paper | to ceiling | re-alloc/scene | re-alloc time '
                      '| s/scene |',
                      '|---|---|---|---|---|---|---|---|---|---|']
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
                scene_rows = r['scenes']
                rows += [{'agent': r['agent'], 'set': cell, **{k: row[k] for k in ROW_KEYS if k in row},
                          'reallocations': len(row.get('reallocations', ()))} for row in scene_rows]
                of_paper = np.mean([row['coverage'] / f if f > 0 else 1.0 for row, f in zip(scene_rows, fill)])
                gap = None
                if roof is not None:
                    done = [(c['coverage'], row['coverage']) for c, row in zip(roof, scene_rows) if c['complete']]
                    gap = float(np.mean([a - b for a, b in done])) if done else None
                events = [len(row.get('reallocations', ())) for row in scene_rows]
                share = sum(row.get('reallocation_s', 0.0) for row in scene_rows) / max(r['seconds'], 1e-9)
                lines.append(f'| {agent} | {fmt(r["R"])} | {fmt(r["e"])} | {fmt(r["f"])} | {fmt(r["coverage"])} '
                             f'| {of_paper:.3f} | {fmt(gap)} | {np.mean(events):.1f} | {share:.0%} '
                             f'| {r["seconds"] / r["n"]:.1f} |')
                print(f'{agent:52s} {cell} cov={r["coverage"]:.3f} of_paper={of_paper:.3f} '
                      f'gap={fmt(gap)} realloc={np.mean(events):.1f} share={share:.0%}', flush=True)
            if roof is not None:
                ended = {k: sum(1 for c in roof if c.get('proof', '') == k) for k in ENDED}
                lines.append(f'| ceiling ({args.ceiling_s:g} s) | | | | {fmt(np.mean([c["coverage"] for c in roof]))} '
                             f'| | | | | {np.mean([c["seconds"] for c in roof]):.1f} |')
                lines += ['', f'Of {len(roof)} scenes, the ceiling is at its bound on {ended["bound"]} and '
                          f'exhausted over every pose on {ended["all poses"]} (the true ceiling, both); exhausted '
                          f'below its bound on {ended["exhausted"]} (the best found: not a proof over others), cut '
                          f'on {ended[""]} (lower bounds, left out of "to ceiling").']
                if any(c.get('incumbent') for c in roof):
                    better = sum(1 for c in roof if c['coverage'] > c['incumbent'] + 1e-9)
                    lines += ['', f'Its search started from the best agent\'s built coverage on each scene (the '
                              f'incumbent); it found a better line on {better} of them.']
                rows += [{'agent': 'ceiling', 'set': cell, **c} for c in roof]
            lines.append('')
            out.mkdir(parents=True, exist_ok=True)
            (out / 'reallocation.md').write_text('\n'.join(lines) + '\n')
            write_rows(out / 'reallocation.rows.jsonl', rows)
    print(f'wrote {out / "reallocation.md"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

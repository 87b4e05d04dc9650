"""The paper's Table II (robot in the loop) for every sequencer, on both geometries.

    python benchmarks/bench_table2.py [--scenes 30] [--grids 4,5] [--clearances 0,0.2]
        [--agents heur,heur-verified,...] [--force] [--out docs/results/table2.md]

Each agent runs with the robot (GAMP + twin, teleporting execution) on the same
generated two-sided scenes, seeds 0..N-1 (never used in training), through
`rad_core.evaluation.evaluate`, the code behind `rad eval`. Geometry: clearance 0
is rad's flush blocks; clearance > 0 makes every block smaller than its cells on
the sides (the predecessor's robot scenes leave 1 cm between neighbours: 0.2 of a
5 cm unit), set through the generator. Agents ending in +verify take the best
action of their ranking that GAMP finds feasible from the current state (no f_g /
f_p by construction); the search agents spend `budget` real planning-twin steps
per decision. Results are cached per (agent, grid, clearance, N) as JSON beside the
table, so an interrupted run resumes; --force recomputes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from rad_core import jsonfmt
from rad_core.evaluation import evaluate, get_agent
from rad_core.progress import ProgressBar

from common import fmt, scenes

ROOT = Path(__file__).resolve().parents[1]
PAPER = {   # Table II of the paper (two-sided, robot in the loop); absent keys are not reported
    (4, 'heur'): {'R': 0.57, 'e': 0.36, 'f_g': 0.24, 'f_p': 0.16, 'coverage': 0.62},
    (4, 'milp-dqn'): {'R': 1.03, 'e': 0.49, 'f_g': 0.08, 'f_p': 0.08, 'coverage': 0.70},
    (4, 'milp-dqn-mcts'): {'R': 1.24, 'e': 0.57, 'f_g': 0.02, 'f_p': 0.03, 'coverage': 0.75},
    (5, 'heur'): {'R': 0.34, 'e': 0.29, 'f_g': 0.34, 'f_p': 0.24, 'coverage': 0.47},
    (5, 'milp-dqn'): {'R': 0.98, 'e': 0.53, 'f_g': 0.10, 'f_p': 0.15, 'coverage': 0.58},
    (5, 'milp-dqn-mcts'): {'R': 1.38, 'e': 0.65, 'f_g': 0.02, 'f_p': 0.06, 'coverage': 0.65},
}
DEFAULT_AGENTS = ('heur', 'heur-verified', 'milp-dqn', 'milp-dqn+verify', 'milp-dqn-mcts', 'milp-dqn-mcts+verify',
                  'milp-dqn-halving+verify', 'milp-dqn-lookahead+verify', 'milp-dqn-mixed+verify',
                  'milp-dqn-mixed-mcts+verify', 'milp-dqn-mixed-halving+verify', 'milp-dqn-mixed-lookahead+verify',
                  'milp-dqn-robot+verify', 'milp-dqn-robot-lookahead+verify')
COLS = ('R', 'd', 'e', 'f', 'f_g', 'f_p', 'coverage', 'coverage_rel')
HEADS = {'coverage': 'a-bar', 'coverage_rel': 'a_rel'}


def agent_of(label: str):
    name, _, suffix = label.partition('+')
    return get_agent(name, verify=suffix == 'verify')


def run(label: str, grid: int, n: int, clearance: float, cache: Path, force: bool) -> dict:
    path = cache / f'{label}-g{grid}-c{clearance:g}-n{n}.json'
    if path.exists() and not force:
        return json.loads(path.read_text())
    agent = agent_of(label)
    t0 = time.perf_counter()
    result = evaluate(agent, scenes(grid, n, clearance), robot=True, seed=0,
                      progress=ProgressBar(n, f'{label} g={grid} c={clearance:g}'))
    result['seconds'] = time.perf_counter() - t0
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(jsonfmt.dumps(result))
    return result


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=30)
    p.add_argument('--grids', default='4,5')
    p.add_argument('--clearances', default='0,0.2')
    p.add_argument('--agents', default=','.join(DEFAULT_AGENTS))
    p.add_argument('--force', action='store_true')
    p.add_argument('--out', default=str(ROOT / 'docs' / 'results' / 'table2.md'))
    args = p.parse_args()
    out = Path(args.out)
    cache = out.parent / 'table2'
    grids = [int(g) for g in args.grids.split(',')]
    clearances = [float(c) for c in args.clearances.split(',')]
    labels = [a for a in args.agents.split(',') if a]
    lines = ['# Table II: the robot in the loop', '',
             f'Generated two-sided scenes, seeds 0..{args.scenes - 1} per grid size, teleporting execution; '
             '`python benchmarks/bench_table2.py` (see its docstring). Paper rows from its Table II '
             '(flush is not the paper\'s geometry: its blocks leave 1 cm between neighbours, clearance 0.2). '
             's/scene is wall time on a shared 2-core machine whose load varied between rows: compare it '
             'within a row\'s own run only.', '']
    for clearance in clearances:
        for grid in grids:
            lines += [f'## g = {grid}, clearance {clearance:g}' + (' (flush)' if not clearance else ''), '',
                      '| agent | ' + ' | '.join(HEADS.get(c, c) for c in COLS) + ' | s/scene |',
                      '|---|' + '---|' * (len(COLS) + 1)]
            for label in labels:
                try:
                    r = run(label, grid, args.scenes, clearance, cache, args.force)
                except Exception as e:  # noqa: BLE001 - one agent's failure should not lose the others
                    print(f'{label} g={grid} c={clearance}: {type(e).__name__}: {e}', file=sys.stderr)
                    continue
                lines.append(f'| {label} | ' + ' | '.join(fmt(r.get(c)) for c in COLS)
                             + f' | {r["seconds"] / r["n"]:.1f} |')
                print(f'{label:32s} g={grid} c={clearance:g} ' + ' '.join(f'{c}={fmt(r.get(c))}' for c in COLS),
                      flush=True)
                paper = PAPER.get((grid, label))
                if paper and clearance:
                    lines.append(f'| {label} (paper) | ' + ' | '.join(fmt(paper.get(c)) for c in COLS) + ' | |')
            lines.append('')
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text('\n'.join(lines) + '\n')
    print(f'wrote {out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

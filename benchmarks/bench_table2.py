"""The paper's Table II (robot in the loop) for any agents, on both geometries.

    python benchmarks/bench_table2.py [--scenes 30] [--grids 4,5] [--clearances 0,0.2]
        [--agents heur,heur-verified,paper,greedy,default] [--force]

Each agent (a preset or any agent text, `rad_core.agents`) runs with the robot on the
same generated two-sided scenes, seeds 0..N-1 (never used in training), through
`rad_core.evaluation.evaluate`, the code behind `rad eval --robot`: the agent plans each
scene as /plan_assembly does (CP-SAT, the sequencer and its search, GAMP) and the plan is
built in a fresh PyBullet twin (teleporting execution); coverage is what the twin's
registration finds built. Geometry: clearance 0 is rad's flush blocks; clearance > 0
makes every block smaller than its cells on the sides (the predecessor's robot scenes
leave 1 cm between neighbours: 0.2 of a 5 cm unit). Verified agents take the best action
of their ranking that GAMP finds feasible (no f_g / f_p by construction).

Writes docs/results/table2.md (the tables and this command) and docs/results/table2.rows.jsonl
(one line per agent and scene). Results are cached per (agent, grid, clearance, N) under
out/cache/table2/, so an interrupted run resumes; --force recomputes.
"""

from __future__ import annotations

import argparse
import sys
import time


from common import RESULTS, agent_legend, cached_evaluation, command_line, fmt, scenes, write_rows

PAPER = {   # Table II of the paper (two-sided, robot in the loop); absent keys are not reported
    (4, 'heur'): {'R': 0.57, 'e': 0.36, 'f_g': 0.24, 'f_p': 0.16, 'coverage': 0.62},
    (4, 'milp-dqn'): {'R': 1.03, 'e': 0.49, 'f_g': 0.08, 'f_p': 0.08, 'coverage': 0.70},
    (4, 'paper'): {'R': 1.24, 'e': 0.57, 'f_g': 0.02, 'f_p': 0.03, 'coverage': 0.75},
    (5, 'heur'): {'R': 0.34, 'e': 0.29, 'f_g': 0.34, 'f_p': 0.24, 'coverage': 0.47},
    (5, 'milp-dqn'): {'R': 0.98, 'e': 0.53, 'f_g': 0.10, 'f_p': 0.15, 'coverage': 0.58},
    (5, 'paper'): {'R': 1.38, 'e': 0.65, 'f_g': 0.02, 'f_p': 0.06, 'coverage': 0.65},
}
DEFAULT_AGENTS = ('heur', 'heur-verified', 'milp-dqn', 'paper', 'greedy', 'default')
COLS = ('R', 'd', 'e', 'f', 'f_g', 'f_p', 'coverage', 'coverage_rel')
HEADS = {'coverage': 'a-bar', 'coverage_rel': 'a_rel'}
ROW_KEYS = ('name', 'return', 'outcome', 'coverage', 'predicted_coverage', 'coverage_opt', 'steps', 'reason',
            'stop_reason', 'lost')


def run(agent: str, grid: int, n: int, clearance: float, force: bool) -> dict:
    return cached_evaluation('table2', agent, f'g{grid}-c{clearance:g}-n{n}', lambda: scenes(grid, n, clearance),
                             force)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=30)
    p.add_argument('--grids', default='4,5')
    p.add_argument('--clearances', default='0,0.2')
    p.add_argument('--agents', default=','.join(DEFAULT_AGENTS), help='presets or agent texts, comma-separated')
    p.add_argument('--force', action='store_true')
    args = p.parse_args()
    grids = [int(g) for g in args.grids.split(',')]
    clearances = [float(c) for c in args.clearances.split(',')]
    agents = [a for a in args.agents.split(',') if a]
    lines = ['# Table II: the robot in the loop', '',
             f'Made by `{command_line()}` ({time.strftime("%Y-%m-%d")}). Generated two-sided scenes, seeds '
             f'0..{args.scenes - 1} per grid size; each agent plans as /plan_assembly does and the plan is built '
             'in a fresh twin (teleporting execution). Paper rows from its Table II (flush is not the paper\'s '
             'geometry: its blocks leave 1 cm between neighbours, clearance 0.2). s/scene is wall time on a shared '
             '2-core machine: compare it within one run only. Per-scene rows: [table2.rows.jsonl](table2.rows.jsonl).',
             ''] + agent_legend(agents)
    rows = []
    for clearance in clearances:
        for grid in grids:
            lines += [f'## g = {grid}, clearance {clearance:g}' + (' (flush)' if not clearance else ''), '',
                      '| agent | ' + ' | '.join(HEADS.get(c, c) for c in COLS) + ' | s/scene |',
                      '|---|' + '---|' * (len(COLS) + 1)]
            for agent in agents:
                try:
                    r = run(agent, grid, args.scenes, clearance, args.force)
                except Exception as e:  # noqa: BLE001 - one agent's failure should not lose the others
                    print(f'{agent} g={grid} c={clearance}: {type(e).__name__}: {e}', file=sys.stderr)
                    continue
                rows += [{'agent': r['agent'], 'grid': grid, 'clearance': clearance,
                          **{k: row[k] for k in ROW_KEYS if k in row}} for row in r['scenes']]
                lines.append(f'| {agent} | ' + ' | '.join(fmt(r.get(c)) for c in COLS)
                             + f' | {r["seconds"] / r["n"]:.1f} |')
                print(f'{agent:16s} g={grid} c={clearance:g} ' + ' '.join(f'{c}={fmt(r.get(c))}' for c in COLS),
                      flush=True)
                paper = PAPER.get((grid, agent))
                if paper and clearance:
                    lines.append(f'| {agent} (paper) | ' + ' | '.join(fmt(paper.get(c)) for c in COLS) + ' | |')
            lines.append('')
            (RESULTS / 'table2.md').write_text('\n'.join(lines) + '\n')
            write_rows(RESULTS / 'table2.rows.jsonl', rows)
    print(f'wrote {RESULTS / "table2.md"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

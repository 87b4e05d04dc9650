"""The paper's Table II (robot in the loop) for any agents, on both geometries.

    python benchmarks/bench_table2.py [--scenes 30] [--grids 4,5] [--clearances 0,0.2]
        [--agents heur,heur-verified,paper,greedy,default] [--force]

Each agent (a preset or any agent text, `rad_core.sequencing.decide.agents`) runs with the robot on the
same generated two-sided scenes, seeds 0..N-1 (never used in training), through
`rad_core.experiment.evaluation.evaluate`, the code behind `rad eval --robot`: the agent plans each
scene as /plan_assembly does (CP-SAT, the sequencer and its search, GAMP) and the plan is
built in a fresh PyBullet twin (teleporting execution); coverage is what the twin's
registration finds built. Geometry: clearance 0 is rad's flush blocks; clearance > 0
makes every block smaller than its cells on the sides (the predecessor's robot scenes
leave 1 cm between neighbours: 0.2 of a 5 cm unit). Verified agents take the best action
of their ranking that GAMP finds feasible (no f_g / f_p by construction).

Writes docs/results/table2.md, one table of a-bar / f per agent and cell made from the rows, and
docs/results/table2.rows.jsonl, one line per agent and scene (`common.write_page`); --from-rows
rebuilds the page from a rows file. Results are cached per (agent, grid, clearance, N) under
out/cache/table2/, so an interrupted run resumes; --force recomputes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common import RESULTS, cached_evaluation, fmt, page_meta, read_rows, scenes, write_page

PAPER = {   # Table II of the paper (two-sided, robot in the loop); absent keys are not reported
    (4, 'heur'): {'R': 0.57, 'e': 0.36, 'f_g': 0.24, 'f_p': 0.16, 'coverage': 0.62},
    (4, 'milp-dqn'): {'R': 1.03, 'e': 0.49, 'f_g': 0.08, 'f_p': 0.08, 'coverage': 0.70},
    (4, 'paper'): {'R': 1.24, 'e': 0.57, 'f_g': 0.02, 'f_p': 0.03, 'coverage': 0.75},
    (5, 'heur'): {'R': 0.34, 'e': 0.29, 'f_g': 0.34, 'f_p': 0.24, 'coverage': 0.47},
    (5, 'milp-dqn'): {'R': 0.98, 'e': 0.53, 'f_g': 0.10, 'f_p': 0.15, 'coverage': 0.58},
    (5, 'paper'): {'R': 1.38, 'e': 0.65, 'f_g': 0.02, 'f_p': 0.06, 'coverage': 0.65},
}
DEFAULT_AGENTS = ('heur', 'heur-verified', 'milp-dqn', 'paper', 'greedy', 'default')
ROW_KEYS = ('name', 'return', 'outcome', 'coverage', 'predicted_coverage', 'coverage_opt', 'steps', 'reason',
            'stop_reason', 'lost')
FAILED = ('invalid_placement', 'invalid_grasp', 'invalid_unstable')
NOTE = ('Generated two-sided scenes, seeds 0..{last} per cell, never used in training; each agent plans as '
        '/plan_assembly does and the plan is built in a fresh twin (teleporting execution). a-bar: coverage of the '
        'whole target; f: episodes ended on a failed action. "(paper)": the paper\'s own Table II, f its f_g + '
        'f_p; its geometry leaves 1 cm between blocks (clearance 0.2), flush is rad\'s.')


def run(agent: str, grid: int, n: int, clearance: float, force: bool) -> dict:
    return cached_evaluation('table2', agent, f'g{grid}-c{clearance:g}-n{n}', lambda: scenes(grid, n, clearance),
                             force)


def table(rows: list[dict]) -> tuple[list[str], list[list]]:
    """The page's table from the rows: a line per agent (then the paper's, where it reports the agent),
    a column per (grid, clearance) cell holding a-bar / f."""
    cells = list(dict.fromkeys((r['clearance'], r['grid']) for r in rows))
    headers = ['agent', 'canonical text'] + [f'g = {g}, ' + (f'clearance {c:g}' if c else 'flush') + ': a-bar / f'
                                             for c, g in cells]
    out = []
    for agent in dict.fromkeys(r['agent'] for r in rows):
        line = [r['label'] for r in rows if r['agent'] == agent][:1] + [f'`{agent}`']
        for c, g in cells:
            mine = [r for r in rows if r['agent'] == agent and r['grid'] == g and r['clearance'] == c]
            line.append(f'{fmt(sum(r["coverage"] for r in mine) / len(mine))} / '
                        f'{fmt(sum(r["outcome"] in FAILED for r in mine) / len(mine))}' if mine else '')
        out.append(line)
        paper = [PAPER.get((g, line[0])) if c else None for c, g in cells]
        if any(paper):
            out.append([f'{line[0]} (paper)', ''] + [f'{fmt(p["coverage"])} / {fmt(p["f_g"] + p["f_p"])}' if p else ''
                                                     for p in paper])
    return headers, out


def write(rows: list[dict], scenes_per_cell: int, **meta) -> Path:
    headers, lines = table(rows)
    return write_page('table2', 'Table II: the robot in the loop', headers, lines,
                      NOTE.format(last=scenes_per_cell - 1), rows, **meta)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=30)
    p.add_argument('--grids', default='4,5')
    p.add_argument('--clearances', default='0,0.2')
    p.add_argument('--agents', default=','.join(DEFAULT_AGENTS), help='presets or agent texts, comma-separated')
    p.add_argument('--force', action='store_true')
    p.add_argument('--from-rows', type=Path, help='rebuild the page from this rows file, running nothing (it keeps '
                   'the command, commit and date the page states)')
    args = p.parse_args()
    if args.from_rows:
        rows = read_rows(args.from_rows)
        n = len({r['name'] for r in rows if (r['grid'], r['clearance']) == (rows[0]['grid'], rows[0]['clearance'])})
        print(f'wrote {write(rows, n, **page_meta(RESULTS / "table2.md"))}')
        return 0
    grids = [int(g) for g in args.grids.split(',')]
    clearances = [float(c) for c in args.clearances.split(',')]
    agents = [a for a in args.agents.split(',') if a]
    rows = []
    for clearance in clearances:
        for grid in grids:
            for agent in agents:
                try:
                    r = run(agent, grid, args.scenes, clearance, args.force)
                except Exception as e:  # noqa: BLE001 - one agent's failure should not lose the others
                    print(f'{agent} g={grid} c={clearance}: {type(e).__name__}: {e}', file=sys.stderr)
                    continue
                rows += [{'agent': r['agent'], 'label': agent, 'grid': grid, 'clearance': clearance,
                          **{k: row[k] for k in ROW_KEYS if k in row}} for row in r['scenes']]
                print(f'{agent:16s} g={grid} c={clearance:g} a-bar={fmt(r["coverage"])} f={fmt(r["f"])}', flush=True)
            write(rows, args.scenes)
    print(f'wrote {RESULTS / "table2.md"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

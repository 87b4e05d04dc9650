"""`default` with the robot in the loop, scene by scene: the figures and the behaviour check.

    python benchmarks/bench_eval.py [--agent default] [--rows out/cache/eval.rows.jsonl]
                                    [--compare OTHER.rows.jsonl] [--results docs/results]

Runs the agent through `rad_core.experiment.evaluation.evaluate` with the robot (what
`rad eval --agent default --robot` runs) on generated two-sided scenes, g = 5 seeds 0..39 and
g = 6 seeds 0..19, and on the held-out hand-made shapes and their tight layouts. Writes
docs/results/eval.md (coverage and f per set) and every scene's row (coverage, outcome, steps,
re-allocations, ...) to --rows. --compare names another run's rows file (e.g. of an older commit,
run from a `git worktree` with its rad_core on PYTHONPATH) and lists the scenes whose rows differ,
times left out. Planning stages have time budgets, so run it on a quiet machine: a loaded one can
change a row.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from common import CACHE, RESULTS, scenes, shape_scenes, write_page
from rad_core.experiment.evaluation import evaluate, get_agent



def scene_sets():
    yield '5', list(scenes(5, 40, 0.0))
    yield '6', list(scenes(6, 20, 0.0))
    yield 'held-out shapes', shape_scenes('holdout')
    yield 'tight layouts', shape_scenes('tight')


def without_times(row):
    """A row without the fields that measure time (they differ from run to run)."""
    if isinstance(row, dict):
        return {k: without_times(v) for k, v in row.items() if 'time' not in k and not k.endswith('_s')}
    if isinstance(row, list):
        return [without_times(v) for v in row]
    return row


def compare(rows: list[dict], other: Path) -> list[str]:
    theirs = {(r['set'], r['name']): without_times(r) for r in map(json.loads, other.read_text().splitlines())}
    differ = [f"{r['set']}/{r['name']}" for r in rows if theirs.get((r['set'], r['name'])) != without_times(r)]
    missing = len(theirs) - len({(r['set'], r['name']) for r in rows} & set(theirs))
    return differ + ([f'{missing} rows of {other} not in this run'] if missing else [])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--agent', default='default')
    p.add_argument('--rows', type=Path, default=CACHE / 'eval.rows.jsonl', help='where each scene\'s row goes')
    p.add_argument('--compare', type=Path, help='another run\'s rows file: list the scenes whose rows differ')
    p.add_argument('--results', type=Path, default=RESULTS, help='folder of the page, eval.md')
    args = p.parse_args()
    agent = get_agent(args.agent)
    rows, table = [], []
    for name, named_scenes in scene_sets():
        t0 = time.perf_counter()
        result = evaluate(agent, named_scenes, True, 0)
        print(f"{name}: coverage {result['coverage']:.3f}, f {result['f']:.2f} ({time.perf_counter() - t0:.0f} s)",
              flush=True)
        rows += [{'set': name, **row} for row in result['scenes']]
        table.append([name, str(result['n']), f"{result['coverage']:.3f}", f"{result['f']:g}"])
    args.rows.parent.mkdir(parents=True, exist_ok=True)
    args.rows.write_text(''.join(json.dumps(r, sort_keys=True, default=str) + '\n' for r in rows))
    print(f'wrote {args.rows}')
    note = (f'`{args.agent}` (`{agent.name}`) plans each scene as /plan_assembly does (in process, the same '
            'functions) and the plan is built in a fresh PyBullet twin (teleporting execution); coverage is '
            'what the twin\'s registration '
            'finds built, f the fraction of episodes that ended on a failed action. Generated scenes are '
            'two-sided, flush, never used in training; the held-out shapes are `rad_core.domain.shapes`\' '
            'held-out split, the tight layouts the same with their blocks 2.5 cm apart. Per-scene rows: '
            '`--rows`; `--compare` checks two runs scene by scene.')
    page = write_page('eval', f'`{args.agent}` with the robot in the loop, scene by scene',
                      ['grid', 'scenes', 'coverage', 'f'], table, note, results=args.results)
    print(f'wrote {page}')
    if args.compare:
        differ = compare(rows, args.compare)
        print(f'compared with {args.compare}: {len(rows) - len(differ)} of {len(rows)} rows the same'
              + (': differ ' + ', '.join(differ) if differ else ''))
        return 1 if differ else 0
    return 0


if __name__ == '__main__':
    sys.exit(main())

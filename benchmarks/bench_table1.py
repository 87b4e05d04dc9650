"""The paper's Table I (two-sided, no robot) for rad's agents, written to docs/results/table1.md.

    python benchmarks/bench_table1.py                 # 200 scenes per grid, g = 3, 4, 5, 6 (hours)
    python benchmarks/bench_table1.py --scenes 20     # a quick look
    python benchmarks/bench_table1.py --from-rows     # the table again from table1.rows.jsonl, no episodes

Rows per grid size, all on the same generated scenes (seeds 0.. : never seen in
training, which uses seeds from 1,000,000, nor in validation, 500,000..):

- HEUR (wo robot): the paper's heuristic with physics, `rad eval --agent heur-norobot`;
- DQN, DQN-REL: the learned baselines without the allocation (one training seed);
- MILP-DQN: one row per training seed and their mean, R with its standard
  deviation over seeds as in the paper;
- MILP-DQN-mixed: rad's default agent, trained on g = 3, 4, 5 and the training
  shapes with the stability-aware allocation;
- "+ verify": the same Q-ranking, but the action taken is the best-ranked one the
  planning copy finds stable (the env's own physics check; no failures by
  construction). It uses the simulator at test time, as the paper's MCTS does;
- ceiling: the best coverage any order of the allocation's poses reaches
  (exhaustive search, `sequencing.bounds.ceiling`), the most a sequencer can do with
  this allocation.

Also the hand-made shapes (`rad_core.domain.shapes`), training and held-out splits
separately. Every number comes from `rad_core.experiment.evaluation.evaluate`, the code behind
`rad eval`. Each (agent, allocation, scene set) run is cached as JSON under
out/cache/table1/ so an interrupted run resumes (--force recomputes); the per-scene
rows of all of them go to docs/results/table1.rows.jsonl (`run_rows`), from which
--from-rows rebuilds the table (`evaluation.summarize` over each run's rows) without
running an episode.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from common import RESULTS, ROOT, cache_dir, page_meta, read_rows, write_page
from rad_core.allocation import AllocationParams, solve
from rad_core.domain import jsonfmt
from rad_core.domain.errors import RadError
from rad_core.domain.scene_sources import generated_scenes
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.experiment.evaluation import evaluate, get_agent, summarize
from rad_core.sequencing.bounds.ceiling import coverage_ceiling
from rad_core.sequencing.decide.actions import AllocationActions
from rad_core.sim.physics import PhysicsStability
from rad_core.view.progress import ProgressBar

NAME = 'table1'
ROWS = RESULTS / f'{NAME}.rows.jsonl'
TRAINING = ROOT / 'data' / 'training'   # each run's progress.csv, copied there by scripts/ship_weights.sh
PAPER = {  # Table I of the paper: R (std), e, d, coverage
    3: {'DQN': (0.63, 0.02, 0.59, 0.27, 0.71), 'DQN-REL': (0.67, 0.01, 0.70, 0.23, 0.68),
        'MILP-DQN': (1.22, 0.01, 0.31, 0.53, 0.87)},
    4: {'DQN': (0.71, 0.08, 0.53, 0.20, 0.69), 'DQN-REL': (0.75, 0.08, 0.65, 0.14, 0.66),
        'MILP-DQN': (1.56, 0.03, 0.25, 0.47, 0.87)},
    5: {'MILP-DQN': (1.92, 0.05, 0.17, 0.42, 0.85)},
}
PAPER_CORRECTED = {3: 0.97, 4: 0.91, 5: 0.87}   # the paper's coverage corrected for the allocation (MILP-DQN)
CURVES = {  # the training runs of this table, as their learning curves group them
    'milp-dqn': ['milp-dqn-s0', 'milp-dqn-s1', 'milp-dqn-s2'],
    'baselines and ablation': ['milp-dqn-s0', 'milp-dqn-double-s0', 'dqn-s0', 'dqn-rel-s0'],
    'mixed': ['milp-dqn-mixed-s0']}
CEILING = 'ceiling'   # the agent field of the ceiling's rows


def run_agent(label: str, agent: str, checkpoint: str | None, scenes, cache: Path, force: bool,
              support: str = 'none', verify: bool = False) -> dict:
    if cache.exists() and not force:
        return json.loads(cache.read_text())
    scenes = list(scenes)
    t0 = time.perf_counter()
    result = evaluate(get_agent(agent, checkpoint, verify=verify), scenes, robot=False, seed=0,
                      progress=ProgressBar(len(scenes), f'{label:>22}'), allocation=AllocationParams(support=support))
    result['seconds'] = time.perf_counter() - t0
    result['checkpoint'] = checkpoint or agent
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(jsonfmt.dumps(result))
    return result


def ceiling_result(rows: list[dict]) -> dict:
    """The ceiling's mean over the scenes where the search finished (rows: name, ceiling)."""
    known = [r['ceiling'] for r in rows if r['ceiling'] is not None]
    return {'ceiling': float(np.mean(known)) if known else None, 'unknown': len(rows) - len(known), 'scenes': rows}


def run_ceiling(scenes, cache: Path, force: bool, support: str = 'none') -> dict:
    if cache.exists() and not force:
        return json.loads(cache.read_text())
    stability, rows = PhysicsStability(), []
    scenes = list(scenes)
    bar = ProgressBar(len(scenes), f'{"ceiling":>22}')
    for name, scene in scenes:
        env = AssemblyEnv(scene, EnvConfig(stability='physics'), stability=stability)
        space = AllocationActions(env, solve(scene, AllocationParams(support=support)).placements)
        rows.append({'name': name, 'ceiling': coverage_ceiling(env, space)})
        bar()
    stability.close()
    out = ceiling_result(rows)
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(jsonfmt.dumps(out))
    return out


def run_rows(key: str, support: str, cond: str, result: dict) -> list[dict]:
    """One run's rows for the rows file: which run (agent key, allocation, scene set) and
    per scene what `evaluate` measured (return, outcome, coverage, coverage_opt, steps) or,
    for the ceiling, the best order's coverage (None where the search gave up)."""
    out = []
    for s in result['scenes']:
        out.append({'agent': key, 'allocation': support, 'set': cond, 'scene': s['name'],
                    **{k: v for k, v in s.items() if k != 'name'}})
    return out


class Measured:
    """Results measured now (or read from out/cache/table1/): the runs' checkpoints under
    `runs`; a run whose training has not finished is left out. `rows` collects every run's
    per-scene rows in the table's order, for the rows file."""

    def __init__(self, runs: Path, cache: Path, force: bool, scenes: int, shape_seeds: int):
        self.runs, self.cache, self.force, self.rows = runs, cache, force, []
        self.scenes, self.shape_seeds = scenes, shape_seeds

    def cache_file(self, key: str, support: str, cond: str) -> Path:
        """The cache of a run; its name holds the number of scenes (or layouts per shape),
        so a quick run with --scenes 20 never reads a full run's results."""
        tag = '' if support == 'none' else '_stable'
        size = f'n{self.scenes}' if grid_of(cond) is not None else f'k{self.shape_seeds}'
        return self.cache / f'{key}{tag}_{cond}-{size}.json'

    def checkpoint(self, run: str) -> str | None:
        """A finished run's model (curves.png is written when a run ends), else None."""
        path = self.runs / run / 'model.pt'
        return str(path) if path.exists() and (self.runs / run / 'curves.png').exists() else None

    def agent(self, label: str, key: str, agent: str, run: str | None, verify: bool, support: str, cond: str,
              make: Callable) -> dict | None:
        checkpoint = self.checkpoint(run) if run else None
        if run and checkpoint is None:
            return None
        result = run_agent(label, agent, checkpoint, make(), self.cache_file(key, support, cond), self.force,
                           support, verify)
        self.rows += run_rows(key, support, cond, result)
        return result

    def ceiling(self, support: str, cond: str, make: Callable) -> dict:
        result = run_ceiling(make(), self.cache_file(CEILING, support, cond), self.force, support)
        self.rows += run_rows(CEILING, support, cond, result)
        return result


class FromRows:
    """Results rebuilt from a rows file (`run_rows`): each run's figures are
    `evaluation.summarize` over its scenes' rows, exactly what `evaluate` returned."""

    def __init__(self, path: Path):
        if not path.exists():
            raise RadError(f'{path} does not exist: run the benchmark without --from-rows to measure the rows')
        self.runs: dict[tuple[str, str, str], list[dict]] = {}
        for row in read_rows(path):
            run = (row.pop('agent'), row.pop('allocation'), row.pop('set'))
            self.runs.setdefault(run, []).append({'name': row.pop('scene'), **row})

    def sets(self) -> list[str]:
        """The scene sets in the order of the file."""
        return list(dict.fromkeys(s for _, _, s in self.runs))

    def agent(self, label, key, agent, run, verify, support, cond, make) -> dict | None:
        rows = self.runs.get((key, support, cond))
        return summarize(rows, key) if rows else None

    def ceiling(self, support: str, cond: str, make: Callable) -> dict:
        rows = self.runs.get((CEILING, support, cond))
        if not rows:
            raise RadError(f'the rows file has no ceiling rows for {cond} with --support {support}')
        return ceiling_result(rows)


def fmt(v, digits=2) -> str:
    return '-' if v is None else f'{v:.{digits}f}'


def mean_of_seeds(results: list[dict]) -> tuple[dict, dict]:
    keys = ('R', 'd', 'e', 'f', 'coverage', 'coverage_rel')
    mean = {k: float(np.mean([r[k] for r in results])) for k in keys}
    mean['scenes'] = [dict(s, coverage=float(np.mean([r['scenes'][i]['coverage'] for r in results])))
                      for i, s in enumerate(results[0]['scenes'])]
    return mean, {'R_seed_std': float(np.std([r['R'] for r in results]))}


def section(source, cond: str, make: Callable, g: int | None, support: str, seeds: list[int]) -> list[tuple]:
    """The table rows of one scene set and allocation: (label, result, extra), runs that
    `source` does not have left out."""
    def agent(label, key, agent_name=None, run=None, verify=False):
        return source.agent(label, key + ('+verify' if verify else ''), agent_name or key, run, verify, support, cond,
                            make)

    rows = [('HEUR (wo robot)', agent('heur-norobot', 'heur-norobot'), {})]
    if g is not None and support == 'none':
        for label, name in (('DQN', 'dqn-s0'), ('DQN-REL', 'dqn-rel-s0')):
            rows.append((label, agent(label, name, label.lower(), name), {}))
    per_seed = [(s, agent(f'milp-dqn-s{s}', f'milp-dqn-s{s}', 'milp-dqn', f'milp-dqn-s{s}')) for s in seeds]
    per_seed = [(s, r) for s, r in per_seed if r is not None]
    if per_seed:
        mean, extra = mean_of_seeds([r for _, r in per_seed])
        rows.append((f'**MILP-DQN** (trained at g = 3, mean of {len(per_seed)} seeds)', mean, extra))
        if support == 'none':
            rows += [(f'MILP-DQN seed {s}', r, {}) for s, r in per_seed]
    if support == 'none':
        rows.append(('MILP-DQN, double DQN (seed 0, ablation)',
                     agent('double', 'milp-dqn-double-s0', 'milp-dqn', 'milp-dqn-double-s0'), {}))
    rows.append(('MILP-DQN seed 0 + verify', agent('s0+verify', 'milp-dqn-s0', 'milp-dqn', 'milp-dqn-s0', True), {}))
    rows.append(('**MILP-DQN-mixed** (g = 3..5 + training shapes, stable allocations)',
                 agent('mixed', 'milp-dqn-mixed-s0', 'milp-dqn', 'milp-dqn-mixed-s0'), {}))
    rows.append(('**MILP-DQN-mixed + verify**',
                 agent('mixed+verify', 'milp-dqn-mixed-s0', 'milp-dqn', 'milp-dqn-mixed-s0', True), {}))
    return [r for r in rows if r[1] is not None]


def grid_of(cond: str) -> int | None:
    """g of a generated set ('g4'), None for the hand-made shapes ('shapes-holdout')."""
    return int(cond[1:]) if cond[0] == 'g' and cond[1:].isdigit() else None


def conditions(args) -> list[tuple[str, Callable, int | None]]:
    """(scene set, its scenes' factory, g) to measure: the grids, then the shapes' splits."""
    grids = [int(g) for g in args.grids.split(',')]
    out = [(f'g{g}', lambda g=g: generated_scenes(g, 2, args.scenes, 0), g) for g in grids]
    from rad_core.domain import shapes
    for split in () if args.skip_shapes else ('train', 'holdout'):
        names = shapes.SPLITS[split]
        out.append((f'shapes-{split}', lambda names=names: [(f'{n}-seed{s}', shapes.shape_scene(n, s))
                                                            for n in names for s in range(args.shape_seeds)], None))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--scenes', type=int, default=200)
    p.add_argument('--grids', default='3,4,5,6')
    p.add_argument('--seeds', default='0,1,2', help='MILP-DQN training seeds (runs/milp-dqn-s<seed>/model.pt)')
    p.add_argument('--runs', default=str(ROOT / 'runs'), help='folder of the training runs')
    p.add_argument('--shape-seeds', type=int, default=5, help='block layouts per hand-made shape')
    p.add_argument('--rows', type=Path, default=ROWS, help='the per-scene rows file '
                   '(written, or read with --from-rows)')
    p.add_argument('--out', type=Path, default=RESULTS / f'{NAME}.md')
    p.add_argument('--force', action='store_true', help='recompute cached results')
    p.add_argument('--skip-shapes', action='store_true', help='only the generated scenes (e.g. to split a run '
                   'over two processes; a last run without it assembles everything from the cache)')
    p.add_argument('--from-rows', action='store_true', help='rebuild the table from --rows without running '
                   'anything (the scene sets and runs are those of the file)')
    args = p.parse_args()
    seeds = [int(s) for s in args.seeds.split(',')]
    if args.from_rows:
        source = FromRows(args.rows)
        sets = [(cond, None, grid_of(cond)) for cond in source.sets()]
    else:
        source = Measured(Path(args.runs), cache_dir(NAME), args.force, args.scenes, args.shape_seeds)
        sets = conditions(args)
    report = {}
    for cond, make, g in sets:
        print(f'--- {cond}', file=sys.stderr)
        report[cond] = ([(support, section(source, cond, make, g, support, seeds), source.ceiling(support, cond, make))
                         for support in ('none', 'stable')], g)
    if args.from_rows:   # the rows stay as they are; the page keeps what it states of the run that measured them
        page = write_markdown(report, args.out, None, **page_meta(args.out))
    else:
        plot_curves(TRAINING, ROOT / 'docs' / 'img')
        page = write_markdown(report, args.out, source.rows)
    print(f'wrote {page}')
    return 0


def scenes_per_grid(report: dict) -> int:
    """How many generated scenes each grid's runs had (the first grid's ceiling rows)."""
    grids = [sections for sections, g in report.values() if g is not None]
    return len(grids[0][0][2]['scenes']) if grids else 0


def page_table(report: dict) -> tuple[list[str], list[list]]:
    """One table: a line per (allocation, agent), a column of coverage per scene set."""
    conds = list(report)
    headers = ['allocation', 'agent'] + [(f'g = {g}' + ('*' if g == 3 else '') if g is not None
                                          else f'shapes, {cond.split("-")[1]}') for cond, (_, g) in report.items()]
    lines: dict[tuple[str, str], dict[str, str]] = {}
    for cond, (sections, _) in report.items():
        for support, rows_, ceiling in sections:
            alloc = 'paper (MILP)' if support == 'none' else 'stable'
            for label, r, _ in rows_:
                lines.setdefault((alloc, label), {})[cond] = f'{r["coverage"]:.2f}'
            lines.setdefault((alloc, 'best order of the allocation (ceiling)'), {})[cond] = fmt(ceiling['ceiling'])
    return headers, [[alloc, label, *(cells.get(c, '') for c in conds)] for (alloc, label), cells in lines.items()]


NOTE = ('Coverage without the robot (physics decides stability), two-sided scenes: {n} generated scenes per grid '
        'size (seeds 0..{last}, never used in training) and the hand-made shapes; agents trained at g = 3 only (the '
        'paper\'s * condition) unless named mixed. The paper\'s Table I MILP-DQN: 0.87 at g = 3, 4 and 0.85 at g = 5. '
        'R, e, d and f of every run are in the rows; learning curves: docs/img/curves_*.png.')


def write_markdown(report: dict, out: Path, rows: list[dict] | None, **meta) -> Path:
    n = scenes_per_grid(report)
    headers, lines = page_table(report)
    return write_page(NAME, 'Table I: the agents without the robot', headers, lines,
                      NOTE.format(n=n, last=n - 1), rows, results=out.parent, **meta)


def plot_curves(training: Path, img: Path, redraw: bool = True) -> list[tuple[str, Path]]:
    """Learning curves from data/training/<run>.csv (copied there from
    runs/<run>/progress.csv by scripts/ship_weights.sh); redraw False draws only the
    missing pictures (a table rebuilt from its rows leaves the committed ones as they are)."""
    from rad_core.training.curves import plot_progress
    out = []
    for name, runs in CURVES.items():
        paths = [training / f'{r}.csv' for r in runs if (training / f'{r}.csv').exists()]
        if paths:
            path = img / f'curves_{name.split()[0]}.png'
            if redraw or not path.exists():
                plot_progress(paths, path, title=name, labels=[p.stem for p in paths])
            out.append((name, path))
    return out


if __name__ == '__main__':
    sys.exit(main())

"""Execution with the whole arm motion simulated, against teleporting execution, fault-free and under faults.

    python benchmarks/bench_execution.py [--grids 4 5] [--scenes 5] [--shapes holdout|train|tight ...]
        [--faults none mocap placement slip miss nudge drops realistic] [--agent default]
        [--runs out/cache/execution/runs.jsonl] [--results docs/results]

What /execute_assembly runs, in-process: the execute / verify / replan loop
(`rad_core.sequencing.execution.execute.execute_assembly`, the function the assembly node calls),
plans from the agent as the node graph runs it (`sequencing.agent.agent_plan.AgentPlanner`: CP-SAT,
the sequencer, in-process GAMP; `default`: stable allocation, re-allocation on), the plant a
real `Twin` as the twin node builds it (`twin_world_config`: blocks with 0.5 mm of play per side; PyBullet: the
arm follows every trajectory under the path and goal tolerances the assembly node sends,
so contact aborts the run as it would on a real controller; the hand grasps by contact)
with the faults of `rad_core.sim.faults` (seeded per scene). DDS adds transport only (bench_plan_assembly
measures that); leaving it out keeps 100+ executions within a session.

Teleporting execution is the reference the figures of the earlier issues came from: the
same first plan, each block put at its planned pose and left to settle, no arm.

Per run: coverage (registered target cells filled at the end), steps executed, replans,
raw per-step success (steps that went as planned / steps), recovered per-step success
(blocks whose placement was attempted that end on a target cell / such blocks), faults
injected (the twin's fault events), wall and simulated time. Every run is appended to
--runs (a cache, not committed) as one JSON line and skipped when run again (the benchmark
resumes); the summary goes to <results>/execution.md (`common.write_page`: a line per scene set
and run kind), the runs it summarises to execution.rows.jsonl (one compact line per run).
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np
from common import RESULTS, cache_dir, shape_scenes, write_page

FAULT_LEVELS = {
    # One fault at a realistic level each, then all together (FaultConfig.realistic()).
    'none': {},
    'mocap': {'mocap_position_noise': 0.001, 'mocap_yaw_noise_deg': 0.5},
    'drops': {'drop_body': 0.02, 'drop_frame': 0.01},
    'placement': {'placement_error': 0.002},
    'slip': {'slip': 0.05},
    'miss': {'miss': 0.05},
    'nudge': {'nudge': 0.05},
    'realistic': 'realistic',
}


SET_NAMES = {'train': 'training shapes', 'holdout': 'held-out shapes', 'tight': 'tight layouts'}


def scenes(grids, count, seed, shapes, sets: dict | None = None):
    """(name, scene) of the generated scenes and the shape splits; sets, if given, gets each name's set."""
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    out = []
    for g in grids:
        out += [(f'g{g}-s{seed + i}', generate_scene(GeneratorConfig(grid=g), seed + i)) for i in range(count)]
    for split in shapes:
        out += shape_scenes(split)
    if sets is not None:
        sets.update({name: f'generated g = {name[1:].split("-")[0]}' if name[0] == 'g' and name[1].isdigit()
                     else '' for name, _ in out})
        for split in shapes:
            sets.update({name: SET_NAMES[split] for name, _ in shape_scenes(split)})
    return out


def attempted_and_placed(steps, final_scene) -> tuple[int, int]:
    from rad_core.domain.grid import Grid, blocks_on_grid
    attempted = {s['block'] for s in steps}
    on_grid = {final_scene.blocks[i].id for i in blocks_on_grid(final_scene, Grid(final_scene))} \
        if final_scene is not None else set()
    return len(attempted), len(attempted & on_grid)


def run_teleport(name, scene, planner) -> dict:
    from rad_core.domain.coverage import measured_coverage
    from rad_core.sequencing.execution.twin_build import build_teleported
    t0 = time.perf_counter()
    plan = planner(scene, None)
    registered = build_teleported(scene, plan.steps)     # a block that fell over is set aside, not counted
    final = registered.scene
    steps = [s.to_dict() for s in plan.steps]
    attempted, placed = attempted_and_placed(steps, final)
    return {'scene': name, 'mode': 'teleport', 'faults': 'none', 'coverage': measured_coverage(final),
            'predicted_coverage': plan.predicted_coverage, 'steps': len(steps), 'replans': 0,
            'raw_step_success': 1.0 if steps else 0.0,
            'recovered_step_success': placed / attempted if attempted else 1.0,
            'success': plan.success, 'reason': plan.reason, 'lost': dict(registered.set_aside),
            'wall_s': time.perf_counter() - t0}


def run_simulated(name, scene, planner, faults: str, seed: int, max_replans: int) -> dict:
    from rad_core.sequencing.execution.execute import ExecuteConfig
    from rad_core.sequencing.execution.twin_build import build_simulated
    from rad_core.sim.twin import TwinConfig
    level = FAULT_LEVELS[faults]
    twin_config = TwinConfig()
    if level:
        from rad_core.sim.faults import FaultConfig
        twin_config = TwinConfig(faults=FaultConfig.realistic(seed=seed) if level == 'realistic'
                                 else FaultConfig(seed=seed, **level))
    t0 = time.perf_counter()
    built = build_simulated(scene, planner, planner.motion, twin_config,
                            ExecuteConfig(settle_s=0.5, max_replans=max_replans))
    result = built.result
    steps = result.steps
    attempted, placed = attempted_and_placed(steps, result.final_scene)
    return {'scene': name, 'mode': 'simulate', 'faults': faults, 'coverage': result.coverage,
            'steps': len(steps), 'replans': result.replans,
            'raw_step_success': max(0.0, 1.0 - len(result.faults) / len(steps)) if steps else 0.0,
            'recovered_step_success': placed / attempted if attempted else 1.0,
            'success': result.success, 'reason': result.reason, 'injected': built.injected,
            'lost': dict(result.lost_blocks), 'recovered_faults': result.recovered_faults,
            'problems': len(result.faults), 'wall_s': time.perf_counter() - t0, 'sim_s': built.sim_s}


def summarise(rows: list[dict]) -> dict:
    by = {}
    for r in rows:
        by.setdefault((r['mode'], r['faults']), []).append(r)
    teleport = {r['scene']: r['coverage'] for r in rows if r['mode'] == 'teleport'}
    clean = {r['scene']: r['coverage'] for r in rows if r['mode'] == 'simulate' and r['faults'] == 'none'}
    out = {}
    for (mode, faults), rs in sorted(by.items()):
        ref = teleport if faults == 'none' else clean
        paired = [r['coverage'] - ref[r['scene']] for r in rs if r['scene'] in ref]
        injected = Counter()
        for r in rs:
            injected.update(r.get('injected') or {})
        out[f'{mode}/{faults}'] = {
            'runs': len(rs), 'coverage': float(np.mean([r['coverage'] for r in rs])),
            'coverage_delta_vs_reference': float(np.mean(paired)) if paired else None,
            'reference': ('teleport' if faults == 'none' else 'simulate/none') if mode == 'simulate' else None,
            'steps': float(np.mean([r['steps'] for r in rs])), 'replans': float(np.mean([r['replans'] for r in rs])),
            'raw_step_success': float(np.mean([r['raw_step_success'] for r in rs])),
            'recovered_step_success': float(np.mean([r['recovered_step_success'] for r in rs])),
            'failed_runs': sum(not r['success'] for r in rs),
            'unexplained_failures': sum(not r['success'] and not r['reason'] for r in rs),
            'injected': dict(injected), 'wall_s': float(np.mean([r['wall_s'] for r in rs])),
        }
    return out


HEADERS = ('scene set', 'run', 'runs', 'coverage', 'delta vs reference', 'steps', 'replans', 'raw step success',
           'recovered step success', 'failed runs', 'faults injected', 'wall s')


def table(rows: list[dict]) -> list[list]:
    """A line per (scene set, mode/faults), from the rows (`summarise` within each set)."""
    out = []
    for name in dict.fromkeys(r['set'] for r in rows):
        for key, s in summarise([r for r in rows if r['set'] == name]).items():
            delta = '' if s['coverage_delta_vs_reference'] is None or not s['reference'] else \
                f'{s["coverage_delta_vs_reference"]:+.3f} ({s["reference"]})'
            injected = ', '.join(f'{k} {v}' for k, v in sorted(s['injected'].items())) or '-'
            out.append([name, key, s['runs'], f'{s["coverage"]:.3f}', delta, f'{s["steps"]:.1f}',
                        f'{s["replans"]:.2f}', f'{s["raw_step_success"]:.3f}', f'{s["recovered_step_success"]:.3f}',
                        s['failed_runs'],
                        injected, f'{s["wall_s"]:.0f}'])
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--grids', type=int, nargs='*', default=[4, 5])
    p.add_argument('--scenes', type=int, default=5, help='generated scenes per grid size')
    p.add_argument('--seed', type=int, default=500, help='first generator seed (training uses >= 1e6)')
    p.add_argument('--shapes', nargs='*', default=['holdout'], choices=['train', 'holdout', 'tight'])
    p.add_argument('--faults', nargs='*', default=list(FAULT_LEVELS), choices=list(FAULT_LEVELS))
    p.add_argument('--agent', default='default',
                   help='the agent (rad_core.sequencing.decide.agents), as the node graph runs it')
    p.add_argument('--max-replans', type=int, default=10)
    p.add_argument('--runs', type=Path, default=None, help='the resumable cache of runs '
                   '(default out/cache/execution/runs.jsonl)')
    p.add_argument('--results', type=Path, default=RESULTS, help='folder of execution.md and execution.rows.jsonl')
    args = p.parse_args()
    args.runs = args.runs or cache_dir('execution') / 'runs.jsonl'
    args.runs.parent.mkdir(parents=True, exist_ok=True)
    done = {}
    if args.runs.exists():
        for line in args.runs.read_text().splitlines():
            r = json.loads(line)
            done[(r['scene'], r['mode'], r['faults'])] = r
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    planner = AgentPlanner(args.agent)
    sets = {}
    todo = scenes(args.grids, args.scenes, args.seed, args.shapes, sets)
    for i, (name, scene) in enumerate(todo):
        jobs = [('teleport', 'none')] + [('simulate', f) for f in args.faults]
        for mode, faults in jobs:
            if (name, mode, faults) in done:
                continue
            row = run_teleport(name, scene, planner) if mode == 'teleport' else \
                run_simulated(name, scene, planner, faults, seed=args.seed + i, max_replans=args.max_replans)
            done[(name, mode, faults)] = row
            with args.runs.open('a') as f:
                f.write(json.dumps(row) + '\n')
            print(f'{name:>14} {mode:>8} {faults:>10}: coverage {row["coverage"]:.3f}, {row["steps"]} steps, '
                  f'{row["replans"]} replans, recovered {row["recovered_step_success"]:.3f}, '
                  f'{row["wall_s"]:.0f} s' + (f' ({row["reason"][:100]})' if not row['success'] else ''),
                  flush=True)
    names = {n for n, _ in todo}
    rows = [{'set': sets[n], **r} for (n, _, f), r in done.items()
            if n in names and (f in args.faults or r['mode'] == 'teleport')]
    summary = summarise(rows)
    for key, s in summary.items():
        delta = s['coverage_delta_vs_reference']
        versus = f' ({delta:+.3f} vs {s["reference"]})' if delta is not None and s['reference'] else ''
        print(f'{key:>22}: coverage {s["coverage"]:.3f}{versus}'
              + f', recovered step success {s["recovered_step_success"]:.3f}, failed runs {s["failed_runs"]}')
    note = (f'Agent `{planner.agent}`; the execute / verify / replan loop of /execute_assembly on a twin that '
            'simulates the whole arm motion (simulate) or puts each block at its pose (teleport), without faults and '
            'under the '
            'fault levels named (seeded per scene). The delta compares each scene with its run without the arm '
            '(teleport) or without faults (simulate/none).')
    page = write_page('execution', 'Execution with the whole arm motion simulated, and under faults', HEADERS,
                      table(rows), note, rows, results=args.results)
    print(f'wrote {page}')


if __name__ == '__main__':
    main()

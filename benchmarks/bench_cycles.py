"""Build, take apart, build again: N cycles on a few scenes with no reset and nothing touched by hand.

    python benchmarks/bench_cycles.py [--cycles 10] [--faults none|realistic] [--results docs/results] [--rows FILE]

Each cycle builds the target with the execute / verify / replan loop /execute_assembly runs and
takes it apart onto the table with the loop /take_apart runs (rad_core.sequencing.execution.disassembly),
in-process on one `Twin` built as the twin node builds it (the whole arm motion simulated, the
node's path and goal tolerances); the next cycle builds from what motion capture sees. Plans:
the agent as the node graph runs it (`sequencing.agent.agent_plan.AgentPlanner`, `default`).
Per cycle: build coverage, steps, replans, take-apart success, blocks lost, drift from the
heap (mm, mean and max), wall time. Results: docs/results/cycles.md (`common.write_page`, a line per
cycle) and --rows (one compact line per cycle, out/cache/cycles/rows.jsonl by default); the per-scene
summary is printed.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from common import CACHE, RESULTS, write_page, write_rows

SCENES = (('default g4 seed 8', ('generated', 4, 8)), ('g5 seed 503', ('generated', 5, 503)),
          ('pillars (held out)', ('shape', 'pillars')))


def scene_of(spec):
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.domain.shapes import shape_scene
    return generate_scene(GeneratorConfig(grid=spec[1]), spec[2]) if spec[0] == 'generated' else shape_scene(spec[1])


def run_cycles(name, scene, planner, cycles: int, faults: str, seed: int) -> list[dict]:
    from rad_core.cell.trajectory import TrajectoryAborted
    from rad_core.sequencing.execution.disassembly import local_place_planner, take_apart
    from rad_core.sequencing.execution.execute import ExecuteConfig, execute_assembly
    from rad_core.sim.faults import FaultConfig
    from rad_core.sim.twin import Tolerances, Twin, TwinConfig, twin_world_config
    from rad_core.sim.world import World
    rows = []
    place = local_place_planner(planner.gamp)
    with World(scene, twin_world_config()) as world:
        twin = Twin(world, TwinConfig(faults=FaultConfig.parse(faults, seed)))
        noise = twin.config.faults.mocap_position_noise

        def move_arm(trajectory):
            report = twin.execute(trajectory, tolerances=Tolerances(path=0.05, goal=0.01, goal_time=1.0))
            if report.error_code:      # as rad_ros.plant.ActionPlant: a started trajectory stopped
                raise TrajectoryAborted(report.error_code, f'trajectory aborted (error code {report.error_code}): '
                                                           f'{report.error_string}')

        kw = dict(move_arm=move_arm, move_gripper=twin.execute_gripper, register=twin.registration,
                  config=ExecuteConfig(settle_s=0.5, max_replans=10, mocap_noise=noise),
                  joints=lambda: twin.world.joint_positions(), settle=twin.settle)
        for cycle in range(1, cycles + 1):
            t0 = time.perf_counter()
            start = twin.registration().scene
            build = execute_assembly(start, planner, plan_motion=planner.motion, **kw)
            order = [s['block'] for s in build.steps]
            apart = take_apart(twin.registration().scene, scene, place, build_order=order, **kw)
            stats = apart.drift_stats()
            row = {'scene': name, 'cycle': cycle, 'coverage': build.coverage, 'build_steps': len(build.steps),
                   'build_replans': build.replans, 'build_success': build.success, 'build_reason': build.reason,
                   'take_apart_success': apart.success, 'take_apart_reason': apart.reason,
                   'take_apart_steps': len(apart.steps), 'lost': sorted(set(apart.lost) | set(build.lost_blocks)),
                   'drift_mean_mm': stats['mean_mm'], 'drift_max_mm': stats['max_mm'],
                   'wall_s': time.perf_counter() - t0}
            rows.append(row)
            print(f'{name:>20} cycle {cycle:2d}: coverage {row["coverage"]:.3f}, {row["build_steps"]} + '
                  f'{row["take_apart_steps"]} steps, {row["build_replans"]} replans, lost {row["lost"] or "none"}, '
                  f'drift {row["drift_mean_mm"]:.1f} / {row["drift_max_mm"]:.1f} mm, {row["wall_s"]:.0f} s'
                  + ('' if apart.success else f' (take-apart: {apart.reason[:120]})'), flush=True)
            if not apart.success and apart.final_scene is None:
                break
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--cycles', type=int, default=10)
    p.add_argument('--faults', default='none')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--agent', default='default',
                   help='the agent (rad_core.sequencing.decide.agents), as the node graph runs it')
    p.add_argument('--results', type=Path, default=RESULTS, help='folder of the page, cycles.md')
    p.add_argument('--rows', default=str(CACHE / 'cycles' / 'rows.jsonl'),
                   help="every cycle's row (the page's table holds every row)")
    args = p.parse_args()
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    planner = AgentPlanner(args.agent)
    rows = []
    for name, spec in SCENES:
        rows += run_cycles(name, scene_of(spec), planner, args.cycles, args.faults, args.seed)
    summary = {}
    for name, _ in SCENES:
        rs = [r for r in rows if r['scene'] == name]
        summary[name] = {'cycles': len(rs), 'coverage_first': rs[0]['coverage'] if rs else None,
                         'coverage_mean': float(np.mean([r['coverage'] for r in rs])) if rs else None,
                         'coverage_min': float(min(r['coverage'] for r in rs)) if rs else None,
                         'take_apart_failures': sum(not r['take_apart_success'] for r in rs),
                         'lost': sorted({b for r in rs for b in r['lost']}),
                         'drift_max_mm': float(max(r['drift_max_mm'] for r in rs)) if rs else None}
    rows_file = write_rows(Path(args.rows), rows)
    headers = ['scene', 'cycle', 'coverage', 'steps (build + take apart)', 'replans', 'take-apart', 'lost',
               'drift mean / max mm', 'wall s']
    table = [[r['scene'], r['cycle'], f'{r["coverage"]:.3f}', f'{r["build_steps"]} + {r["take_apart_steps"]}',
              r['build_replans'], 'ok' if r['take_apart_success'] else 'failed', ', '.join(r['lost']) or '-',
              f'{r["drift_mean_mm"]:.1f} / {r["drift_max_mm"]:.1f}', f'{r["wall_s"]:.0f}'] for r in rows]
    note = (f'Agent `{planner.agent}`, faults {args.faults}: in-process loops of /execute_assembly and /take_apart on '
            'one twin, no reset. The drift is how far the blocks end from where they started on the table.')
    page = write_page('cycles', 'Build, take apart, build again', headers, table, note, results=args.results)
    print(f'wrote {page} and {rows_file}')
    for name, s in summary.items():
        print(f'{name}: {s}')


if __name__ == '__main__':
    main()

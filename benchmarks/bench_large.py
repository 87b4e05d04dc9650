"""Planning time and coverage against structure size, up to 100 blocks from a feeder.

    python benchmarks/bench_large.py [--agent greedy] [--grids 4,6,8,10] [--seeds 3] [--seed 7000]
                                     [--large all] [--time-limit 120] [--out docs/results]

For each generated two-sided scene (g in --grids, seeds --seed.., unseen by training; from
g = 7 or 8 on the generator puts the blocks in a feeder, the table within reach being too
small) and each large hand-made target (`rad_core.domain.large_shapes`, 45 to 100 blocks, all in a
feeder; the two-deep flush walls, which a parallel gripper cannot fill (`large_shapes.FLUSH_LIMIT`),
as a group of their own), the agent plans with the robot in the loop in process (`AgentPlanner`: CP-SAT, the
sequencer, GAMP on the planning twin, re-allocation), then the twin builds the plan
(teleporting execution, physics settling after each block) and motion capture registers it.
Per structure it records the blocks in the scene, the blocks placed, the planning time and
its stages, the predicted and the built coverage, the failures (blocks the build lost) and, after
planning, an upper bound on what any top-down build reaches (`sequencing.planning.courses.course_bound`);
it writes <out>/large.md and <out>/large.rows.jsonl (`common.write_page`) and docs/img/large.png (planning time per
placed block against the blocks in the scene: the issue asks that it grow no faster than
linearly, i.e. that the time per block stay flat or grow at most linearly). While it runs,
<out>/large.partial.jsonl holds the rows measured so far (removed once the results are written).

"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from common import RESULTS, ROOT, write_page


def cases(grids, seeds: int, seed0: int, large: list[str]):
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.domain.large_shapes import FLUSH, large_scene
    for g in grids:
        for s in range(seed0, seed0 + seeds):
            yield f'g{g}-s{s}', f'generated g={g}', generate_scene(GeneratorConfig(grid=g, sides=2), s)
    for name in large:
        yield name, 'large two-deep flush' if name in FLUSH else 'large hand-made', large_scene(name)


def measure(planner, name: str, kind: str, scene) -> dict:
    from rad_core.domain.coverage import measured_coverage
    from rad_core.sequencing.execution.twin_build import build_teleported
    t0 = time.perf_counter()
    plan = planner(scene, None, 0)
    planning = time.perf_counter() - t0
    registered = build_teleported(scene, plan.steps)
    placed = len(plan.steps)
    from rad_core.sequencing.planning.courses import course_bound
    return {'case': name, 'kind': kind, 'blocks': len(scene.blocks), 'cells': scene.num_target_cells,
            'feeder': scene.feeder is not None, 'placed': placed, 'planning_s': round(planning, 2),
            's_per_block': round(planning / max(placed, 1), 3),
            'predicted': round(plan.predicted_coverage, 3), 'built': round(measured_coverage(registered.scene), 3),
            'course_bound': round(course_bound(scene), 3),
            'lost': sorted(registered.set_aside), 'success': plan.success, 'reason': plan.reason[:300],
            'stages': {k: round(v, 2) for k, v in plan.timings.items()}}


def plot(rows: list[dict], out: Path, agent: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for kind, marker in (('generated', 'o'), ('large hand-made', 's'), ('large two-deep flush', 'x')):
        sel = [r for r in rows if r['kind'].startswith(kind)]
        if not sel:
            continue
        axes[0].scatter([r['blocks'] for r in sel], [r['s_per_block'] for r in sel], marker=marker, label=kind)
        axes[1].scatter([r['blocks'] for r in sel], [r['built'] for r in sel], marker=marker, label=kind)
    axes[0].set_xlabel('blocks in the scene')
    axes[0].set_ylabel('planning time per placed block (s)')
    axes[0].set_ylim(bottom=0)
    axes[1].set_xlabel('blocks in the scene')
    axes[1].set_ylabel('coverage built by the twin')
    axes[1].set_ylim(0, 1.05)
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f'planning with the robot in the loop against size ({agent})')
    fig.tight_layout()
    fig.savefig(out, dpi=90)


HEADERS = ('case', 'blocks', 'feeder', 'target cells', 'placed', 'planning (s)', 's / block', 'predicted', 'built',
           'bound', 'lost')


def table(rows: list[dict]) -> list[list]:
    return [[r['case'], r['blocks'], 'yes' if r['feeder'] else 'no', r['cells'], r['placed'], f"{r['planning_s']:.1f}",
             f"{r['s_per_block']:.2f}", f"{r['predicted']:.3f}", f"{r['built']:.3f}", f"{r['course_bound']:.3f}",
             len(r['lost'])] for r in rows]


def note(rows: list[dict], agent: str) -> str:
    groups = []
    for kind in dict.fromkeys(r['kind'] for r in rows):
        sel = [r for r in rows if r['kind'] == kind]
        groups.append(f"{kind} {statistics.mean(r['built'] for r in sel):.3f}")
    return (f'Agent `{agent}`, robot in the loop, the plan built by the teleporting twin. "bound": '
            '`course_bound`, the most any top-down build reaches. Mean built coverage: ' + '; '.join(groups) +
            f". Slowest plan {max(r['planning_s'] for r in rows):.1f} s. "
            '![planning time per block and coverage against size](../img/large.png)')


def write(rows: list[dict], out: Path, command: str, agent: str, **meta) -> Path:
    plot(rows, ROOT / 'docs' / 'img' / 'large.png', agent)
    return write_page('large', f'Planning against structure size, up to {max(r["blocks"] for r in rows)} blocks',
                      HEADERS, table(rows), note(rows, agent), rows, command=command, results=out, **meta)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--agent', default='greedy')
    ap.add_argument('--grids', default='4,6,8,10')
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--seed', type=int, default=7000, help='first seed of the generated scenes')
    ap.add_argument('--large', default='all', help="comma-separated large shapes, 'all' or 'none'")
    ap.add_argument('--time-limit', type=float, default=120.0,
                    help="planning time limit per structure (s); 120: the assembly node's default")
    ap.add_argument('--improve-time-s', type=float, default=None,
                    help="anytime planning's budget after the first plan (default: the assembly node's, "
                         "agent_plan.IMPROVE_TIME_S)")
    ap.add_argument('--out', default=str(RESULTS))
    args = ap.parse_args(argv)
    from rad_core.domain.large_shapes import LARGE_SPECS
    from rad_core.sequencing.agent.agent_plan import IMPROVE_TIME_S, AgentPlanner
    grids = [int(g) for g in args.grids.split(',') if g]
    large = list(LARGE_SPECS) if args.large == 'all' else [n for n in args.large.split(',') if n and n != 'none']
    improve = IMPROVE_TIME_S if args.improve_time_s is None else args.improve_time_s
    planner = AgentPlanner(args.agent, time_limit_s=args.time_limit, improve_time_s=improve)
    rows = []
    partial = Path(args.out) / 'large.partial.jsonl'     # each row as soon as it is measured
    partial.parent.mkdir(parents=True, exist_ok=True)
    partial.write_text('')
    for name, kind, scene in cases(grids, args.seeds, args.seed, large):
        row = measure(planner, name, kind, scene)
        rows.append(row)
        with partial.open('a') as f:
            f.write(json.dumps(row) + '\n')
        print(f"{name:16s} blocks {row['blocks']:3d} placed {row['placed']:3d} planning {row['planning_s']:7.1f} s "
              f"({row['s_per_block']:.2f} s/block) built {row['built']:.3f} lost {len(row['lost'])}", flush=True)
    command = 'python benchmarks/bench_large.py ' + ' '.join(sys.argv[1:] if argv is None else argv)
    write(rows, Path(args.out), command.strip(), args.agent)
    partial.unlink()
    print(f'wrote {Path(args.out) / "large.md"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

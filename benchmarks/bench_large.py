"""Planning time and coverage against structure size: up to 100 blocks from a feeder, large voxel designs.

    python benchmarks/bench_large.py [--agent default] [--grids 4,6,8,10] [--seeds 3] [--seed 7000]
                                     [--large all] [--designs none] [--effector hand] [--time-limit 120]
                                     [--improve-time-s S] [--unit 0.02] [--supply-time-limit 10]
                                     [--out docs/results] [--page large]

For each generated two-sided scene (g in --grids, seeds --seed.., unseen by training; from
g = 7 or 8 on the generator puts the blocks in a feeder, the table within reach being too
small) and each large hand-made target (`rad_core.domain.large_shapes`, 45 to 100 blocks, all in a
feeder; the two-deep flush walls, which a hand that only sets blocks down cannot fill (`large_shapes.FLUSH_LIMIT`),
as a group of their own) and each voxel design named by --designs (names of `common.designs()`,
300-2,100 cells, and of `common.thin_designs()`, letters, stairs and towers two cells deep,
comma-separated; 'all' for the first, 'thin' for the second; default none; each made a scene by `common.design_scene`,
the code of `rad scene from-voxels`: --unit, supply's CP-SAT limit --supply-time-limit, the hand's order
asked, --supply auto; kind 'design'), the agent plans with the robot in the loop in process
(`AgentPlanner`: CP-SAT, the sequencer, GAMP on the planning twin, re-allocation; --time-limit s per
structure, the arm carrying --effector, hand or suction), then the twin builds the plan (teleporting
execution, physics settling after each block, the same effector) and motion capture registers it.
Per structure it records the blocks in the scene, the blocks placed, the planning time and
its stages, the predicted and the built coverage, the failures (blocks the build lost) and, after
planning, an upper bound on what any top-down build reaches (`sequencing.planning.courses.course_bound`,
the parallel hand's); a design's row also carries its supply report's `covered` (target cells the chosen
blocks cover), `stands` (the supply's order keeps them standing) and `supply_s`, and the page compares the
cells built against the cells covered (the cells that can stand, where stands). It writes
<out>/<page>.md and <out>/<page>.rows.jsonl (`common.write_page`; --page, default large) and
<out>/../img/<page>.png (docs/img/large.png by default: planning time per placed block against the
blocks in the scene: the issue asks that it grow no faster than linearly, i.e. that the time per block
stay flat or grow at most linearly). A design-only run names its own page (--page large_designs) so that
large.md stays. While it runs, <out>/<page>.partial.jsonl holds the rows measured so far (removed once
the results are written).

"""

from __future__ import annotations

import argparse
import json
import shlex
import statistics
import sys
import time
from pathlib import Path

from common import RESULTS, design_scene, designs, fmt, thin_designs, write_page


def design_cases(names: list[str], unit: float, supply_time_limit: float):
    """(name, 'design', scene, supply's figures) for each voxel design named, as bench_designs makes it;
    a design that cannot become a scene is said and skipped."""
    from rad_core.domain.errors import RadError
    grids = {**designs(), **thin_designs()}
    for name in names:
        t0 = time.perf_counter()
        try:
            scene, report, fit = design_scene(name, grids[name], unit, supply_time_limit)
        except RadError as e:
            print(f'{name}: no scene: {e}', file=sys.stderr, flush=True)
            continue
        yield name, 'design', scene, {'covered': report.covered, 'stands': report.stands,
                                      'hand_covered': report.hand_covered, 'supply_status': report.status,
                                      'fit': fit, 'supply_s': round(time.perf_counter() - t0, 1)}


def cases(grids, seeds: int, seed0: int, large: list[str], designs=(), unit: float = 0.02,
          supply_time_limit: float = 10.0):
    """(name, kind, scene, extra row fields) of each structure, made as it is reached."""
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.domain.large_shapes import FLUSH, large_scene
    for g in grids:
        for s in range(seed0, seed0 + seeds):
            yield f'g{g}-s{s}', f'generated g={g}', generate_scene(GeneratorConfig(grid=g, sides=2), s), {}
    for name in large:
        yield name, 'large two-deep flush' if name in FLUSH else 'large hand-made', large_scene(name), {}
    yield from design_cases(list(designs), unit, supply_time_limit)


def measure(planner, name: str, kind: str, scene, effector: str = 'hand', extra=None) -> dict:
    from rad_core.domain.coverage import measured_coverage
    from rad_core.sequencing.execution.twin_build import build_teleported
    t0 = time.perf_counter()
    plan = planner(scene, None, 0)
    planning = time.perf_counter() - t0
    t1 = time.perf_counter()
    registered = build_teleported(scene, plan.steps, effector=effector)
    build_s = time.perf_counter() - t1
    placed = len(plan.steps)
    built = measured_coverage(registered.scene)
    from rad_core.sequencing.planning.courses import course_bound
    row = {'case': name, 'kind': kind, 'blocks': len(scene.blocks), 'cells': scene.num_target_cells,
           'feeder': scene.feeder is not None, 'placed': placed, 'planning_s': round(planning, 2),
           's_per_block': round(planning / max(placed, 1), 3),
           'predicted': round(plan.predicted_coverage, 3), 'built': round(built, 3),
           'course_bound': round(course_bound(scene), 3),
           'lost': sorted(registered.set_aside), 'success': plan.success, 'reason': plan.reason[:300],
           'stages': {k: round(v, 2) for k, v in plan.timings.items()}}
    if extra:       # a design: built cells against the cells its supply covers
        row['built_cells'] = round(built * scene.num_target_cells)
        row['built_of_covered'] = round(row['built_cells'] / max(extra['covered'], 1), 3)
        if extra.get('hand_covered'):
            row['built_of_placeable'] = round(row['built_cells'] / extra['hand_covered'], 3)
        row['build_s'] = round(build_s, 1)
        row.update(extra)
    return row


def plot(rows: list[dict], out: Path, agent: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for kind, marker in (('generated', 'o'), ('large hand-made', 's'), ('large two-deep flush', 'x'),
                         ('design', '^')):
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


DESIGN_HEADERS = ('covered', 'stands', 'hand places', 'built cells', 'built / covered', 'built / hand places')


def headers(rows: list[dict]) -> tuple:
    """HEADERS, and the designs' columns where a row is a design."""
    return HEADERS + (DESIGN_HEADERS if any('covered' in r for r in rows) else ())


def table(rows: list[dict]) -> list[list]:
    designs = any('covered' in r for r in rows)
    out = []
    for r in rows:
        line = [r['case'], r['blocks'], 'yes' if r['feeder'] else 'no', r['cells'], r['placed'],
                f"{r['planning_s']:.1f}", f"{r['s_per_block']:.2f}", f"{r['predicted']:.3f}", f"{r['built']:.3f}",
                f"{r['course_bound']:.3f}", len(r['lost'])]
        if designs:
            line += ([r['covered'], 'yes' if r['stands'] else 'no', fmt(r.get('hand_covered'), 'd'), r['built_cells'],
                      f"{r['built_of_covered']:.3f}", fmt(r.get('built_of_placeable'), '.3f')]
                     if 'covered' in r else [''] * len(DESIGN_HEADERS))
        out.append(line)
    return out


def note(rows: list[dict], agent: str, effector: str = 'hand', image: str = 'large.png') -> str:
    groups = []
    for kind in dict.fromkeys(r['kind'] for r in rows):
        sel = [r for r in rows if r['kind'] == kind]
        groups.append(f"{kind} {statistics.mean(r['built'] for r in sel):.3f}")
    text = (f'Agent `{agent}`, robot in the loop' + ('' if effector == 'hand' else f' (effector {effector})') +
            ', the plan built by the teleporting twin. "bound": '
            '`course_bound`, the most any top-down build reaches. Mean built coverage: ' + '; '.join(groups) +
            f". Slowest plan {max(r['planning_s'] for r in rows):.1f} s. ")
    if any('covered' in r for r in rows):
        text += ('Designs (bench_designs.py, made scenes by `design_scene`): covered, the target cells the '
                 "supply's blocks cover; stands, whether its order keeps them standing (then covered is the "
                 'cells that can stand; otherwise an upper bound on them); hand places, the covered cells the '
                 "hand's order model (`allocation.order.hand_order`: each piece held from above past what is "
                 'built, resting, the whole standing after each) places in one order: cells that can stand, a '
                 'lower bound; built / covered and built / hand places, the cells the twin built over each (the '
                 'issue asks at least 0.9 of the cells that can stand, which lie between the two). ')
    return text + f'![planning time per block and coverage against size](../img/{image})'


def write(rows: list[dict], out: Path, command: str, agent: str, page: str = 'large', effector: str = 'hand',
          **meta) -> Path:
    image = out.parent / 'img' / f'{page}.png'    # beside <out>, as the page links it (docs/img for docs/results)
    image.parent.mkdir(parents=True, exist_ok=True)
    plot(rows, image, agent if effector == 'hand' else f'{agent}, {effector}')
    return write_page(page, f'Planning against structure size, up to {max(r["blocks"] for r in rows)} blocks',
                      headers(rows), table(rows), note(rows, agent, effector, image.name), rows, command=command,
                      results=out, **meta)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--agent', default='default', help="the agent (default: what /plan_assembly runs)")
    ap.add_argument('--grids', default='4,6,8,10')
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--seed', type=int, default=7000, help='first seed of the generated scenes')
    ap.add_argument('--large', default='all', help="comma-separated large shapes, 'all' or 'none'")
    ap.add_argument('--time-limit', type=float, default=120.0,
                    help="planning time limit per structure (s); 120: the assembly node's default")
    ap.add_argument('--improve-time-s', type=float, default=None,
                    help="anytime planning's budget after the first plan (default: the assembly node's, "
                         "agent_plan.IMPROVE_TIME_S)")
    ap.add_argument('--designs', default='none',
                    help="comma-separated voxel designs of common.designs() or common.thin_designs(); "
                         "'all' (the large ones), 'thin' or 'none'")
    ap.add_argument('--effector', default='hand', choices=('hand', 'suction'),
                    help='what the arm carries, in planning and in the twin')
    ap.add_argument('--unit', type=float, default=0.02, help="the designs' cell (m), as bench_designs")
    ap.add_argument('--supply-time-limit', type=float, default=10.0,
                    help="the designs' supply CP-SAT time limit (s), as bench_designs")
    ap.add_argument('--out', default=str(RESULTS), help='results folder; the plot goes to <out>/../img/')
    ap.add_argument('--page', default='large', help='page name: <out>/<page>.md, .rows.jsonl, ../img/<page>.png')
    args = ap.parse_args(argv)
    from rad_core.domain.large_shapes import LARGE_SPECS
    from rad_core.sequencing.agent.agent_plan import IMPROVE_TIME_S, AgentPlanner
    grids = [int(g) for g in args.grids.split(',') if g]
    large = list(LARGE_SPECS) if args.large == 'all' else [n for n in args.large.split(',') if n and n != 'none']
    sets = {'all': list(designs()), 'thin': list(thin_designs())}
    known = sets['all'] + sets['thin']
    named = sets.get(args.designs) or [n for n in args.designs.split(',') if n and n != 'none']
    if unknown := [n for n in named if n not in known]:
        ap.error(f"unknown design(s) {', '.join(unknown)}; known: {', '.join(known)}")
    improve = IMPROVE_TIME_S if args.improve_time_s is None else args.improve_time_s
    planner = AgentPlanner(args.agent, time_limit_s=args.time_limit, improve_time_s=improve, effector=args.effector)
    rows = []
    out = Path(args.out)
    partial = out / f'{args.page}.partial.jsonl'     # each row as soon as it is measured
    partial.parent.mkdir(parents=True, exist_ok=True)
    partial.write_text('')
    for name, kind, scene, extra in cases(grids, args.seeds, args.seed, large, named, args.unit,
                                          args.supply_time_limit):
        row = measure(planner, name, kind, scene, args.effector, extra)
        rows.append(row)
        with partial.open('a') as f:
            f.write(json.dumps(row) + '\n')
        print(f"{name:16s} blocks {row['blocks']:3d} placed {row['placed']:3d} planning {row['planning_s']:7.1f} s "
              f"({row['s_per_block']:.2f} s/block) built {row['built']:.3f} lost {len(row['lost'])}"
              + (f" covered {row['covered']} stands {row['stands']} built cells {row['built_cells']} "
                 f"({row['built_of_covered']:.3f} of covered)" if 'covered' in row else '')
              + ('' if row['success'] else f" not success: {row['reason'][:120]}"), flush=True)
    if not rows:
        print('nothing measured', file=sys.stderr)
        return 1
    command = 'python benchmarks/bench_large.py ' + shlex.join(sys.argv[1:] if argv is None else argv)
    write(rows, out, command.strip(), args.agent, args.page, args.effector)
    planner.close()
    partial.unlink()
    print(f'wrote {out / (args.page + ".md")}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

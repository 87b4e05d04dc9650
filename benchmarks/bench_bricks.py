"""Studded bricks with the robot in the loop: Duplo-style tasks of 2-12 bricks and brick designs read
with `rad scene from-bricks`, built by pressing each brick home onto the studs under it.

    python benchmarks/bench_bricks.py [--unit 0.03] [--effectors hand,suction] [--agent default]
                                      [--seeds 2] [--execution simulate] [--results docs/results]
                                      [--sets duplo,designs,lego] [--lego-unit 0.016] [--baseplate]
                                      [--only NAMES] [--page bricks]

Tasks: `rad_core.domain.brick_tasks.duplo_task(n, seed)` for n = 2..12, the first `--seeds` seeds
of each n whose design stands with Duplo's clutch (`allocation.brick_scenes.design_verdict`; the
others are counted, as a user's design that falls is refused). Designs: the files in scenes/bricks/
(text and LDraw, LEGO and Duplo). LEGO (`--sets lego`): the LEGO-style designs of 26-186 bricks
`brick_tasks.lego_designs` makes (walls, a tower, letters, an arch, a chair; those that stand with
clutch), at `--lego-unit`, the system's proportions kept. Each becomes a scene as
`rad scene from-bricks --unit U [--baseplate]` makes it
(the design's own bricks laid out on the table, or waiting in a feeder where they do not fit) and is
planned by the agent with the robot in the loop and built in a fresh twin, whose arm presses every
brick home (`sim.clutch`). Writes docs/results/bricks.md (or `--page`) and one row per design. Run it on a quiet
machine: planning stages have time budgets.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from common import RESULTS, write_page
from rad_core.allocation.brick_scenes import design_verdict, lattice_of, scene_from_design
from rad_core.domain.brick_designs import parse_text, read_design
from rad_core.domain.brick_tasks import duplo_task, lego_designs
from rad_core.experiment.evaluation import get_agent, robot_planner, scene_episode, summarize

DESIGNS = Path(__file__).resolve().parents[1] / 'scenes' / 'bricks'


def tasks(unit: float, seeds: int, counts=range(2, 13)) -> tuple[list, int]:
    """(designs that stand, how many drawn fell): the first `seeds` standing seeds of each count."""
    out, fell = [], 0
    for n in counts:
        kept, seed = 0, 0
        while kept < seeds and seed < 50:
            design = duplo_task(n, seed)
            seed += 1
            if design_verdict(design, lattice_of(design, None, unit))[0] == 'falls':
                fell += 1
                continue
            out.append(design)
            kept += 1
    return out, fell


def files() -> list:
    return [read_design(p) for p in sorted(DESIGNS.iterdir()) if p.suffix in ('.txt', '.ldr', '.mpd')]


def lego(unit: float, baseplate: bool) -> tuple[list, int]:
    """(the LEGO-style designs that stand with clutch, how many fell), as LEGO designs."""
    out, fell = [], 0
    for designs in lego_designs().values():
        for name, text in designs:
            design = replace(parse_text(text, f'{name}.txt', name), system='lego')
            if design_verdict(design, lattice_of(design, None, unit, baseplate=baseplate))[0] == 'falls':
                fell += 1
            else:
                out.append(design)
    return out, fell


class _Timed:
    """The agent's planner, timing its plans (a build's re-plans included); the rest passes through."""

    def __init__(self, planner):
        self.planner, self.seconds = planner, 0.0

    def __call__(self, *args):
        t0 = time.perf_counter()
        try:
            return self.planner(*args)
        finally:
            self.seconds += time.perf_counter() - t0

    def __getattr__(self, name):
        return getattr(self.planner, name)


def _evaluate(agent, scenes: list, execution: str, effector: str) -> dict:
    """`evaluate`'s rows and metrics (robot in the loop, scene i seeded i), each row with plan_s."""
    planner = _Timed(robot_planner(agent, effector=effector))
    rows = []
    try:
        for i, (name, scene) in enumerate(scenes):
            planner.seconds = 0.0
            row = {'name': name, **scene_episode(agent, scene, True, i, execution, planner=planner)}
            rows.append({**row, 'plan_s': planner.seconds})
    finally:
        planner.close()
    return summarize(rows, agent.name)


def run_set(set_name: str, designs: list, unit: float, effector: str, agent, execution: str,
            baseplate: bool = False) -> tuple[list, list]:
    rows, scenes = [], []
    for design in designs:
        scene, _ = scene_from_design(design, None if design.system else 'duplo', unit, baseplate=baseplate)
        lattice = lattice_of(design, None if design.system else 'duplo', unit, baseplate=baseplate)
        alone = design_verdict(design, lattice, clutch=False)[0]
        scenes.append((design.name, scene))
        rows.append({'effector': effector, 'set': set_name, 'name': design.name, 'bricks': len(design.bricks),
                     'system': lattice.system, 'cells': len(design.cells()), 'needs_clutch': alone == 'falls'})
    t0 = time.perf_counter()
    result = _evaluate(agent, scenes, execution, effector)
    seconds = time.perf_counter() - t0
    for row, got in zip(rows, result['scenes']):
        row.update(coverage=got['coverage'], outcome=got['outcome'], steps=got['steps'],
                   failed=got['outcome'].startswith('invalid'), reason=got['reason'] or got['stop_reason'],
                   lost=got.get('lost', {}), replans=got.get('replans', 0), plan_s=got['plan_s'])
    whole = sum(r['coverage'] >= 1.0 - 1e-9 for r in rows)
    plan = sorted(r['plan_s'] for r in rows)
    clutch = [r for r in rows if r['needs_clutch']]
    line = [effector, set_name, str(len(rows)), str(len(clutch)), f"{result['coverage']:.3f}",
            f'{whole}/{len(rows)}', f"{sum(r['coverage'] >= 1 - 1e-9 for r in clutch)}/{len(clutch)}",
            f"{result['f']:g}", str(sum(len(r['lost']) for r in rows)),
            f'{plan[len(plan) // 2]:.1f} / {plan[-1]:.1f}', f'{seconds / max(1, len(rows)):.1f}']
    print(' | '.join(line), flush=True)
    return rows, line


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--unit', type=float, default=0.03, help='stud pitch, m (default 0.03)')
    p.add_argument('--effectors', default='hand,suction')
    p.add_argument('--agent', default='default')
    p.add_argument('--seeds', type=int, default=2, help='standing tasks per brick count')
    p.add_argument('--execution', choices=('teleport', 'simulate'), default='simulate')
    p.add_argument('--sets', default='duplo,designs', help='duplo (tasks), designs (scenes/bricks/), lego '
                   '(the LEGO-style designs of brick_tasks.lego_designs), comma-separated')
    p.add_argument('--lego-unit', type=float, default=0.016, help='stud pitch of the lego set, m (default 0.016: '
                   'LEGO twice its size, the largest at which its designs fit the reach)')
    p.add_argument('--baseplate', action='store_true', help='build on a baseplate (studs.baseplate)')
    p.add_argument('--only', help='only the designs of these names, comma-separated (a subset while iterating)')
    p.add_argument('--page', default='bricks', help='the page (and rows file) it writes (default bricks)')
    p.add_argument('--results', type=Path, default=RESULTS)
    args = p.parse_args()
    agent = get_agent(args.agent)
    chosen = args.sets.split(',')
    unknown = set(chosen) - {'duplo', 'designs', 'lego'}
    if unknown:
        p.error(f'unknown sets: {", ".join(sorted(unknown))} (duplo, designs, lego)')
    drawn, fell = tasks(args.unit, args.seeds) if 'duplo' in chosen else ([], 0)
    walls, lego_fell = lego(args.lego_unit, args.baseplate) if 'lego' in chosen else ([], 0)
    sets = [('duplo tasks', drawn, args.unit), ('designs', files(), args.unit), ('lego', walls, args.lego_unit)]
    if args.only:
        names = set(args.only.split(','))
        sets = [(s, [d for d in designs if d.name in names], unit) for s, designs, unit in sets]
    rows, table = [], []
    for effector in args.effectors.split(','):
        for set_name, designs, unit in sets:
            if set_name.split()[0] not in chosen or not designs:
                continue
            got, line = run_set(set_name, designs, unit, effector, agent, args.execution, args.baseplate)
            rows += got
            table.append(line)
    note = (f'`{args.agent}` (`{agent.name}`) with the robot in the loop, {args.execution} execution, bricks at a '
            f'{args.unit * 1000:g} mm stud pitch. '
            f'duplo tasks: `brick_tasks.duplo_task(n, seed)`, n = 2..12, the first {args.seeds} seeds of each n '
            f'that stand with Duplo\'s clutch ({fell} drawn tasks fell and were passed over, as `rad scene '
            'from-bricks` refuses them); designs: the files in scenes/bricks/; '
            f'lego: `brick_tasks.lego_designs` at a {args.lego_unit * 1000:g} mm pitch ({lego_fell} that fall '
            'even with clutch left out)' + ('; all on a baseplate (`studs.baseplate`)' if args.baseplate else
                                            '; on the bare table') + '. needing clutch: designs that '
            'fall without it. coverage: what the twin finds built, mean over designs; whole: designs built to '
            'the last cell; f: episodes that ended on a failed action; lost: bricks the twin found moved off '
            'their places (each structure the robot built was one the statics stand under its press: a '
            'brick lost is a structure they disagree on); planning s: the plans of a design (its re-plans '
            'included), median and max over designs; s/design: planning and building, mean.')
    page = write_page(args.page, 'Studded bricks pressed home by the robot',
                      ['effector', 'set', 'designs', 'needing clutch', 'coverage', 'whole',
                       'needing clutch whole', 'f', 'lost', 'planning s (median / max)', 's/design'],
                      table, note, rows=rows, results=args.results)
    print(f'wrote {page}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""Does the stability model agree with the twin? Intermediate structures of studded-brick designs
(LEGO-style walls, letters, an arch, a chair, cantilevers too long to stand; the files in
scenes/bricks/; Duplo-style tasks), judged by the statics (`domain.statics.structure_statics`, with
the bricks' clutch) and by the physics twin (`sim.world.World` with its stud joints, `sim.clutch`).

    python benchmarks/bench_statics_twin.py [--quick] [--designs a,b] [--prefixes 5] [--seconds 1.0] [--recheck 4]
                                            [--results docs/results]

A design's bricks are put in a bottom-up order: by course, then the order the statics walk
(`order_statics`, without the press) accepts, the bricks it leaves waiting last. Each prefix of that
order is an intermediate structure; a design gets at most `--prefixes` of them (evenly spaced, the
whole design always, and the two either side of the first brick that waits, where one does).
Besides, structures that should fall: the whole design without clutch (the twin joins no studs), and
the whole design less one brick that holds up an overhang (`less_one`).

The statics' verdict: `structure_statics(grid, pieces, clutch=studs.clutch_in_weights)`. The twin's:
a scene of just the structure's bricks, each at its lattice pose, in a `World` as the twin builds it
(`sim.twin.twin_world_config`), every brick joined to the bricks under it as a pressed or teleported
placement is (`world.studs.join`: one joint per stud, its pull capped at the clutch, broken past
1 mm), the arm turned away from the structure, then `--seconds` of simulated time. A brick has
fallen when one of its unit centres moved more than MOVE_TOL of a stud pitch or it turned more than
TILT_TOL degrees; the structure stands in the twin when none has. Where the two disagree the statics
are asked again at other margins, and a twin with a `--recheck` times shorter time step judges again
(`run_design`). Writes docs/results/statics_twin.md and a row per structure.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rad_core.domain.brick_tasks import lego_designs

sys.path.insert(0, str(Path(__file__).resolve().parent))     # `common`, also where a test loads this file

from common import RESULTS, write_page  # noqa: E402

DESIGNS = Path(__file__).resolve().parents[1] / 'scenes' / 'bricks'

LEGO_UNIT = 0.016
"""The stud pitch (m) of the LEGO-style designs: LEGO bricks at twice their size (Duplo's pitch), the
largest unit at which a design 24 studs wide and 20 courses high stands within the arm's reach
(`voxels.largest_unit`). Clutch 1 N a stud (LEGO's), a cell 2.3 g: 44 cell weights a stud."""

DUPLO_UNIT = 0.03
"""The stud pitch (m) of the Duplo-style tasks and designs, as benchmarks/bench_bricks.py builds
them. Clutch 2 N a stud (Duplo's), a cell 11.5 g: 17.7 cell weights a stud."""

SECONDS = 1.0
"""Simulated seconds the twin runs a structure: a brick that tips or pulls off its studs has moved
centimetres by then (one exactly over an edge, the slowest, tips past 3 degrees in about 0.3 s:
`sim.physics.PhysicsConfig.max_steps`); most that stand have settled in 0.2 s (an arm may sway on its
stud joints longer: `CHECK_S`)."""

MOVE_TOL = 0.2
"""A brick one of whose unit centres moved more than this (a fraction of the stud pitch) has fallen:
3.2 mm at 16 mm, 6 mm at 30 mm; the robot environment's `structure_tol` and the stability check's
`placed_move` ("the structure is destroyed"). A corbel standing on its studs sags up to about
1.7 mm at its tip in the twin (its stud joints are soft), so the environment's 0.1 for a new
block would call standing corbels fallen."""

TILT_TOL = 3.0
"""...or that turned more than this (degrees; the stability check's `placed_tilt_deg`)."""

CHECK_S = 0.1
"""Every how many simulated seconds the twin looks whether a brick has plainly fallen (`GONE`): it
stops there. Otherwise it judges at the end: a cantilevered arm may sway a few millimetres on its
stud joints for a second before it settles within MOVE_TOL."""

GONE = (1.0, 10.0)
"""A brick that moved a stud pitch or turned 10 degrees has plainly fallen."""

AWAY = (2.6, -0.215, 0.0, -2.57, 0.0, 2.356, 2.356, 0.04, 0.04)
"""The arm's joints while the twin judges: HOME turned 150 degrees about the base, away from the
structure in front of it."""


# ---- a design on its lattice ---------------------------------------------------------------------

@dataclass
class Layout:
    """A design where the arm builds it: its bricks as blocks at their lattice poses, and the grid's
    cells of each (`allocation.brick_scenes.design_verdict` sets a design out the same way)."""

    name: str
    design: object            # BrickDesign, turned as it stands
    lattice: object           # BrickLattice
    scene: object             # Scene: every brick at its place in the target
    grid: object
    pieces: list

    @property
    def clutch(self) -> float:
        """The clutch in cell weights (the statics' unit)."""
        return self.lattice.studs.clutch_in_weights

    def brick(self, n: int) -> str:
        b = self.design.bricks[n]
        return f'b{n} ({b.describe()})'


def layout(design, system: str | None = None, unit: float | None = None, clutch: float | None = None) -> Layout:
    """The design on its lattice (`lattice_of`), where `target_of` puts it: RadError where the arm's
    reach does not allow it at this unit."""
    from rad_core.allocation.brick_scenes import built_blocks, lattice_of, target_of
    from rad_core.domain.grid import Grid
    from rad_core.domain.scene import Scene
    lattice = lattice_of(design, system, unit, clutch)
    placed, region, _ = target_of(design, lattice)
    types, blocks = built_blocks(placed, lattice, region)
    scene = Scene(lattice.unit, types, tuple(blocks), (region,), studs=lattice.studs)
    grid = Grid(scene)
    pieces = [np.asarray(grid.cells_at(scene.unit_positions(b)), dtype=int) for b in blocks]
    return Layout(design.name, placed, lattice, scene, grid, pieces)


def build_order(lay: Layout) -> tuple[list[int], int]:
    """(the bricks bottom-up: by course, then as the statics walk accepts them, those it leaves
    waiting last; how many wait)."""
    from rad_core.domain.statics import order_statics
    by_course = sorted(range(len(lay.pieces)), key=lambda n: (lay.design.bricks[n].z, n))
    walk, waiting = order_statics(lay.grid, [lay.pieces[n] for n in by_course], clutch=lay.clutch, press=False)
    return [by_course[i] for i in walk] + [by_course[i] for i in waiting], len(waiting)


@dataclass
class Verdict:
    """One judge's verdict on a structure: whether it stands, the bricks (design indices) that fall
    and, for the statics, why; for the twin, the largest movement (m) and turn (deg) of any brick."""

    stands: bool
    falling: tuple = ()
    why: tuple = ()
    moved: float = 0.0
    turned: float = 0.0
    broken: int = 0
    """Stud joints that let go (the twin's)."""
    at: float = 0.0
    """When (simulated s) the twin gave its verdict: the first look that found a brick gone (`GONE`),
    else the end."""


def statics_verdict(lay: Layout, bricks, clutch: bool = True) -> Verdict:
    """`structure_statics` of these bricks (design indices) with the bricks' clutch (or none)."""
    from rad_core.domain.statics import structure_statics
    bricks = list(bricks)
    got = structure_statics(lay.grid, [lay.pieces[n] for n in bricks], clutch=lay.clutch if clutch else None)
    return Verdict(got.stands, tuple(bricks[i] for i in got.falling), tuple(got.why))


class Twin:
    """A physics world in which structures of one design's bricks are judged (module docstring).
    One World, its scene reloaded for each structure."""

    def __init__(self, config=None):
        """config: the `WorldConfig` (default: the twin's, `twin_world_config`)."""
        from rad_core.sim.twin import twin_world_config
        from rad_core.sim.world import World, WorldConfig
        self.world = World(None, config or twin_world_config(WorldConfig()))

    def close(self) -> None:
        self.world.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __call__(self, lay: Layout, bricks, clutch: bool = True, seconds: float = SECONDS) -> Verdict:
        from dataclasses import replace

        from rad_core.domain.transforms import quaternion_angle_deg
        bricks = list(bricks)
        base = lay.scene
        scene = replace(base, blocks=tuple(base.blocks[n] for n in bricks))
        world = self.world
        world.load_scene(scene)
        world.set_joint_positions(AWAY)
        ids = [base.blocks[n].id for n in bricks]
        if clutch:
            for block_id in ids:
                world.studs.join(world, block_id)       # pressed home onto the studs under it
        before = {b: (world.unit_centres(b), world.block_pose(b)[1]) for b in ids}
        tol = MOVE_TOL * lay.scene.unit
        dt = world.config.physics.time_step
        total, every, done = int(round(seconds / dt)), max(1, int(round(CHECK_S / dt))), 0
        while True:
            falling, worst_move, worst_turn, gone = [], 0.0, 0.0, False
            for n, b in zip(bricks, ids):
                centres, q = before[b]
                move = float(np.linalg.norm(world.unit_centres(b) - centres, axis=1).max())
                turn = quaternion_angle_deg(q, world.block_pose(b)[1])
                worst_move, worst_turn = max(worst_move, move), max(worst_turn, turn)
                if move > tol or turn > TILT_TOL:
                    falling.append(n)
                gone = gone or move > GONE[0] * lay.scene.unit or turn > GONE[1]
            if gone or done >= total:
                break
            world.step(min(every, total - done))
            done += min(every, total - done)
        return Verdict(not falling, tuple(falling), (), worst_move, worst_turn, len(world.studs.broken), done * dt)


def judge(lay: Layout, bricks, twin: Twin, clutch: bool = True, seconds: float = SECONDS) -> tuple[Verdict, Verdict]:
    """(the statics' verdict, the twin's) on the structure of these bricks (design indices), with the
    bricks' clutch or without it."""
    return statics_verdict(lay, bricks, clutch), twin(lay, bricks, clutch, seconds)


# ---- the structures of a design --------------------------------------------------------------------

def less_one(lay: Layout, tries: int = 8) -> tuple[int, Verdict] | None:
    """A brick under an overhanging brick (from the top course down) whose loss the statics say topples
    the design, one that tips or pulls off where one of `tries` does, else one that leaves something
    resting on nothing, else the first tried: (the brick, the statics' verdict without it)."""
    from rad_core.domain.statics import FLOATS, overhangs
    owner = np.full(lay.grid.num_cells, -1, dtype=int)
    for n, cells in enumerate(lay.pieces):
        owner[cells] = n
    under = []
    for o in sorted(overhangs(lay.grid, lay.pieces), key=lambda n: -lay.design.bricks[n].z):
        below = lay.grid.below_idx[lay.pieces[o]]
        for m in sorted({int(owner[c]) for c in below[below >= 0]} - {-1, o}):
            if m not in under:
                under.append(m)
    seen = []
    for m in under[:tries]:
        rest = [n for n in range(len(lay.pieces)) if n != m]
        verdict = statics_verdict(lay, rest)
        seen.append((m, verdict))
        if not verdict.stands and FLOATS not in verdict.why:
            return m, verdict
    for m, verdict in seen:
        if not verdict.stands:
            return m, verdict
    return seen[0] if seen else None


def structures(lay: Layout, prefixes: int) -> tuple[list[dict], int]:
    """(the structures a design is judged on: kind, bricks, clutch, words; how many prefixes it has)."""
    order, waiting = build_order(lay)
    n = len(order)
    sizes = {max(1, round(n * i / prefixes)) for i in range(1, prefixes + 1)} | {n}
    if waiting:
        sizes |= {n - waiting, n - waiting + 1} - {0}
    out = [{'kind': 'prefix', 'bricks': order[:k], 'clutch': True, 'size': k, 'last': order[k - 1]}
           for k in sorted(sizes)]
    out.append({'kind': 'no clutch', 'bricks': order, 'clutch': False, 'size': n, 'last': None})
    less = less_one(lay)
    if less is not None:
        m = less[0]
        out.append({'kind': 'less one', 'bricks': [b for b in order if b != m], 'clutch': True, 'size': n - 1,
                    'last': None, 'removed': m})
    return out, n


# ---- the design sets -------------------------------------------------------------------------------

DUPLO_COUNTS = (8, 12, 16, 20, 24)
QUICK_COUNTS = (8, 16)
QUICK_FILES = ('letter_t.txt', 'duplo_bridge_tower.ldr')


def design_sets(quick: bool = False) -> list[tuple[str, object, str, float]]:
    """(set, BrickDesign, system, unit) of every design judged."""
    from rad_core.domain.brick_designs import parse_text, read_design
    out = []
    for set_name, designs in lego_designs(quick).items():
        out += [(set_name, parse_text(text, f'{name}.txt', name), 'lego', LEGO_UNIT) for name, text in designs]
    for path in sorted(DESIGNS.iterdir()):
        if path.suffix in ('.txt', '.ldr', '.mpd') and (not quick or path.name in QUICK_FILES):
            design = read_design(path)
            system = design.system or 'lego'
            out.append(('scenes/bricks', design, system, LEGO_UNIT if system == 'lego' else DUPLO_UNIT))
    for n in (QUICK_COUNTS if quick else DUPLO_COUNTS):
        out += [('duplo tasks', task, 'duplo', DUPLO_UNIT) for task in duplo_tasks(n, 1 if quick else 2)]
    return out


def duplo_tasks(n: int, count: int) -> list:
    """The first `count` tasks of n bricks `duplo_task` draws (a seed whose bricks find no place is passed over)."""
    from rad_core.domain.brick_tasks import duplo_task
    from rad_core.domain.errors import RadError
    out = []
    for seed in range(20):
        try:
            out.append(duplo_task(n, seed))
        except RadError:
            continue
        if len(out) == count:
            break
    return out


# ---- the run ---------------------------------------------------------------------------------------

def fine_config(substeps: int = 4):
    """The twin's world with a time step `substeps` times shorter (the rechecks')."""
    from dataclasses import replace

    from rad_core.sim.twin import twin_world_config
    from rad_core.sim.world import WorldConfig
    base = twin_world_config(WorldConfig())
    return replace(base, physics=replace(base.physics, time_step=base.physics.time_step / substeps))


MARGINS = (0.1, 0.2, 0.3)
"""Margins (cells) the statics are asked again with where they say a structure stands that the twin
says falls: how close to its edge the structure is."""


def statics_margin(lay: Layout, bricks, clutch: bool, stands: bool) -> str:
    """Where the statics say it stands: the smallest of `MARGINS` at which they say it falls. Where
    they say it falls: their verdict with the corner forces at the twin's own play from the edges
    (`sim.twin.BLOCK_PLAY`) rather than `statics.MARGIN`."""
    from rad_core.domain.statics import structure_statics
    from rad_core.sim.twin import BLOCK_PLAY
    pieces = [lay.pieces[n] for n in bricks]
    limit = lay.clutch if clutch else None
    if stands:
        for m in MARGINS:
            if not structure_statics(lay.grid, pieces, margin=m, clutch=limit, explain=False).stands:
                return f'falls from margin {m:g}'
        return f'stands at margin {MARGINS[-1]:g} too'
    got = structure_statics(lay.grid, pieces, margin=BLOCK_PLAY, clutch=limit, explain=False).stands
    return f"{'stands' if got else 'falls'} at margin {BLOCK_PLAY:g}"


def run_design(set_name: str, design, system: str, unit: float, twin: Twin, prefixes: int,
               seconds: float, fine: Twin | None = None) -> list[dict]:
    """One row per structure of the design. Where the two disagree, the statics are asked again at
    other margins (`statics_margin`), and `fine` (the twin with a shorter time step), where given,
    judges again."""
    lay = layout(design, system, unit)
    todo, n = structures(lay, prefixes)
    rows = []
    for s in todo:
        t0 = time.perf_counter()
        st = statics_verdict(lay, s['bricks'], s['clutch'])
        t1 = time.perf_counter()
        tw = twin(lay, s['bricks'], s['clutch'], seconds)
        t2 = time.perf_counter()
        rows.append({'set': set_name, 'design': design.name, 'system': lay.lattice.system, 'unit': unit,
                     'design_bricks': n, 'kind': s['kind'], 'size': s['size'], 'clutch': s['clutch'],
                     'last': None if s['last'] is None else lay.brick(s['last']),
                     'removed': lay.brick(s['removed']) if 'removed' in s else None,
                     'statics_stands': st.stands, 'statics_falling': [lay.brick(b) for b in st.falling],
                     'statics_why': st.why[0] if st.why else '',
                     'twin_stands': tw.stands, 'twin_falling': [lay.brick(b) for b in tw.falling],
                     'moved_mm': tw.moved * 1000, 'turned_deg': tw.turned, 'broken_studs': tw.broken, 'at_s': tw.at,
                     'agree': st.stands == tw.stands, 'statics_s': t1 - t0, 'twin_s': t2 - t1,
                     'statics_margin': None, 'fine_stands': None, 'fine_moved_mm': None, 'fine_s': 0.0,
                     'cause': None})
    for s, row in zip(todo, rows):
        if row['agree']:
            continue
        row['statics_margin'] = statics_margin(lay, s['bricks'], s['clutch'], row['statics_stands'])
        if fine is not None:
            t0 = time.perf_counter()
            again = fine(lay, s['bricks'], s['clutch'], seconds)
            row.update(fine_stands=again.stands, fine_moved_mm=again.moved * 1000, fine_broken=again.broken,
                       fine_at_s=again.at, fine_s=time.perf_counter() - t0)
        row['cause'] = cause(row)
    return rows


CAUSES = {
    'step': "the twin's time step: with a shorter one the twin agrees",
    'step?': 'not rechecked (`--recheck 0`)',
    'edge': "near an edge: the statics stand it only at small margins (corner forces less than 0.3 of a "
            "stud in from the edges), and the twin with a shorter step lets it go too",
    'margin': "the statics' margin: with the corner forces at the twin's play from the edges they agree",
    'other': 'neither the time step nor the margin',
}
"""What a disagreement comes down to (`cause`), from the rechecks."""


def cause(row: dict) -> str:
    """The key in CAUSES of a disagreement's row."""
    if row['fine_stands'] is not None and row['fine_stands'] == row['statics_stands']:
        return 'step'
    if row['statics_stands']:
        if row['statics_margin'].startswith('falls from'):
            return 'edge'
        return 'step?' if row['fine_stands'] is None else 'other'
    return 'margin' if row['statics_margin'].startswith('stands') else 'other'


def _names(bricks: list[str], most: int = 3) -> str:
    head = ', '.join(bricks[:most])
    return head + (f' and {len(bricks) - most} more' if len(bricks) > most else '')


def disagreement(row: dict, substeps: int = 4) -> str:
    """One line for a structure on which the two disagree."""
    what = {'prefix': f"the first {row['size']} bricks (the last {row['last']})",
            'no clutch': f"all {row['size']} bricks without clutch",
            'less one': f"all but {row['removed']}"}[row['kind']]
    if row['statics_stands']:
        verdict = (f"the statics say it stands ({row['statics_margin']}); in the twin {_names(row['twin_falling'])} "
                   f"fell within {row['at_s']:.1f} s (up to {row['moved_mm']:.1f} mm, {row['turned_deg']:.1f} deg, "
                   f"{row['broken_studs']} studs let go)")
    else:
        verdict = (f"the statics say {_names(row['statics_falling'])} fall ({row['statics_why']}; "
                   f"{row['statics_margin']}); the twin stands (up to {row['moved_mm']:.1f} mm, "
                   f"{row['turned_deg']:.1f} deg)")
    if row['fine_stands'] is not None:
        how = f"{row['fine_moved_mm']:.1f} mm" + ('' if row['fine_stands'] else f" within {row['fine_at_s']:.1f} s")
        verdict += (f"; with a {substeps} times shorter time step the twin says it "
                    f"{'stands' if row['fine_stands'] else 'falls'} ({how}): "
                    f"{'agrees' if row['fine_stands'] == row['statics_stands'] else 'disagrees'}")
    return f"- {row['design']} ({row['set']}), {what}: {verdict} [{cause(row)}]"


def table(rows: list[dict], set_order: list[str]) -> list[list[str]]:
    out = []
    for name in [*set_order, 'all']:
        got = [r for r in rows if name == 'all' or r['set'] == name]
        if not got:
            continue
        designs = sorted({r['design'] for r in got}, key=[r['design'] for r in got].index)
        sizes = [next(r['design_bricks'] for r in got if r['design'] == d) for d in designs]
        again = [r for r in got if r['fine_stands'] is not None]
        out.append([name, str(len(designs)), f'{min(sizes)}-{max(sizes)}', str(len(got)),
                    f"{sum(r['statics_stands'] for r in got)} / {sum(not r['statics_stands'] for r in got)}",
                    f"{sum(r['twin_stands'] for r in got)} / {sum(not r['twin_stands'] for r in got)}",
                    f"{sum(r['agree'] for r in got)}/{len(got)}", str(sum(not r['agree'] for r in got)),
                    f"{sum(r['fine_stands'] == r['statics_stands'] for r in again)}/{len(again)}" if again else '',
                    f"{sum(r['statics_s'] for r in got):.1f}",
                    f"{sum(r['twin_s'] for r in got):.0f} + {sum(r['fine_s'] for r in got):.0f}"])
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--quick', action='store_true', help='a few small designs, 4 prefixes each (a smoke test; '
                                                        'writes under out/ unless --results is given)')
    p.add_argument('--prefixes', type=int, help='intermediate structures per design, at most (default 5; 4 quick)')
    p.add_argument('--seconds', type=float, default=SECONDS, help=f'simulated seconds a structure runs '
                                                                  f'(default {SECONDS:g})')
    p.add_argument('--recheck', type=int, default=4, help='judge disagreements again in a twin whose time step is '
                                                          'this many times shorter (default 4; 0: not)')
    p.add_argument('--results', type=Path, help='where the page goes (default docs/results; quick: out/)')
    p.add_argument('--designs', help='only these designs (names, comma-separated; a subset while iterating: '
                                     'writes under out/ unless --results is given)')
    args = p.parse_args(argv)
    only = set(args.designs.split(',')) if args.designs else None
    prefixes = args.prefixes or (4 if args.quick else 5)
    results = args.results or (RESULTS.parents[1] / 'out' / 'statics_twin_quick' if args.quick or only else RESULTS)
    t0 = time.perf_counter()
    rows, set_order = [], []
    fine = Twin(fine_config(args.recheck)) if args.recheck > 1 else None
    try:
        with Twin() as twin:
            for set_name, design, system, unit in design_sets(args.quick):
                if only is not None and design.name not in only:
                    continue
                if set_name not in set_order:
                    set_order.append(set_name)
                got = run_design(set_name, design, system, unit, twin, prefixes, args.seconds, fine)
                rows += got
                bad = [r for r in got if not r['agree']]
                print(f"{set_name:24s} {design.name:20s} {got[0]['design_bricks']:4d} bricks {len(got):3d} structures "
                      f"{sum(r['twin_s'] + r['fine_s'] for r in got):6.1f} s  disagree {len(bad)}", flush=True)
                for r in bad:
                    print('   ', disagreement(r, args.recheck), flush=True)
    finally:
        if fine is not None:
            fine.close()
    wall_s = time.perf_counter() - t0
    from rad_core.sim.twin import twin_world_config
    from rad_core.sim.world import WorldConfig
    world_config = twin_world_config(WorldConfig())
    lines = table(rows, set_order)
    bad = [r for r in rows if not r['agree']]
    again = [r for r in bad if r['fine_stands'] is not None]
    sag = max((r['moved_mm'] for r in rows if r['twin_stands']), default=0.0)
    counts = QUICK_COUNTS if args.quick else DUPLO_COUNTS
    note = (
        f"Every structure judged twice: by the statics (`domain.statics.structure_statics`, the bricks' "
        f"clutch as stud pulls, corner forces `statics.MARGIN` in from the edges) and by the physics twin "
        f"(a `sim.world.World` as the twin builds it, `sim.twin.twin_world_config`: a 1/240 s step, "
        f"simulated in a studded scene as {world_config.stud_substeps} steps of "
        f"{world_config.stud_solver_iterations} solver iterations (`WorldConfig.stud_substeps`), "
        f"0.01 of a stud of play a side; holding just the structure's bricks at their "
        f"lattice poses, each joined to the bricks under it as a pressed placement is, `world.studs.join`: one "
        f"joint a stud, its pull capped at the clutch, let go past 1 mm; the arm turned away; then "
        f"{args.seconds:g} s simulated). In the twin a brick has fallen when a unit centre moved more than "
        f"{MOVE_TOL:g} of the stud pitch or it turned more than {TILT_TOL:g} deg by the end; the twin stops "
        f"early, at a look every {CHECK_S:g} s, once a brick moved a whole stud pitch or turned "
        f"{GONE[1]:g} deg (the bricks named had fallen by then). The largest movement in a structure the twin "
        f"says stands was {sag:.2f} mm.\n\n"
        f"Designs: LEGO-style ones the benchmark makes in the text format, every brick resting on at least "
        f"one stud of the course under it (walls one and two studs deep of 1 x N and 2 x N bricks in running "
        f"bond whose top courses corbel out past an end; a tower of four bonded walls with a corbel; the "
        f"letters T, E, F, P two studs deep, of which F and P tip over as a whole before they are done; an "
        f"arch whose lintel steps out past a pillar; a chair; two cantilevers too long to stand, one tipping "
        f"its light base over, one pulling its last brick off the studs of a heavy one), and the LEGO "
        f"files of scenes/bricks/, at a {LEGO_UNIT * 1000:g} mm stud pitch (LEGO bricks twice their size: "
        f"the largest pitch at which a design 24 studs wide and 20 courses high fits the arm's reach, "
        f"`voxels.largest_unit`; clutch 1 N a stud, 44 cell weights); the Duplo ones (scenes/bricks/'s and "
        f"the first {1 if args.quick else 2} tasks `brick_tasks.duplo_task(n, seed)` draws for n = "
        f"{', '.join(str(n) for n in counts)}) at {DUPLO_UNIT * 1000:g} mm (clutch 2 N, 17.7 cell "
        f"weights). Structures: the bricks bottom-up (by course, then in the order the statics walk "
        f"`order_statics` accepts, the bricks it leaves waiting last), at most {prefixes} prefixes a design "
        f"(evenly spaced, the whole design always, and where some bricks wait the prefixes either side of "
        f"the first), the whole design without clutch (no joints), and the whole design less one brick that "
        f"holds up an overhang (`less_one`).\n\n"
        f"Where the two disagree, the statics are asked again: where they say it stands, at margins "
        f"{', '.join(f'{m:g}' for m in MARGINS)} (how near its edge it is); where they say it falls, with "
        f"the corner forces at the twin's play (0.01) from the edges. "
        + (f"And a twin with a {args.recheck} times shorter time step (`--recheck`) judges every structure "
           f"they disagree on again; rechecked agree: that twin's verdict against the statics'. "
           if args.recheck > 1 else '')
        + f"statics s: the statics' seconds; twin s: the twin's, plus the rechecks'; the run took {wall_s:.0f} s.\n\n"
        + (f"Disagreements ({len(bad)}; {sum(r['fine_stands'] == r['statics_stands'] for r in again)} of the "
           f"{len(again)} rechecked agree with the shorter time step), each with what it comes down to:\n\n"
           + ''.join(f"- {key}: {words} ({sum(cause(r) == key for r in bad)})\n" for key, words in CAUSES.items())
           + '\n' + '\n'.join(disagreement(r, args.recheck) for r in bad) if bad
           else 'The two agree on every structure.'))
    page = write_page('statics_twin', 'The stability model against the twin, on studded-brick structures',
                      ['set', 'designs', 'bricks', 'structures', 'statics stands / falls', 'twin stands / falls',
                       'agree', 'disagreements', 'rechecked agree', 'statics s', 'twin s'],
                      lines, note, rows=rows, results=results)
    for line in lines:
        print(' | '.join(line))
    print(f'{len(bad)} disagreements; {wall_s:.0f} s; wrote {page}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

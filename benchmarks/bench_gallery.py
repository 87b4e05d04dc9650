"""The gallery: shapes from mesh files made into scenes, planned by an agent, built in the twin.

    python benchmarks/bench_gallery.py [--shapes arch bridge ...] [--agent default] [--unit 0.05]
        [--clearances 0 0.2]

For every mesh of data/meshes/meshes.json (scripts/make_meshes.py), as a user would do it:
`rad scene from-mesh FILE --unit U --size N --up A` (rad_core.domain.voxels, then rad_core.allocation.supply:
the fewest blocks of the default set that cover the target, laid out within reach); the
plan of the agent as the node graph runs it (`AgentPlanner`: CP-SAT, the sequencer, GAMP in
process); its blocks put at their planned poses in a real PyBullet twin, each left to settle
(teleporting execution, as bench_execution.py's reference), and the coverage measured by
registering the world (`coverage.measured_coverage`: a block that fell counts nothing).

Each shape is run once per clearance (the scenes' gap between neighbouring blocks: 0 is
from-mesh's default, flush; 0.2 the paper's 1 cm). Writes docs/gallery/<shape>/ (scene.json,
target.png, before.png, after.png, build.png) for the first clearance, docs/gallery.md (its page:
the command, commit and date, the pictures and figures, the mean coverage per clearance) and
docs/gallery/gallery.rows.jsonl (one line per shape and clearance). Finished runs are cached in
out/cache/gallery/ and skipped when run again (their pictures are not redrawn: clear the cache to
redraw them).
"""

from __future__ import annotations

import argparse
import json
import time

from common import ROOT, cache_dir, command_line, git_commit, read_rows, write_rows

MESHES = ROOT / 'data' / 'meshes'
GALLERY = ROOT / 'docs' / 'gallery'
PICTURE = {'width': 320, 'height': 260}


def make_scene(name: str, entry: dict, unit: float, clearance: float):
    """The scene `rad scene from-mesh` writes for the mesh (with --clearance), and the supply's report."""
    from rad_core.allocation.supply import supply
    from rad_core.domain.blocks import DEFAULT_LIBRARY
    from rad_core.domain.voxels import mesh_models, place_regions
    models = mesh_models([(name, str(MESHES / entry['file']))], unit, size=entry['size'], up=entry['up'])
    return supply(place_regions(models, unit), unit, dict(DEFAULT_LIBRARY), clearance=clearance)


def build(scene, planner) -> tuple[dict, object, list]:
    """Plan, then put every planned block in place in the twin and let it settle (as
    bench_execution.run_teleport); the measured figures, the registered end state, the steps."""
    from rad_core.domain.coverage import measured_coverage
    from rad_core.domain.transforms import yaw_quaternion
    from rad_core.sim.twin import Twin, twin_world_config
    from rad_core.sim.world import World
    t0 = time.perf_counter()
    plan = planner(scene, None)
    planning_s = time.perf_counter() - t0
    with World(scene, twin_world_config()) as world:
        twin = Twin(world)
        for step in plan.steps:
            world.set_block_pose(step.block, step.position, yaw_quaternion(step.yaw))
            twin.settle(0.5)
        registered = twin.registration()      # a block that fell over is set aside, not counted
    final = registered.scene
    steps = [s.to_dict() for s in plan.steps]
    figures = {'coverage': measured_coverage(final) if final is not None else 0.0,
               'predicted_coverage': plan.predicted_coverage, 'steps': len(steps),
               'reallocations': len(plan.reallocations),
               'planning_s': plan.timings.get('total', planning_s), 'success': plan.success,
               'reason': plan.reason, 'lost': dict(registered.set_aside)}
    return figures, final, steps


def run_shape(name: str, entry: dict, unit: float, clearance: float, planner, pictures: bool) -> dict:
    from rad_core.view.render import save_build_pictures, save_scene_png
    t0 = time.perf_counter()
    scene, report = make_scene(name, entry, unit, clearance)
    out = GALLERY / name
    figures, final, steps = build(scene, planner)
    if pictures:
        out.mkdir(parents=True, exist_ok=True)
        (out / 'scene.json').write_text(scene.dumps() + '\n')
        save_scene_png(scene, out / 'target.png', **PICTURE)
        save_build_pictures(scene, final, steps, out, **PICTURE)
    region = scene.targets[0]
    return {'shape': name, 'file': entry['file'], 'size': entry['size'], 'up': entry['up'], 'clearance': clearance,
            'cells': scene.num_target_cells, 'box': list(region.size), 'blocks': len(scene.blocks),
            'counts': {k: v for k, v in scene.type_counts().items() if v}, 'supply_exact': report.exact,
            'supply_coverage': report.coverage, **figures, 'wall_s': time.perf_counter() - t0}


ROWS = ROOT / 'docs' / 'gallery' / 'gallery.rows.jsonl'


def write_tables(rows: list[dict], agent: str, command: str) -> None:
    # The reason a plan stopped names every action tried: its first 200 characters are enough here.
    write_rows(ROWS, [{**r, 'reason': r['reason'][:200]} for r in rows])
    first = rows[0]['clearance'] if rows else 0.0
    write_gallery_page([r for r in rows if r['clearance'] == first], agent, command, means(rows))


def means(rows: list[dict]) -> str:
    """One sentence: mean coverage and complete builds per clearance."""
    parts = []
    for clearance in dict.fromkeys(r['clearance'] for r in rows):
        part = [r for r in rows if r['clearance'] == clearance]
        parts.append(f'{sum(r["coverage"] for r in part) / len(part):.3f} '
                     + ('flush' if clearance == 0 else f'at clearance {clearance:g}')
                     + f' ({sum(r["coverage"] >= 1 for r in part)} of {len(part)} built completely)')
    return 'Mean coverage: ' + ', '.join(parts) + '.'


INTRO = '''# Gallery: your own shapes, built

[README](../README.md) · [formats](formats.md) · [every row](gallery/gallery.rows.jsonl)

Shapes from mesh files (self-made, in [data/meshes](../data/meshes/meshes.json), drawn by
`scripts/make_meshes.py`), each made into a scene as a user would with
`rad scene from-mesh FILE --unit 0.05 --size N [--up y] [--clearance C]`
([formats.md](formats.md#your-own-target-rad-scene-from-mesh-from-voxels-supply)):
voxelized, placed in front of the robot, the fewest blocks of the default set that cover it
chosen and laid out on the table. Each was then planned by the agent as the node graph runs it
and its blocks put at their planned poses in the PyBullet twin, each left to settle; coverage
is what registration of the twin's world measures (a block that fell counts nothing).

Target: the scene (target cells pink, blocks on the table). Built: the structure at the end,
from two sides (unbuilt target cells as pink outlines, blocks on non-target cells tinted red);
`build.png` in each folder replays the build step by step (an animated PNG). Each folder also
holds the `scene.json`, so `rad demo --scene docs/gallery/NAME/scene.json` builds it with the
whole node graph.
'''


def write_gallery_page(rows: list[dict], agent: str, command: str, summary: str = '') -> None:
    """docs/gallery.md: the pictures and figures of every shape (the first clearance's), with the
    command, the commit and the date, and the mean coverage of every clearance."""
    lines = [INTRO, f'- command: `{command}`', f'- commit: {git_commit()}',
             f'- date: {time.strftime("%Y-%m-%d", time.gmtime())}', f'- agent: `{agent}`', '', summary, '',
             '| shape | target | built | coverage | steps | planning s |', '|---|---|---|---|---|---|']
    for r in rows:
        name = r['shape']
        lines.append(f'| **{name}**<br>{r["file"]}<br>{r["cells"]} cells, {r["blocks"]} blocks | '
                     f'![{name} target](gallery/{name}/target.png) | '
                     f'![{name} built](gallery/{name}/after.png)<br>[step by step](gallery/{name}/build.png) | '
                     f'{r["coverage"]:.2f} | {r["steps"]} | {r["planning_s"]:.1f} |')
    (ROOT / 'docs' / 'gallery.md').write_text('\n'.join(lines) + '\n')


def main() -> None:
    manifest = json.loads((MESHES / 'meshes.json').read_text())
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--shapes', nargs='*', default=list(manifest), choices=list(manifest))
    p.add_argument('--agent', default='default',
                   help='the agent (rad_core.sequencing.decide.agents), as the node graph runs it')
    p.add_argument('--unit', type=float, default=0.05)
    p.add_argument('--clearances', type=float, nargs='+', default=[0.0],
                   help="the scenes' gap between neighbouring blocks, a fraction of the unit (0.2: the paper's 1 cm); "
                        "the pictures are the first's")
    args = p.parse_args()
    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    planner = AgentPlanner(args.agent)
    rows = []
    try:
        for k, clearance in enumerate(args.clearances):
            cache = cache_dir('gallery') / f'{planner.agent}-u{args.unit:g}-c{clearance:g}.jsonl'
            done = {r['shape']: {'clearance': clearance, **r} for r in read_rows(cache)} if cache.exists() else {}
            for name in args.shapes:
                if name not in done:
                    done[name] = run_shape(name, manifest[name], args.unit, clearance, planner, pictures=k == 0)
                    with cache.open('a') as f:
                        f.write(json.dumps(done[name]) + '\n')
                    r = done[name]
                    print(f'{name} (clearance {clearance:g}): {r["cells"]} cells, {r["blocks"]} blocks, '
                          f'{r["steps"]} steps, coverage {r["coverage"]:.2f}, planning {r["planning_s"]:.1f} s '
                          f'({r["wall_s"]:.0f} s)', flush=True)
                rows.append(done[name])
    finally:
        planner.close()
    write_tables(rows, planner.agent, command_line())
    print(f'wrote {ROOT / "docs" / "gallery.md"} and {ROWS}')


if __name__ == '__main__':
    main()

"""The `rad` command line tool.

    rad scene generate --grid G --sides S --seed N -o scene.json
    rad scene check scene.json
    rad scene render scene.json -o scene.png [--allocation allocation.json]
    rad scene stats --grid G --sides S --scenes N
    rad allocate scene.json [--time-limit S] [--seed N] [--workers W] [--solver cp-sat|highs]
    rad demo [--scene FILE] --out DIR

Bad input ends with exit code 2 and one line on stderr naming the problem.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from rad_core import jsonfmt
from rad_core.errors import RadError
from rad_core.scene import Scene


def _read_scene(path: str) -> Scene:
    if path == '-':
        return Scene.loads(sys.stdin.read())
    return Scene.load(path)


def _write_text(text: str, path: str | None) -> None:
    if path in (None, '-'):
        sys.stdout.write(text + '\n')
        return
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(text + '\n')
    except OSError as e:
        raise RadError(f'cannot write {path!r}: {e.strerror}') from None


def _allocation_params(args):
    from rad_core.allocation import AllocationParams
    params = AllocationParams(time_limit_s=args.time_limit, seed=args.seed, num_workers=args.workers)
    params.validate()
    return params


def cmd_scene_generate(args) -> int:
    from rad_core.generator import GeneratorConfig, generate_scene
    config = GeneratorConfig(grid=args.grid, sides=args.sides, unit=args.unit)
    _write_text(generate_scene(config, args.seed).dumps(), args.output)
    return 0


def cmd_scene_check(args) -> int:
    scene = _read_scene(args.scene)
    counts = {k: v for k, v in scene.type_counts().items() if v}
    print(f'ok: {len(scene.blocks)} blocks {counts}, {len(scene.targets)} target regions, '
          f'{scene.num_target_cells} target cells, unit {scene.unit} m')
    return 0


def cmd_scene_stats(args) -> int:
    from rad_core.generator import GeneratorConfig, target_statistics
    stats = target_statistics(GeneratorConfig(grid=args.grid, sides=args.sides), args.scenes, args.seed)
    print(jsonfmt.dumps(stats))
    return 0


def cmd_scene_render(args) -> int:
    from rad_core.allocation import AllocationResult
    from rad_core.render import save_scene_png
    scene = _read_scene(args.scene)
    allocation = None
    if args.allocation:
        try:
            allocation = AllocationResult.from_dict(json.loads(Path(args.allocation).read_text()))
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise RadError(f'cannot read allocation {args.allocation!r}: {e}') from None
    save_scene_png(scene, args.output, allocation=allocation, width=args.width, height=args.height)
    print(f'wrote {args.output}')
    return 0


def cmd_allocate(args) -> int:
    from rad_core.allocation import solve
    from rad_core.allocation.highs import solve_highs
    scene = _read_scene(args.scene)
    params = _allocation_params(args)
    result = solve(scene, params) if args.solver == 'cp-sat' else solve_highs(scene, params.time_limit_s)
    _write_text(jsonfmt.dumps(result.to_dict()), args.output)
    return 0 if result.has_solution else 1


def cmd_demo(args) -> int:
    from rad_core.allocation import solve, validate_allocation
    from rad_core.generator import GeneratorConfig, generate_scene
    out = Path(args.out)
    t0 = time.perf_counter()
    scene = _read_scene(args.scene) if args.scene else generate_scene(GeneratorConfig(grid=4, sides=2), seed=0)
    result = solve(scene, _allocation_params(args))
    problems = validate_allocation(scene, result)
    _write_text(scene.dumps(), str(out / 'scene.json'))
    _write_text(jsonfmt.dumps(result.to_dict()), str(out / 'allocation.json'))
    try:
        from rad_core.render import save_scene_png
        save_scene_png(scene, out / 'scene.png', allocation=result)
        picture = f'{out / "scene.png"}'
    except ImportError:
        picture = 'no picture (renderer not available)'
    covered = sum(len(p.cells) for p in result.placements)
    print(f'scene: {len(scene.blocks)} blocks, {len(scene.targets)} regions, '
          f'{scene.num_target_cells} target cells')
    print(f'allocation: {result.status}, objective {result.objective:g} (bound {result.bound:g}), '
          f'{len(result.placements)} blocks filling {covered} cells, solved in {result.solve_time_s * 1e3:.1f} ms')
    print(f'validator: {"ok" if not problems else "; ".join(problems)}')
    print(f'wrote {out / "scene.json"}, {out / "allocation.json"}, {picture} '
          f'({time.perf_counter() - t0:.2f} s)')
    return 0 if result.has_solution and not problems else 1


def _add_solver_args(p: argparse.ArgumentParser) -> None:
    p.add_argument('--time-limit', type=float, default=10.0, metavar='S', help='solver time limit, seconds')
    p.add_argument('--seed', type=int, default=0, help='solver random seed')
    p.add_argument('--workers', type=int, default=1, help='CP-SAT workers (1 = deterministic)')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='rad', description='rad: robot assembly discovery tools')
    parser.add_argument('--debug', action='store_true', help='show tracebacks of internal errors')
    sub = parser.add_subparsers(dest='command', required=True)

    scene = sub.add_parser('scene', help='generate, check, render scenes').add_subparsers(dest='action', required=True)
    p = scene.add_parser('generate', help='generate a random scene like the paper\'s')
    p.add_argument('--grid', type=int, default=3, help='g: largest target width and height, cells')
    p.add_argument('--sides', type=int, default=2, help='1 or 2 target faces')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--unit', type=float, default=0.05, help='cube edge, metres')
    p.add_argument('-o', '--output', help='output file (default: stdout)')
    p.set_defaults(func=cmd_scene_generate)
    p = scene.add_parser('check', help='validate a scene file')
    p.add_argument('scene', help="scene file, or - for stdin")
    p.set_defaults(func=cmd_scene_check)
    p = scene.add_parser('render', help='draw a scene (and an allocation) to a PNG')
    p.add_argument('scene')
    p.add_argument('-o', '--output', required=True)
    p.add_argument('--allocation', help='rad-allocation/1 file to draw as ghost blocks')
    p.add_argument('--width', type=int, default=640)
    p.add_argument('--height', type=int, default=480)
    p.set_defaults(func=cmd_scene_render)
    p = scene.add_parser('stats', help='target-size statistics of generated scenes')
    p.add_argument('--grid', type=int, default=3)
    p.add_argument('--sides', type=int, default=2)
    p.add_argument('--scenes', type=int, default=1000)
    p.add_argument('--seed', type=int, default=0)
    p.set_defaults(func=cmd_scene_stats)

    p = sub.add_parser('allocate', help='solve the allocation MILP for a scene, print rad-allocation/1 JSON')
    p.add_argument('scene', help='scene file, or - for stdin')
    p.add_argument('--solver', choices=['cp-sat', 'highs'], default='cp-sat')
    p.add_argument('-o', '--output', help='output file (default: stdout)')
    _add_solver_args(p)
    p.set_defaults(func=cmd_allocate)

    p = sub.add_parser('demo', help='run the main job on a default (or given) scene')
    p.add_argument('--scene', help='scene file (default: a generated g=4 two-sided scene)')
    p.add_argument('--out', default='out/demo', help='output folder')
    _add_solver_args(p)
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except RadError as e:
        print(f'rad: error: {e}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as e:  # noqa: BLE001 - the CLI must end with one clear line
        if args.debug:
            raise
        print(f'rad: internal error: {type(e).__name__}: {e} (run with --debug for details)', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())

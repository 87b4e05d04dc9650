"""The `rad` command line tool.

    rad scene generate --grid G --sides S --seed N [--clearance C] -o scene.json
    rad scene check scene.json
    rad scene render scene.json -o scene.png [--allocation allocation.json] [--robot]
    rad scene stats --grid G --sides S --scenes N
    rad scene from-mesh MODEL [NAME=MODEL ...] --unit U [--size N | --scale S] [--up z] [--yaw 0|90|180|270]
        [--hollow] -o scene.json
    rad scene from-voxels FILE.npy|FILE.binvox [...] --unit U [--up z] [--yaw 0|90|180|270] [--hollow] -o scene.json
    rad scene supply scene.json [--types I2,L3,... | --inventory FILE] [--objective fewest|cheapest] -o scene.json
    rad allocate scene.json [--time-limit S] [--seed N] [--workers W] [--solver cp-sat|highs]
    rad demo [--scene FILE] [--out DIR] [--rtf X] [--faults none|realistic|FILE] [--cycles N]
             [--effector hand|suction]
    rad limits RESULT.json [--robot panda|fr3] [--joint-prefix P]
    rad calibrate PAIRS.csv [--out FILE] [--max-rms M] [--mocap-frame NAME]
    rad calibrate --hand-eye POSES.csv [--out FILE] [--max-rms M] [--mocap-frame NAME]
    rad eval --agent AGENT [--checkpoint FILE] --grid G [--robot] --scenes N --seed S --json FILE
             [--workers N [--dashboard] | --scheduler ADDR [--workers N]]
    rad ceiling SCENE.json [...] [--time-limit S] [--agent AGENT] [--support arm,hand] [--allocations-only]
                [--effector hand|suction] [--json FILE]
    rad dataset build --grids 3 --scenes 50000 -o data/train-g3.jsonl.gz [--shapes train]
    rad train --method milp-dqn|dqn|dqn-rel --out runs/NAME [--resume] [--<config field> VALUE ...]
              [--actors N [--chunk-steps S] [--refresh-every K] | --seeds S1,S2,...] [--scheduler ADDR]
    rad expert --out runs/NAME [--resume] [--<expert config field> VALUE ...]

Bad input ends with exit code 2 and one line on stderr naming the problem.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from rad_core.domain import jsonfmt
from rad_core.domain.errors import RadError
from rad_core.view.progress import ProgressBar

if TYPE_CHECKING:
    from rad_core.domain.scene import Scene


def _read_scene(path: str) -> Scene:
    from rad_core.domain.scene import Scene  # numpy: not needed to parse arguments or print help
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
    from rad_core.allocation import AllocationParams  # ortools: this command only
    params = AllocationParams(time_limit_s=args.time_limit, seed=args.seed, num_workers=args.workers)
    params.validate()
    return params


def cmd_scene_generate(args) -> int:
    from rad_core.domain.generator import GeneratorConfig, generate_scene  # numpy: this command only
    config = GeneratorConfig(grid=args.grid, sides=args.sides, unit=args.unit, clearance=args.clearance,
                             supply=args.supply, feeder_order=args.feeder_order, feeder_window=args.feeder_window)
    _write_text(generate_scene(config, args.seed).dumps(), args.output)
    return 0


BRICK_SUFFIXES = ('.txt', '.ldr', '.mpd')


def cmd_scene_check(args) -> int:
    if Path(args.scene).suffix.lower() in BRICK_SUFFIXES:
        return _check_design(args)
    scene = _read_scene(args.scene)
    counts = {k: v for k, v in scene.type_counts().items() if v}
    feeder = (f' ({len(scene.feeder.blocks)} in a {scene.feeder.order} feeder at {list(scene.feeder.station)})'
              if scene.feeder is not None else '')
    studs = (f', {scene.studs.system} studs ({scene.course * 1000:.2f} mm courses, clutch {scene.studs.clutch:g} N)'
             if scene.studs is not None else '')
    print(f'ok: {len(scene.blocks)} blocks {counts}{feeder}, {len(scene.targets)} target regions, '
          f'{scene.num_target_cells} target cells, unit {scene.unit} m{studs}')
    if scene.studs is None:
        return 0
    from rad_core.domain.grid import Grid, blocks_on_grid  # numpy: this command only
    from rad_core.domain.statics import first_failure  # ortools: this command only
    grid = Grid(scene)
    built = blocks_on_grid(scene, grid)
    failure = first_failure(grid, list(built.values()), clutch=grid.clutch) if built else None
    if failure is None:
        print(f'stands: the {len(built)} blocks built in the target' if built else 'nothing built in the target yet')
        return 0
    ids = [scene.blocks[b].id for b in built]
    step, verdict = failure
    whys = verdict.why or ('',) * len(verdict.falling)
    print(f'falls once block {ids[step]!r} is on: '
          + '; '.join(f'{ids[n]} {why}'.strip() for n, why in zip(verdict.falling, whys)))
    return 1


def _check_design(args) -> int:
    """`rad scene check` of a brick design: whether it stands with its clutch, and without."""
    from rad_core.domain.brick_designs import read_design  # numpy: this command only
    from rad_core.allocation.brick_scenes import design_verdict, lattice_of  # ortools: this command only
    design = read_design(args.scene)
    lattice = lattice_of(design, args.system, args.unit, args.clutch, args.baseplate)
    verdict, words = design_verdict(design, lattice)
    print(f'{args.scene}: {len(design.bricks)} {lattice.system} bricks: {words}')
    if verdict == 'stands':
        alone, why = design_verdict(design, lattice, clutch=False)
        print(f'without clutch it {why}' if alone == 'falls' else 'without clutch it stands too')
    return 0 if verdict == 'stands' else 1


def cmd_scene_from_bricks(args) -> int:
    from rad_core.domain.brick_designs import read_design  # numpy: this command only
    from rad_core.allocation.brick_scenes import scene_from_design  # ortools: this command only
    scene, lines = scene_from_design(read_design(args.design), args.system, args.unit, args.clutch, args.yaw,
                                     args.seed, args.supply, args.baseplate)
    _write_text(scene.dumps(), args.output)
    for line in lines:
        _say(args, line)
    return 0


def cmd_scene_stats(args) -> int:
    from rad_core.domain.generator import GeneratorConfig, target_statistics  # numpy: this command only
    stats = target_statistics(GeneratorConfig(grid=args.grid, sides=args.sides), args.scenes, args.seed)
    print(jsonfmt.dumps(stats))
    return 0


def cmd_scene_render(args) -> int:
    from rad_core.allocation import AllocationResult  # ortools: this command only
    from rad_core.view.render import save_scene_png  # numpy: this command only
    scene = _read_scene(args.scene)
    allocation = None
    if args.allocation:
        try:
            allocation = AllocationResult.from_dict(json.loads(Path(args.allocation).read_text()))
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise RadError(f'cannot read allocation {args.allocation!r}: {e}') from None
    robot = None
    if args.robot:
        from rad_core.cell.panda import HOME  # numpy: this command only
        robot = HOME
    save_scene_png(scene, args.output, allocation=allocation, width=args.width, height=args.height, robot=robot)
    print(f'wrote {args.output}')
    return 0


def _supply_types(args, scene=None) -> tuple[dict, dict | None, dict]:
    """The block types, the inventory (None: any number) and the costs the supply flags name."""
    from rad_core.allocation.supply import library, parse_costs, pick_types, read_inventory  # ortools
    from rad_core.domain.blocks import DEFAULT_LIBRARY  # numpy: this command only
    known = library(scene)
    if args.types and args.inventory:
        raise RadError('give --types or --inventory, not both (an inventory names its types)')
    costs = parse_costs(args.cost) if args.cost else {}
    inventory = None
    if args.inventory:
        inventory, file_costs = read_inventory(args.inventory, known)
        types = {n: known[n] for n in inventory}
        costs = {**file_costs, **costs}
    elif args.types:
        types = pick_types(args.types, known)
    else:
        types = dict(scene.block_types) if scene is not None else dict(DEFAULT_LIBRARY)
    return types, inventory, costs


def _supply_and_write(args, targets, unit: float, clearance: float = 0.0, scene=None) -> int:
    """Choose and lay out the blocks (or none, with --no-supply), write the scene, say how well it covers."""
    from rad_core.allocation.supply import SupplyParams, supply, target_only  # ortools: this command only
    types, inventory, costs = _supply_types(args, scene)
    clearance = clearance if args.clearance is None else args.clearance
    if getattr(args, 'no_supply', False):
        _write_text(target_only(targets, unit, types, clearance).dumps(), args.output)
        cells = sum(len(t.filled) for t in targets)
        _say(args, f'target only: {len(targets)} regions, {cells} target cells, no blocks '
                   f'(rad scene supply lays them out)')
        return 0
    params = SupplyParams(objective=args.objective, costs=costs, time_limit_s=args.time_limit, seed=args.seed,
                          hand=not args.any_order, start=args.supply)
    result, report = supply(targets, unit, types, inventory, params, clearance)
    _write_text(result.dumps(), args.output)
    if result.feeder is not None:
        _say(args, f'the {len(result.blocks)} blocks wait in a feeder presenting them at {result.feeder.station} '
                   + ('(they do not fit on the table within the arm\'s reach)' if args.supply == 'auto' else ''))
    if args.report:
        _write_text(jsonfmt.dumps(report.to_dict()), args.report)
    _say(args, report.summary())
    if not report.exact:
        _say(args, f'rad: warning: the blocks cannot cover the target exactly with these types: '
                   f'{report.covered} of {report.target_cells} target cells can be covered'
                   + (f', {report.filler_cells} cells off the target hold blocks up' if report.filler_cells else ''))
    return 0


def _say(args, line: str) -> None:
    """A line for the user: stdout when the scene went to a file, stderr when it went to stdout."""
    print(line, file=sys.stderr if args.output in (None, '-') else sys.stdout)


def cmd_scene_from_mesh(args) -> int:
    from rad_core.domain.voxels import fit_report, mesh_models, place_regions, region_names  # numpy: this command only
    models = mesh_models(region_names(args.models), args.unit, size=args.size, scale=args.scale, up=args.up,
                         hollow=args.hollow, yaw=args.yaw)
    for model in models:
        _say(args, f'{model.path}: {model.report.summary()}')
    regions = place_regions(models, args.unit)
    _say(args, fit_report(models, args.unit, given_yaw=args.yaw is not None))
    return _supply_and_write(args, regions, args.unit)


def cmd_scene_from_voxels(args) -> int:
    from rad_core.domain.voxels import fit_report, place_regions, region_names, voxel_models  # numpy: this command only
    models = voxel_models(region_names(args.files), args.unit, up=args.up, hollow=args.hollow, yaw=args.yaw)
    regions = place_regions(models, args.unit)
    _say(args, fit_report(models, args.unit, given_yaw=args.yaw is not None))
    return _supply_and_write(args, regions, args.unit)


def cmd_scene_supply(args) -> int:
    from rad_core.domain.grid import Grid, blocks_on_grid  # numpy: this command only
    scene = _read_scene(args.scene)
    placed = blocks_on_grid(scene, Grid(scene))
    if placed:
        raise RadError(f'{args.scene}: {len(placed)} blocks already sit in the target; supply lays out the blocks '
                       f'for an empty target (remove them from "blocks")')
    return _supply_and_write(args, scene.targets, scene.unit, scene.clearance, scene)


def cmd_allocate(args) -> int:
    from rad_core.allocation import solve  # ortools: this command only
    from rad_core.allocation.highs import solve_highs  # ortools: this command only
    scene = _read_scene(args.scene)
    params = _allocation_params(args)
    result = solve(scene, params) if args.solver == 'cp-sat' else solve_highs(scene, params.time_limit_s)
    _write_text(jsonfmt.dumps(result.to_dict()), args.output)
    return 0 if result.has_solution else 1


def cmd_demo(args) -> int:
    """Hand over to rad_planner's demo, which brings up the whole node graph.

    rad_core stays free of ROS: the demo is a separate installed executable.
    """
    exe = next((Path(prefix) / 'lib' / 'rad_planner' / 'demo'
                for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
                if prefix and (Path(prefix) / 'lib' / 'rad_planner' / 'demo').is_file()), None)
    if exe is None:
        raise RadError('rad_planner is not installed or not sourced: run scripts/setup.sh and '
                       'source scripts/env.sh (rad allocate works without ROS)')
    argv = [str(exe), '--out', args.out, '--rtf', str(args.rtf), '--time-limit', str(args.time_limit)]
    if args.scene:
        argv += ['--scene', args.scene]
    if args.faults != 'none':
        argv += ['--faults', args.faults, '--faults-seed', str(args.faults_seed)]
    if args.cycles != 1:
        argv += ['--cycles', str(args.cycles)]
    if args.effector != 'hand':
        argv += ['--effector', args.effector]
    os.execv(str(exe), argv)
    return 1

def cmd_limits(args) -> int:
    """Would a real Franka take these arm trajectories? Every trajectory of a rad-result document
    (result.json of `rad demo` or /execute_assembly) or a plan (steps with trajectories), in order,
    each from where the previous one ended (HOME first), through `trajectory.limit_violation`."""
    import numpy as np  # numpy: this command only

    from rad_core.cell.panda import HOME  # numpy: this command only
    from rad_core.cell.robot_model import robot_model  # numpy: this command only
    from rad_core.cell.trajectory import limit_ratios, limit_violation  # numpy: this command only
    model = robot_model(args.robot, args.joint_prefix)
    try:
        doc = json.loads(Path(args.result).read_text() if args.result != '-' else sys.stdin.read())
    except (OSError, ValueError) as e:
        raise RadError(f'cannot read {args.result!r}: {e}') from None
    steps = doc.get('steps') if isinstance(doc, dict) else None
    if not isinstance(steps, list):
        raise RadError(f'{args.result}: not a rad-result or plan document (no "steps" list)')
    q = np.asarray(HOME[:7])
    worst = {'velocity': 0.0, 'acceleration': 0.0, 'jerk': 0.0}
    problems, count = [], 0
    for i, step in enumerate(steps):
        for k, traj in enumerate(step.get('trajectories') or []):
            count += 1
            try:
                why = limit_violation(traj, q, model)
            except RadError as e:      # refused before any motion: names, points, positions
                why = str(e)
            if why:
                problems.append(f'step {i} ({step.get("block", "?")}) trajectory {k}: {why}')
            else:
                for key, value in limit_ratios(traj, q, model).items():
                    worst[key] = max(worst[key], value)
            q = np.asarray(traj['points'][-1]['positions'], dtype=float)[:7]
    print(json.dumps({'robot': model.name, 'trajectories': count, 'refused': len(problems),
                      'worst_ratio': {k: round(v, 3) for k, v in worst.items()}, 'problems': problems}))
    if count == 0:
        raise RadError(f'{args.result}: no arm trajectories to check')
    return 0 if not problems else 1


def cmd_calibrate(args) -> int:
    """Fit the motion-capture frame to the robot's base from point pairs (rad_core.cell.calibration), or with
    --hand-eye a fixed camera from flange and tag poses (rad_core.cell.hand_eye); print the transform and its
    residuals as one JSON object; --out writes the assembly node's parameters."""
    from rad_core.cell.calibration import fit, parse_pairs_csv, read_pairs_csv  # numpy: this command only
    if not args.mocap_frame:
        raise RadError("--mocap-frame must name the motion-capture frame ('' means no calibration)")
    if args.out == '-':
        raise RadError('--out needs a file: stdout carries the JSON')
    if (args.pairs is None) == (args.hand_eye is None):
        raise RadError('give either PAIRS.csv (motion capture) or --hand-eye POSES.csv (a fixed camera), not '
                       + ('both' if args.pairs is not None else 'neither'))
    if args.hand_eye is not None:
        return _calibrate_hand_eye(args)
    pairs = parse_pairs_csv(sys.stdin.read(), 'stdin') if args.pairs == '-' else read_pairs_csv(args.pairs)
    calibration = fit(pairs, args.max_rms)
    return _print_calibration(args, calibration, f'rad calibrate {args.pairs}: {len(pairs.base)} points, rms '
                              f'residual {calibration.rms_m * 1e3:.3f} mm, max '
                              f'{max(calibration.residuals_m) * 1e3:.3f} mm')


def _print_calibration(args, calibration, header: str) -> int:
    """Print the fit as one JSON object; --out writes the assembly node's parameters (`header` their
    first comment)."""
    doc = {**calibration.to_dict(), 'max_rms_m': args.max_rms if args.max_rms != float('inf') else None,
           'mocap_frame': args.mocap_frame}
    if args.out:
        _write_text(calibration.params_yaml(args.mocap_frame, header).rstrip('\n'), args.out)
        doc['out'] = args.out
    print(json.dumps(doc))
    return 0


def _calibrate_hand_eye(args) -> int:
    """`rad calibrate --hand-eye`: the camera in the base frame, the tag on the flange, the residuals;
    --out writes the camera as the frame the assembly node's poses arrive in (--mocap-frame names it)."""
    from rad_core.cell.hand_eye import fit, parse_poses_csv, read_poses_csv  # scipy: this command only
    poses = parse_poses_csv(sys.stdin.read(), 'stdin') if args.hand_eye == '-' else read_poses_csv(args.hand_eye)
    hand_eye = fit(poses, args.max_rms)
    return _print_calibration(args, hand_eye, f'rad calibrate --hand-eye {args.hand_eye}: {len(poses)} poses, rms '
                              f'residual {hand_eye.rms_position_m * 1e3:.3f} mm, {hand_eye.rms_rotation_deg:.3f} deg')


def cmd_eval(args) -> int:
    from rad_core.domain.scene_sources import generated_scenes, scene_dir  # numpy: this command only
    from rad_core.experiment.evaluation import evaluate, get_agent, uses_robot  # ortools: this command only
    distributed = args.workers is not None or args.scheduler is not None
    if args.workers is not None and args.workers < 1:
        raise RadError(f'--workers must be at least 1, got {args.workers}')
    if args.dashboard and (args.workers is None or args.scheduler is not None):
        raise RadError('--dashboard applies to the cluster --workers N starts, not to the serial run or --scheduler')
    if args.effector != 'hand' and distributed:
        raise RadError('--effector suction runs serially for now: leave out --workers and --scheduler')
    agent = get_agent(args.agent, args.checkpoint, verify=args.verify, budget=args.budget,
                      reallocate=args.reallocate)
    policy = agent.make_policy()   # a bad checkpoint fails here, before any scene runs
    robot = uses_robot(agent, args.robot)
    if args.scene_dir:
        scenes = scene_dir(args.scene_dir)
        total, source = len(scenes), args.scene_dir
    else:
        if args.scenes < 1:
            raise RadError(f'--scenes must be at least 1, got {args.scenes}')
        scenes = generated_scenes(args.grid, args.sides, args.scenes, args.seed)
        last = args.seed + args.scenes - 1
        total, source = args.scenes, f'g={args.grid} sides={args.sides} seeds {args.seed}..{last}'
    t0 = time.perf_counter()
    from rad_core.allocation import AllocationParams  # ortools: this command only
    allocation = AllocationParams(support=args.support) if args.support else None
    bar = ProgressBar(total, args.agent)
    if distributed:
        from rad_core.experiment.distributed import AgentArgs, evaluate_distributed  # ortools: this command only
        agent_args = AgentArgs(args.agent, args.checkpoint, args.verify, args.budget, args.reallocate)
        result = evaluate_distributed(agent_args, scenes, robot, args.seed, progress=bar, workers=args.workers,
                                      scheduler=args.scheduler, execution=args.execution, allocation=allocation,
                                      dashboard=args.dashboard, policy=policy)
    else:
        result = evaluate(agent, scenes, robot, args.seed, progress=bar, execution=args.execution, policy=policy,
                          allocation=allocation, effector=args.effector)
    elapsed = time.perf_counter() - t0
    mode = f'robot ({args.execution})' if robot else 'no robot'
    if distributed:
        mode += f', Dask scheduler {args.scheduler}' if args.scheduler else f', {args.workers} Dask workers'
    print(f'{agent.name} on {result["n"]} scenes ({source}), {mode}, {elapsed:.1f} s')
    print(f'{"R":>13} {"d":>5} {"e":>5} {"f":>5} {"f_g":>5} {"f_p":>5} {"cov":>5} {"cov_rel":>7}')
    print(f'{result["R"]:6.2f} ({result["R_std"]:.2f}) {result["d"]:5.2f} {result["e"]:5.2f} {result["f"]:5.2f} '
          f'{result["f_g"]:5.2f} {result["f_p"]:5.2f} {result["coverage"]:5.2f} {result["coverage_rel"]:7.2f}')
    if args.json:
        _write_text(jsonfmt.dumps(result), args.json)
        print(f'wrote {args.json}')
    return 0


def cmd_ceiling(args) -> int:
    from rad_core.sequencing.bounds.robot_ceiling import robot_ceiling  # ortools: this command only
    from rad_core.sequencing.decide.agents import SUPPORTS  # numpy: this command only
    if not args.time_limit > 0:
        raise RadError(f'--time-limit must be a positive number of seconds, got {args.time_limit}')
    supports = tuple(s for s in args.support.split(',') if s)
    for rule in supports:
        if rule not in SUPPORTS:
            raise RadError(f'--support: unknown rule {rule!r} ({", ".join(SUPPORTS)})')
    scenes = [(Path(f).stem if f != '-' else 'stdin', _read_scene(f)) for f in args.scenes]
    agent = None
    if args.agent:
        from rad_core.experiment.evaluation import evaluate, get_agent  # ortools: this command only
        agent = get_agent(args.agent)
    rows = []
    for k, (name, scene) in enumerate(scenes):
        row = {'name': name}
        known = 0.0
        if agent is not None:
            built = evaluate(agent, [(name, scene)], robot=True, seed=args.seed + k,
                             effector=args.effector)['scenes'][0]
            row['agent'], row['agent_coverage'] = agent.name, built['coverage']
            known = float(built['coverage'])
        found = robot_ceiling(scene, args.time_limit, support=supports, incumbent=known,
                              every_pose=not args.allocations_only, effector=args.effector)
        row.update(ceiling=found.coverage, proof=found.proof, complete=found.complete, bound=found.bound,
                   states=found.states, seconds=round(found.elapsed_s, 3), reason=found.reason,
                   line=[{'block': scene.blocks[a.block].id, 'unit': a.unit, 'cell': a.cell, 'rotation': a.rotation}
                         for a in found.actions])   # MDP actions (mdp.Action), the block by its id
        rows.append(row)
        ended = {'bound': 'the ceiling over every allocation (it reached the bound)',
                 'all poses': 'the ceiling over every allocation (every sequence of poses searched)',
                 'exhausted': (f'the best found; the allocations searched do no better, any allocation '
                               f'covers at most {found.bound:.3f}'),
                 '': f'a lower bound ({found.reason}); any build covers at most {found.bound:.3f}'}[found.proof]
        line = f'{name}: ceiling {found.coverage:.3f}, {ended}; {found.states} states, {found.elapsed_s:.1f} s'
        if agent is not None:
            line += f'; {args.agent} builds {row["agent_coverage"]:.3f}'
        print(line, flush=True)
    if args.json:
        _write_text(jsonfmt.dumps({'time_limit_s': args.time_limit, 'support': list(supports),
                                   'agent': agent.name if agent else None, 'scenes': rows}), args.json)
        print(f'wrote {args.json}')
    return 0


def cmd_dataset_build(args) -> int:
    from rad_core.training.dataset import build  # ortools: this command only
    shapes = []
    if args.shapes:
        from rad_core.domain import shapes as shape_lib  # numpy: this command only
        names = shape_lib.SPLITS.get(args.shapes, None)
        if names is None:
            raise RadError(f'--shapes must be one of {", ".join(shape_lib.SPLITS)}, got {args.shapes!r}')
        shapes = [(n, shape_lib.shape_scene(n, seed)) for n in names for seed in range(args.shape_seeds)]
    try:
        grids = [int(g) for g in args.grids.split(',') if g.strip()]
    except ValueError:
        raise RadError(f'--grids must be comma-separated integers, e.g. 3,4,5; got {args.grids!r}') from None
    if not grids:
        raise RadError('--grids names no grid size')
    bar = ProgressBar(len(grids) * args.scenes + len(shapes), 'dataset')
    from rad_core.allocation import AllocationParams  # ortools: this command only
    params = AllocationParams(support=args.support)
    params.validate()
    header = build(args.output, grids, args.scenes, sides=args.sides, first_seed=args.seed, shapes=shapes,
                   params=params, progress=bar)
    size = Path(args.output).stat().st_size / 1e6
    print(f'wrote {args.output}: {header["count"]} scenes in {header["created_s"]} s, {size:.1f} MB')
    return 0


def cmd_train(args) -> int:
    from dataclasses import fields

    from rad_core.training.dqn import TrainConfig, train  # torch: this command only
    given = {f.name: getattr(args, f.name) for f in fields(TrainConfig) if getattr(args, f.name) is not None}
    if args.resume:
        extra = sorted(set(given) - {'total_steps'})
        if extra:
            raise RadError(f'--resume continues with the checkpoint\'s configuration; only --total-steps may '
                           f'change, not --{extra[0].replace("_", "-")}')
        config = TrainConfig()
    else:
        config = TrainConfig(**given)
        config.validate()
    seeds = _train_mode(args, given)
    total = given.get('total_steps', config.total_steps)
    if seeds is not None:
        from rad_core.training.actors import seed_folder, train_seeds  # torch: this command only

        def finished(seed: int, result: dict) -> None:
            print(f'seed {seed}: {result["env_steps"]} environment steps, {result["grad_steps"]} gradient steps, '
                  f'{result["wall_s"]:.0f} s; model: {seed_folder(args.out, seed) / "model.pt"}', flush=True)

        train_seeds(config, args.out, seeds, resume=args.resume, total_steps=given.get('total_steps'),
                    scheduler=args.scheduler, progress=finished)
        print(f'done: {len(seeds)} seeds in {args.out}/seed-*')
        return 0
    bar = ProgressBar(total, f'train {given.get("method", config.method)}')

    def progress(steps: int) -> None:   # the bar counts environment steps
        bar.done = min(steps, bar.total) - 1
        bar()

    if args.actors is not None:
        from rad_core.training.actors import ActorConfig, train_with_actors  # torch: this command only
        actor = ActorConfig(args.actors, args.chunk_steps or ActorConfig.chunk_steps,
                            args.refresh_every or ActorConfig.refresh_every)
        result = train_with_actors(config, args.out, actor, resume=args.resume,
                                   total_steps=given.get('total_steps'), progress=progress, scheduler=args.scheduler)
    else:
        result = train(config, args.out, resume=args.resume, total_steps=given.get('total_steps'), progress=progress)
    state = 'interrupted, checkpointed' if result['interrupted'] else 'done'
    print(f'{state}: {result["env_steps"]} environment steps, {result["grad_steps"]} gradient steps, '
          f'{result["episodes"]} episodes, {result["wall_s"]:.0f} s; model: {Path(args.out) / "model.pt"}')
    return 130 if result['interrupted'] else 0


def cmd_expert(args) -> int:
    from dataclasses import fields

    from rad_core.training.expert import ExpertConfig, ExpertIteration  # torch: this command only
    given = {f.name: getattr(args, f.name) for f in fields(ExpertConfig) if getattr(args, f.name) is not None}
    out = Path(args.out)
    if args.resume and (out / 'config.json').exists():
        # The run's own configuration with the flags given on top: the run refuses any but --rounds.
        config = ExpertConfig.from_dict({**json.loads((out / 'config.json').read_text()), **given})
    else:
        config = ExpertConfig(**given)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / 'expert.log', 'a') as logf:
        def log(line: str) -> None:
            stamped = f'{time.strftime("%H:%M:%S")} {line}'
            print(stamped, flush=True)
            logf.write(stamped + '\n')
            logf.flush()
        rows = ExpertIteration(config, out).run(resume=args.resume, log=log)
    print(f'done: {len(rows)} rounds; model: {out / "model.pt"}')
    return 0


def _train_mode(args, given: dict) -> list[int] | None:
    """Check the --actors/--seeds/--scheduler combination; the seeds of --seeds, else None."""
    if args.actors is not None and args.actors < 1:
        raise RadError(f'--actors must be at least 1, got {args.actors}')
    if args.actors is not None and args.seeds is not None:
        raise RadError('--actors and --seeds do not combine: --seeds trains each seed serially, in parallel')
    for flag, value in (('--chunk-steps', args.chunk_steps), ('--refresh-every', args.refresh_every)):
        if value is not None and args.actors is None:
            raise RadError(f'{flag} applies to --actors N only')
        if value is not None and value < 1:
            raise RadError(f'{flag} must be at least 1, got {value}')
    if args.scheduler is not None and args.actors is None and args.seeds is None:
        raise RadError('--scheduler applies to --actors N or --seeds, not to the serial run')
    if args.seeds is None:
        return None
    if 'seed' in given:
        raise RadError('--seed and --seeds do not combine: give the seeds as --seeds S1,S2,...')
    try:
        seeds = [int(s) for s in args.seeds.split(',') if s.strip()]
    except ValueError:
        raise RadError(f'--seeds takes whole numbers separated by commas, e.g. 1,2,3; got {args.seeds!r}') from None
    if not seeds:
        raise RadError('--seeds needs at least one seed, e.g. --seeds 1,2,3')
    return seeds


def _add_train_args(p: argparse.ArgumentParser, config=None) -> None:
    """Every field of a training config (default: TrainConfig) as --field-name (default: the dataclass's)."""
    from dataclasses import MISSING, fields
    if config is None:
        from rad_core.training.dqn import TrainConfig as config  # torch: this command only
    for f in fields(config):
        flag = '--' + f.name.replace('_', '-')
        default = f.default if f.default is not MISSING else None
        helptext = f'{f.metadata.get("help", "")} (default: {default})'
        if f.type in (bool, 'bool'):
            # `--robot` alone means true; `--double false` still reads a value.
            p.add_argument(flag, dest=f.name, type=lambda v: v.lower() in ('1', 'true', 'yes', 'on'),
                           nargs='?', const=True, metavar='BOOL', help=helptext)
        else:
            kind = {'int': int, 'float': float, 'str': str}.get(f.type if isinstance(f.type, str) else
                                                                f.type.__name__, str)
            p.add_argument(flag, dest=f.name, type=kind, help=helptext)


def _add_solver_args(p: argparse.ArgumentParser) -> None:
    p.add_argument('--time-limit', type=float, default=10.0, metavar='S', help='solver time limit, seconds')
    p.add_argument('--seed', type=int, default=0, help='solver random seed')
    p.add_argument('--workers', type=int, default=1, help='CP-SAT workers (1 = deterministic)')


def _add_brick_args(p) -> None:
    p.add_argument('--system', choices=('lego', 'duplo'),
                   help="the bricks' system where the file cannot say (the text format)")
    p.add_argument('--unit', type=float, help='the stud pitch in the scene, m (default: the system\'s own, 8 or 16 mm; '
                                              'courses keep the system\'s proportion)')
    p.add_argument('--clutch', type=float, help='the pull one stud connection holds, N (default: the system\'s)')
    p.add_argument('--baseplate', action='store_true',
                   help="the table is a baseplate of the system's studs: the first course is pressed onto it "
                        "and held (default: the bricks sit loose on the table)")


def _add_target_args(p: argparse.ArgumentParser) -> None:
    p.add_argument('--unit', type=float, default=0.05, help='cell edge (the cube edge), metres (default: 0.05)')
    p.add_argument('--up', choices=['x', 'y', 'z'], default='z', help="the model's axis that points up (default: z)")
    p.add_argument('--hollow', action='store_true', help='only the surface shell, not the solid inside')
    p.add_argument('--yaw', type=int, choices=(0, 90, 180, 270), metavar='0|90|180|270',
                   help='turn the model this many degrees about z, counter-clockwise seen from above (default: '
                        'as in the file, a quarter turn where only that fits the reach; the line printed says)')


def _add_supply_args(p: argparse.ArgumentParser, no_supply: bool = True) -> None:
    p.add_argument('--types', metavar='T1,T2,...', help='block types to lay out (default: the scene\'s, or the '
                                                          'default set cube,I2,I3,I2_up,L3,L3_up,T4,T4_up,O4_up,S4_up)')
    p.add_argument('--inventory', metavar='FILE',
                   help='JSON: type -> count or {"count": N, "cost": C}: only these blocks')
    p.add_argument('--objective', choices=['fewest', 'cheapest'], default='fewest',
                   help='among the best covers, the fewest blocks or the lowest cost (default: fewest)')
    p.add_argument('--cost', metavar='T=C,...', help='per-type costs for --objective cheapest (others cost 1)')
    p.add_argument('--seed', type=int, default=0, help='solver and layout seed')
    p.add_argument('--time-limit', type=float, default=10.0, metavar='S', help='solver time limit, seconds')
    p.add_argument('--any-order', action='store_true',
                   help='take the best cover even where a top-down hand cannot place all of it in any order '
                        '(default: rule out the pieces it cannot and solve again, rad_core.allocation.supply)')
    p.add_argument('--supply', choices=('auto', 'table', 'feeder'), default='auto',
                   help='where the blocks start: on the table, in a feeder presenting them at a station right of '
                        'the target, or auto (the table where they fit within reach, else the feeder)')
    p.add_argument('--report', metavar='FILE', help='write how well the blocks cover (JSON) here')
    p.add_argument('--clearance', type=float, metavar='C',
                   help="gap between neighbouring blocks, a fraction of the unit (0.2: the paper's 1 cm at 5 cm; "
                        "default: the scene's, 0 for a new one)")
    if no_supply:
        p.add_argument('--no-supply', action='store_true',
                       help='write the target and the block types only, no blocks (for rad scene supply)')
    p.add_argument('-o', '--output', help='output scene file (default: stdout)')


def build_parser(command: str | None = 'train') -> argparse.ArgumentParser:
    """The whole parser, built without importing torch, OR-Tools, PyBullet or Dask: each command imports
    what it uses when it runs. Only `rad train`'s --<config field> flags need a heavy import (TrainConfig
    lives with the trainer, which imports torch), so they are added only when `command` is 'train'."""
    parser = argparse.ArgumentParser(prog='rad', description='rad: robot assembly discovery tools')
    parser.add_argument('--debug', action='store_true', help='show tracebacks of internal errors')
    sub = parser.add_subparsers(dest='command', required=True)

    scene = sub.add_parser('scene', help='generate, check, render scenes').add_subparsers(dest='action', required=True)
    p = scene.add_parser('generate', help='generate a random scene like the paper\'s')
    p.add_argument('--grid', type=int, default=3, help='g: largest target width and height, cells')
    p.add_argument('--sides', type=int, default=2, help='1 or 2 target faces')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--unit', type=float, default=0.05, help='grid pitch (the cube edge of flush blocks), metres')
    p.add_argument('--clearance', type=float, default=0.0,
                   help='gap between neighbouring blocks, a fraction of the unit (0: flush; 0.2: 1 cm at 5 cm)')
    p.add_argument('--supply', choices=('auto', 'table', 'feeder'), default='auto',
                   help='where the blocks start: on the table, in a feeder presenting them at a station, or auto '
                        '(the table where they fit within reach, else the feeder: g >= 8)')
    p.add_argument('--feeder-order', choices=('request', 'queue'), default='request',
                   help="a feeder's order: the plan asks for any block (request) or the feeder dictates (queue)")
    p.add_argument('--feeder-window', type=int, default=3,
                   help='a queue feeder: how many of its first blocks the robot may take from (a tray)')
    p.add_argument('-o', '--output', help='output file (default: stdout)')
    p.set_defaults(func=cmd_scene_generate)
    p = scene.add_parser('check', help='validate a scene file; of studded bricks, say whether what is built stands',
                         description='A scene file: validate it, and where its blocks are studded bricks, say '
                                     'whether the blocks built in its target stand with their clutch. A brick '
                                     'design (.txt, .ldr, .mpd): whether it stands, which brick falls first and '
                                     'why (exit 1 when it falls).')
    p.add_argument('scene', help="scene file (- for stdin) or brick design")
    _add_brick_args(p)
    p.set_defaults(func=cmd_scene_check)
    p = scene.add_parser('from-bricks', help='a scene from a brick design, keeping its bricks',
                         description='Read a brick model (text: one brick a line, "HxW (x,y,z)"; LDraw .ldr/.mpd '
                                     'of common bricks and plates): its cells are the target, its bricks the blocks, '
                                     'laid out on the table or in a feeder (docs/formats.md). A design that does not '
                                     'stand even with clutch is refused, naming the brick that falls.')
    p.add_argument('design', help='brick design file (.txt, .ldr, .mpd)')
    _add_brick_args(p)
    p.add_argument('--yaw', type=int, choices=(0, 90, 180, 270), help='turn the design (default: the yaw that fits)')
    p.add_argument('--seed', type=int, default=0, help='seed of the layout on the table')
    p.add_argument('--supply', choices=('auto', 'table', 'feeder'), default='auto',
                   help='where the bricks start: the table, a feeder, or auto (the table where they fit)')
    p.add_argument('-o', '--output', help='output scene file (default: stdout)')
    p.set_defaults(func=cmd_scene_from_bricks)
    p = scene.add_parser('render', help='draw a scene (and an allocation) to a PNG')
    p.add_argument('scene')
    p.add_argument('-o', '--output', required=True)
    p.add_argument('--allocation', help='rad-allocation/1 file to draw as ghost blocks')
    p.add_argument('--width', type=int, default=640)
    p.add_argument('--height', type=int, default=480)
    p.add_argument('--robot', action='store_true', help='draw the Panda (at its home pose) too')
    p.set_defaults(func=cmd_scene_render)
    p = scene.add_parser('stats', help='target-size statistics of generated scenes')
    p.add_argument('--grid', type=int, default=3)
    p.add_argument('--sides', type=int, default=2)
    p.add_argument('--scenes', type=int, default=1000)
    p.add_argument('--seed', type=int, default=0)
    p.set_defaults(func=cmd_scene_stats)
    p = scene.add_parser('from-mesh', help='a target from a mesh (STL, OBJ, PLY, OFF, GLB/GLTF), with the blocks '
                                           'to build it',
                         description='Voxelize meshes at the unit (a cell is a target cell when its centre is inside '
                                     'the solid; a mesh with holes or several overlapping shells is repaired and '
                                     'flood-filled from outside, and a line says what was done), place them as '
                                     'target regions in front of the robot, choose and lay out the blocks '
                                     '(docs/formats.md).')
    p.add_argument('models', nargs='+', metavar='MODEL',
                   help='mesh file, or NAME=FILE to name its region; several files: regions back to back along y')
    _add_target_args(p)
    p.add_argument('--size', type=int, metavar='N', help='the longest side of the models, in cells')
    p.add_argument('--scale', type=float, metavar='S', help='metres per mesh unit (default: 1, a model in metres)')
    _add_supply_args(p)
    p.set_defaults(func=cmd_scene_from_mesh)
    p = scene.add_parser('from-voxels', help='a target from a voxel grid (.npy boolean z-up, binvox), with blocks',
                         description='One cell per voxel; place the grids as target regions in front of the robot, '
                                     'choose and lay out the blocks (docs/formats.md).')
    p.add_argument('files', nargs='+', metavar='FILE', help='.npy or .binvox file, or NAME=FILE to name its region')
    _add_target_args(p)
    _add_supply_args(p)
    p.set_defaults(func=cmd_scene_from_voxels)
    p = scene.add_parser('supply', help='choose the blocks for a scene\'s target and lay them out on the table',
                         description='CP-SAT over the allocation\'s placements: an exact, stable cover with the '
                                     'fewest (or cheapest) blocks where one exists, else the most it can cover; '
                                     'the blocks replace the scene\'s.')
    p.add_argument('scene', help='scene file (its block types are offered unless --types or --inventory), - for stdin')
    _add_supply_args(p, no_supply=False)
    p.set_defaults(func=cmd_scene_supply)

    p = sub.add_parser('allocate', help='solve the allocation MILP for a scene, print rad-allocation/1 JSON')
    p.add_argument('scene', help='scene file, or - for stdin')
    p.add_argument('--solver', choices=['cp-sat', 'highs'], default='cp-sat')
    p.add_argument('-o', '--output', help='output file (default: stdout)')
    _add_solver_args(p)
    p.set_defaults(func=cmd_allocate)

    p = sub.add_parser('demo', help='bring up the node graph, plan and build a scene (the main job)')
    p.add_argument('--scene', help='scene file (default: a generated g=4 two-sided scene)')
    p.add_argument('--out', default='out/demo', help='output folder')
    p.add_argument('--rtf', type=float, default=5.0, help='twin speed, simulated s per wall s')
    p.add_argument('--time-limit', type=float, default=120.0, help='planning time limit, s')
    p.add_argument('--faults', default='none', metavar='none|realistic|FILE',
                   help="the twin's faults of a real cell: none, realistic, or a JSON/YAML file of FaultConfig fields")
    p.add_argument('--faults-seed', type=int, default=0, help='seed of the faults')
    p.add_argument('--cycles', type=int, default=1, metavar='N',
                   help='build, take apart and build again N times, with no reset (1: build once)')
    p.add_argument('--effector', choices=('hand', 'suction'), default='hand',
                   help="the arm's end effector: Franka's parallel hand, or the vacuum gripper in its place")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser('limits', help="check a result's or plan's arm trajectories against a Franka's limits")
    p.add_argument('result', help='rad-result/1 JSON (out/demo/result.json) or a plan with steps, - for stdin')
    p.add_argument('--robot', default='panda', choices=['panda', 'fr3'])
    p.add_argument('--joint-prefix', default='', help="arm joints <prefix>_joint1..7 ('' = the model's)")
    p.set_defaults(func=cmd_limits)
    p = sub.add_parser('calibrate', help='fit the motion-capture frame (or, with --hand-eye, a fixed camera) to '
                                         'the robot base')
    p.add_argument('pairs', nargs='?', help='CSV with the header x_base,y_base,z_base,x_mocap,y_mocap,z_mocap '
                                            '(any order, other columns ignored), - for stdin')
    p.add_argument('--hand-eye', metavar='POSES.csv',
                   help='fit a fixed camera from a tag on the flange instead: CSV with the header bf_x,bf_y,bf_z,'
                        'bf_qx,bf_qy,bf_qz,bf_qw (the flange in the base) and ct_x,...,ct_qw (the tag in the '
                        'camera), - for stdin')
    p.add_argument('--out', metavar='FILE', help="write the assembly node's parameters (ROS 2 YAML) here")
    p.add_argument('--max-rms', type=float, default=0.005, metavar='M',
                   help='refuse a fit whose rms (position) residual is over this, m (default: 0.005)')
    p.add_argument('--mocap-frame', default='mocap', metavar='NAME',
                   help="the motion-capture frame's name (with --hand-eye: the camera frame's), written as "
                        'mocap_frame (default: mocap)')
    p.set_defaults(func=cmd_calibrate)
    p = sub.add_parser('eval', help="the paper's metrics (R, d, e, f, f_g, f_p, coverage) of a sequencer over scenes")
    # A name, not argparse choices: the registry imports the solvers and networks, and building the parser
    # must stay quick for every command; get_agent refuses an unknown name with the list of valid ones.
    p.add_argument('--agent', default='heur', metavar='AGENT',
                   help='the agent to evaluate (default: heur): a preset (default, greedy, paper, heur, heur-verified, '
                        'exact) or scorer+parts, e.g. milp-dqn-mixed+mcts:10+verify+realloc+support:stable '
                        '(rad_core.sequencing.decide.agents); results record its canonical text')
    p.add_argument('--verify', action='store_true',
                   help='take the best-ranked action the planning copy finds feasible (GAMP with the robot, '
                        'the stability check without): no failures by construction')
    p.add_argument('--reallocate', action='store_true',
                   help='when sequencing stalls with allocated poses left, exclude the poses that fail (no-goods) '
                        'and re-solve the allocation over the free cells, then go on (each event is in the rows)')
    p.add_argument('--checkpoint', metavar='FILE',
                   help='learned agents: a model file (runs/NAME/model.pt) to load instead of the shipped weights')
    p.add_argument('--budget', type=int, metavar='N',
                   help='search agents (*-mcts, *-halving): simulations (real planning-twin steps) per decision; '
                        'default 5, the paper\'s')
    p.add_argument('--grid', type=int, default=4, help='g of generated scenes')
    p.add_argument('--sides', type=int, default=2, help='1 or 2 target faces of generated scenes')
    p.add_argument('--scenes', type=int, default=20, help='number of generated scenes')
    p.add_argument('--seed', type=int, default=0, help='first generator seed; scene i seeds the policy with seed + i')
    p.add_argument('--robot', action='store_true',
                   help='robot in the loop (GAMP + twin) for heur; heur-verified always has it, heur-norobot never')
    p.add_argument('--execution', choices=['teleport', 'simulate'], default='teleport',
                   help='robot runs: put the block in place (fast) or simulate the whole arm motion')
    p.add_argument('--effector', choices=['hand', 'suction'], default='hand',
                   help="robot runs: the arm's end effector, Franka's hand or the vacuum gripper in its place")
    p.add_argument('--scene-dir', metavar='DIR', help='evaluate every *.json scene in DIR instead of generating')
    p.add_argument('--support', choices=['none', 'stable', 'arm', 'hand'],
                   help="allocation: the paper's MILP (none), every allocated block able to stand (stable), "
                        "that and nothing the arm can never do (arm), or that and an order a top-down hand can "
                        "place it in (hand); default: the agent's own (its support: part, else what its model "
                        "file was trained for, none for heur)")
    p.add_argument('--json', metavar='FILE', help='write the metrics and per-scene rows here')
    p.add_argument('--workers', type=int, metavar='N',
                   help='run the scenes on a Dask cluster of N worker processes on 127.0.0.1 (the same rows and '
                        'metrics as the serial run); with --scheduler: wait for at least N workers there')
    p.add_argument('--scheduler', metavar='ADDR',
                   help='run the scenes on the workers of an existing Dask scheduler, e.g. tcp://127.0.0.1:8786 '
                        '(they need the same rad installed)')
    p.add_argument('--dashboard', action='store_true',
                   help='with --workers: serve the Dask dashboard on 127.0.0.1:8787 (needs bokeh)')
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser('ceiling', help='the robot-feasible ceiling of a scene (the most any order of its '
                                      'allocations, then of every pose, builds with the robot), and how far an '
                                      'agent is from it')
    p.add_argument('scenes', nargs='+', metavar='SCENE', help='scene files (- reads one from stdin)')
    p.add_argument('--time-limit', type=float, default=60.0, metavar='S',
                   help='seconds of branch and bound per scene (default 60); a cut search is a lower bound')
    p.add_argument('--agent', metavar='AGENT',
                   help="plan with this agent first (e.g. default), build its plan in the twin, and start the "
                        "search from what it built (the incumbent); the line says how far it is from the ceiling")
    p.add_argument('--support', default='arm,hand', metavar='RULES',
                   help="the allocations searched from the empty scene, in turn, while the one before was "
                        "exhausted below the bound (default arm,hand); then every pose, while time is left")
    p.add_argument('--allocations-only', action='store_true',
                   help='do not search every pose after the allocations (small targets finish there)')
    p.add_argument('--effector', choices=('hand', 'suction'), default='hand',
                   help="the arm's end effector: Franka's parallel hand, or the vacuum gripper in its place")
    p.add_argument('--seed', type=int, default=0, help="the agent's seed (scene i: seed + i)")
    p.add_argument('--json', metavar='FILE', help='write each scene\'s ceiling, how its search ended and its line here')
    p.set_defaults(func=cmd_ceiling)

    dataset = sub.add_parser('dataset', help='training scenes with precomputed allocations').add_subparsers(
        dest='action', required=True)
    p = dataset.add_parser('build', help='generate scenes, solve their allocations once, store them compactly')
    p.add_argument('--grids', default='3', help='comma-separated g values, e.g. 3 or 3,4,5')
    p.add_argument('--scenes', type=int, default=50_000, help='scenes per grid size')
    p.add_argument('--sides', type=int, default=2)
    p.add_argument('--seed', type=int, default=1_000_000, help='first generator seed (evaluation uses 0..)')
    p.add_argument('--shapes', help="also add the hand-made shapes of this split ('train')")
    p.add_argument('--shape-seeds', type=int, default=20, help='block layouts per hand-made shape')
    p.add_argument('--support', choices=['none', 'stable'], default='none',
                   help="allocation: the paper's MILP (none) or every block able to stand (stable)")
    p.add_argument('-o', '--output', required=True)
    p.set_defaults(func=cmd_dataset_build)

    p = sub.add_parser('train', help='train a sequencing policy with DQN (milp-dqn, dqn, dqn-rel)')
    p.add_argument('--out', required=True, help='run folder: progress.csv, tb/, checkpoint.pt, model.pt, curves.png')
    p.add_argument('--resume', action='store_true', help="continue the run in --out from its checkpoint")
    p.add_argument('--actors', type=int, metavar='N',
                   help='collect experience with N Dask actors (a LocalCluster on 127.0.0.1 unless --scheduler) '
                        'while this process learns; not bit-deterministic')
    p.add_argument('--chunk-steps', type=int, metavar='STEPS',
                   help='with --actors: environment steps an actor plays per task (default: 32)')
    p.add_argument('--refresh-every', type=int, metavar='GRAD_STEPS',
                   help='with --actors: gradient steps between the weights the actors get (default: 10)')
    p.add_argument('--seeds', metavar='S1,S2,...',
                   help='train these seeds in parallel (one Dask task each), each the serial run of --seed S '
                        'into OUT/seed-S')
    p.add_argument('--scheduler', metavar='ADDR',
                   help='with --actors or --seeds: use the workers of an existing Dask scheduler, '
                        'e.g. tcp://127.0.0.1:8786')
    if command == 'train':
        _add_train_args(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser('expert', help='expert iteration: train the network on the lines the verified, repairing '
                                      'planner keeps (robot in the loop)')
    p.add_argument('--out', required=True, help='run folder: demos/, rR.pt, model.pt, progress.jsonl, expert.log')
    p.add_argument('--resume', action='store_true', help='continue the run in --out (only --rounds may change)')
    if command == 'expert':
        from rad_core.training.expert import ExpertConfig  # torch: this command only
        _add_train_args(p, ExpertConfig)
    p.set_defaults(func=cmd_expert)
    return parser


def _command(argv: list[str]) -> str | None:
    """The subcommand argv names: its first word that is not an option (the top level has only --debug)."""
    return next((a for a in argv if not a.startswith('-')), None)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command(argv))
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

"""The main job: bring up the graph, plan and build a scene, write what happened.

    demo [--scene FILE] [--out DIR] [--rtf X] [--time-limit S]
         [--faults none|realistic|FILE] [--faults-seed N] [--cycles N] [--effector hand|suction]

Writes DIR/scene.json, DIR/result.json (rad-result/1), pictures of the build and, when
the Rerun visualizer is installed, DIR/recording.rrd; node logs in DIR/logs/. The pictures
(rad_core.view.render.save_build_pictures) show the structure close up from two sides, target
cells no block fills as translucent pink cubes and blocks on cells outside the target tinted
red: DIR/before.png (the target and the heap at the start), DIR/after.png (what was built, as
motion capture saw it at the end) and DIR/build.png, an animated PNG of the structure after
each step (blocks at their planned poses).
Without --scene it builds the default scene: two-sided, g = 4, generator seed 8.

--faults gives the twin the faults of a real cell (rad_core.sim.faults: 'realistic'
or a JSON/YAML file of FaultConfig fields; 'none' by default).

--cycles N builds, takes the structure apart back onto the table (/take_apart: every
block back to its heap pose or a free spot, every motion verified) and builds again
from what motion capture sees, N times, with no reset and nothing touched by hand:
every cycle is a build and a take-apart, so the cell ends on the heap it started from.
One line per cycle; result.json is the last build's document with a `cycles` list of
per-cycle figures (coverage, steps, replans, failures, blocks lost, drift from the heap
in mm, wall time); DIR/cycles/ holds each build's and take-apart's own document.
Without --cycles: one build, no take-apart (the demo as it always was).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import rclpy
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.sequencing.execution.result import final_scene
from rclpy.action import ActionClient

from rad_planner.graph import default_params, start_graph

DEFAULT_SCENE = (GeneratorConfig(grid=4, sides=2), 8)


def faults_param(spec: str, seed: int = 0) -> str:
    """The twin's `faults` parameter for --faults: 'none', 'realistic' or a file's absolute path;
    RadError naming the problem for anything the twin would refuse."""
    from rad_core.sim.faults import FaultConfig
    spec = spec.strip()
    if spec not in ('none', 'realistic'):
        path = Path(spec).expanduser()
        if not path.is_file():
            raise RadError(f'--faults: {spec!r} is neither none, realistic nor a file')
        spec = str(path.resolve())
    FaultConfig.parse(spec, seed)
    return spec


def _goal(node, client, goal, what: str, timeout_s: float):
    """Send an action goal, print its feedback, wait for its result."""
    def feedback(msg):
        f = msg.feedback
        print(f'  {what} step {f.step + 1}: {f.phase} {f.block_id} {f.message}'.rstrip(), flush=True)

    sent = client.send_goal_async(goal, feedback_callback=feedback)
    rclpy.spin_until_future_complete(node, sent, timeout_sec=30.0)
    handle = sent.result()
    if handle is None or not handle.accepted:
        raise RadError(f'the {what} goal was not accepted')
    done = handle.get_result_async()
    rclpy.spin_until_future_complete(node, done, timeout_sec=timeout_s)
    if done.result() is None:
        raise RadError(f'no result from {what} in time')
    return done.result().result


def _failures(doc: dict) -> int:
    return sum(1 for s in doc.get('steps', []) if s.get('failure'))


def cycle_figures(k: int, build, build_doc: dict, build_s: float, apart=None, apart_doc=None,
                  apart_s: float = 0.0) -> dict:
    """One cycle's row of result.json's `cycles`."""
    row = {'cycle': k, 'coverage': float(build.coverage),
           'build': {'success': bool(build.success), 'reason': build.reason, 'steps': int(build.steps_executed),
                     'replans': int(build.replans), 'failures': _failures(build_doc) + (not build.success),
                     'wall_s': build_s}}
    lost, drift = [], {'mean_mm': 0.0, 'max_mm': 0.0}
    if apart is not None:
        lost = list(apart.lost)
        drift = {'mean_mm': 1e3 * apart.drift_mean_m, 'max_mm': 1e3 * apart.drift_max_m}
        row['take_apart'] = {'success': bool(apart.success), 'reason': apart.reason,
                             'steps': int(apart.steps_executed), 'replans': int(apart.replans),
                             'failures': _failures(apart_doc or {}) + (not apart.success), 'wall_s': apart_s}
    parts = [row['build']] + ([row['take_apart']] if apart is not None else [])
    row.update({'steps': sum(p['steps'] for p in parts), 'replans': sum(p['replans'] for p in parts),
                'failures': sum(p['failures'] for p in parts), 'blocks_lost': len(lost), 'lost': lost,
                'drift_mm': drift, 'wall_s': build_s + apart_s})
    return row


def cycle_line(row: dict, n: int) -> str:
    apart = row.get('take_apart')
    steps = f'{row["build"]["steps"]} + {apart["steps"]} steps' if apart else f'{row["steps"]} steps'
    line = (f'demo: cycle {row["cycle"]}/{n}: coverage {row["coverage"]:.2f}, {steps}, {row["replans"]} replans, '
            f'{row["failures"]} failures, {row["blocks_lost"]} lost, drift {row["drift_mm"]["mean_mm"]:.1f} mean / '
            f'{row["drift_mm"]["max_mm"]:.1f} max mm, {row["wall_s"]:.1f} s')
    reasons = [p['reason'] for p in (row['build'], apart or {}) if p.get('reason')]
    return line + (f' ({"; ".join(reasons)})' if reasons else '')


def run(scene: Scene, out: Path, rtf: float, time_limit: float, faults: str = 'none', faults_seed: int = 0,
        cycles: int | None = None, effector: str = 'hand') -> dict:
    from rad_msgs.action import ExecuteAssembly, TakeApart
    from rad_msgs.srv import Sequence
    out.mkdir(parents=True, exist_ok=True)
    scene_path = out / 'scene.json'
    scene_path.write_text(scene.dumps() + '\n')
    twin = {'scene_file': str(scene_path.resolve()), 'real_time_factor': str(rtf)}
    overrides = {'twin': twin, 'viz': {'recording_path': str((out / 'recording.rrd').resolve())}}
    if effector != 'hand':
        # Every node that plans, allocates, commands or simulates the end effector is told which.
        twin['effector'] = effector
        for node_name in ('gamp', 'assembly', 'allocation', 'viz'):
            overrides.setdefault(node_name, {})['effector'] = effector
    if faults != 'none':
        from rad_core.sim.faults import FaultConfig
        twin.update({'faults': faults, 'faults_seed': str(int(faults_seed))})
        # The assembly node is told the tracker's noise, as a user would configure it for their cell.
        config = FaultConfig.parse(faults, int(faults_seed))
        overrides.setdefault('assembly', {}).update(mocap_noise=str(config.mocap_position_noise),
                                                    mocap_yaw_noise_deg=str(config.mocap_yaw_noise_deg))
    t0 = time.perf_counter()
    graph = start_graph(default_params(), overrides, log_dir=out / 'logs')
    rclpy.init()
    node = rclpy.create_node('rad_demo')
    rows, docs = [], []
    try:
        client = ActionClient(node, ExecuteAssembly, 'execute_assembly')
        if not client.wait_for_server(timeout_sec=60.0):
            raise RadError(f'the graph did not come up (see {out / "logs"})')
        if not node.create_client(Sequence, 'sequence').wait_for_service(timeout_sec=60.0):
            raise RadError(f'the sequencer did not come up (see {out / "logs"}/sequencer.log)')
        apart_client = None
        if cycles is not None:
            apart_client = ActionClient(node, TakeApart, 'take_apart')
            if not apart_client.wait_for_server(timeout_sec=30.0):
                raise RadError('the assembly node serves no /take_apart action: --cycles needs it')
            (out / 'cycles').mkdir(exist_ok=True)
        time.sleep(1.0)   # let the twin publish its first motion-capture frames
        for k in range(1, (cycles or 1) + 1):
            if cycles is not None:
                print(f'demo: cycle {k}/{cycles}: building', flush=True)
            tb = time.perf_counter()
            # The first build is of the scene as given; later ones of the world as motion capture sees it.
            goal = ExecuteAssembly.Goal(scene_json=scene.dumps() if k == 1 else '', time_limit_s=time_limit,
                                        replan=True)
            result = _goal(node, client, goal, 'build', time_limit + 600.0)
            build_s = time.perf_counter() - tb
            doc = json.loads(result.result_json) if result.result_json else {}
            docs.append(doc)
            if cycles is None:
                break
            (out / 'cycles' / f'build_{k}.json').write_text(json.dumps(doc, indent=1) + '\n')
            print(f'demo: cycle {k}/{cycles}: taking apart', flush=True)
            ta = time.perf_counter()
            order = [s['block'] for s in doc.get('steps', []) if not s.get('failure')]
            apart = _goal(node, apart_client, TakeApart.Goal(heap_json=scene.dumps(), build_order=order,
                                                             time_limit_s=time_limit), 'take apart',
                          time_limit + 600.0)
            apart_doc = json.loads(apart.result_json) if apart.result_json else {}
            (out / 'cycles' / f'take_apart_{k}.json').write_text(json.dumps(apart_doc, indent=1) + '\n')
            rows.append(cycle_figures(k, result, doc, build_s, apart, apart_doc, time.perf_counter() - ta))
            print(cycle_line(rows[-1], cycles), flush=True)
            if not apart.success:
                print(f'demo: stopping after cycle {k}: the take-apart failed', file=sys.stderr, flush=True)
                break
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        codes = graph.stop()
    doc = dict(docs[-1]) if docs else {}
    doc.setdefault('timings', {})['demo_total'] = time.perf_counter() - t0
    if cycles is not None:
        doc['cycles'] = rows
    (out / 'result.json').write_text(json.dumps(doc, indent=1) + '\n')
    final = final_scene({**doc, 'scene': scene.to_dict()})
    # The last build's own start: with --cycles, the heap as motion capture saw it after a take-apart.
    start = Scene.from_dict(doc['scene']) if doc.get('scene') else scene
    from rad_core.view.render import save_build_pictures
    save_build_pictures(start, final, doc.get('steps', []), out)
    return {'result': result, 'doc': doc, 'exit_codes': codes, 'final': final, 'cycles': rows}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='demo', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scene', type=Path, help='rad-scene/1 file (default: the generated default scene)')
    parser.add_argument('--out', type=Path, default=Path('out/demo'))
    parser.add_argument('--rtf', type=float, default=5.0, help='twin speed, simulated s per wall s')
    parser.add_argument('--time-limit', type=float, default=120.0, help='planning time limit, s')
    parser.add_argument('--faults', default='none', metavar='none|realistic|FILE',
                        help="the twin's faults of a real cell (default none)")
    parser.add_argument('--faults-seed', type=int, default=0, help="seed of the twin's faults")
    parser.add_argument('--cycles', type=int, metavar='N',
                        help='build, take apart, N times with no reset (default: one build, no take-apart)')
    parser.add_argument('--effector', choices=('hand', 'suction'), default='hand',
                        help="the arm's end effector: Franka's hand, or the vacuum gripper in its place")
    args = parser.parse_args(argv)
    try:
        scene = Scene.load(args.scene) if args.scene else generate_scene(*DEFAULT_SCENE)
        if not args.rtf > 0 or not args.time_limit > 0:
            raise RadError('--rtf and --time-limit must be positive')
        if args.cycles is not None and args.cycles < 1:
            raise RadError(f'--cycles must be at least 1, got {args.cycles}')
        if args.faults_seed < 0:
            raise RadError(f'--faults-seed must be >= 0, got {args.faults_seed}')
        faults = faults_param(args.faults, args.faults_seed)
        print(f'demo: {len(scene.blocks)} blocks, {scene.num_target_cells} target cells'
              + (f', faults {args.faults}' if faults != 'none' else '')
              + (f', {args.cycles} cycles' if args.cycles else '')
              + (f', the {args.effector} gripper' if args.effector != 'hand' else '')
              + '; starting the graph', flush=True)
        run_ = run(scene, args.out, args.rtf, args.time_limit, faults, args.faults_seed, args.cycles, args.effector)
    except RadError as e:
        print(f'demo: error: {e}', file=sys.stderr)
        return 2
    result, doc = run_['result'], run_['doc']
    files = ', '.join(str(args.out / f) for f in ('scene.json', 'result.json', 'before.png', 'after.png',
                                                  'build.png', 'recording.rrd') if (args.out / f).exists())
    print(f'demo: {"built" if result.success else "stopped"}: {result.steps_executed} steps, '
          f'{result.replans} replans, coverage {result.coverage:.2f}'
          + (f' ({result.reason})' if result.reason else ''))
    print(f'demo: {doc["timings"]["demo_total"]:.1f} s; wrote {files}')
    bad = {n: c for n, c in run_['exit_codes'].items() if c != 0}
    if bad:
        print(f'demo: nodes did not exit cleanly: {bad}', file=sys.stderr)
    rows = run_['cycles']
    cycles_ok = args.cycles is None or (len(rows) == args.cycles and all(
        r['build']['steps'] > 0 and r['take_apart']['success'] and not r['blocks_lost'] for r in rows))
    return 0 if result.steps_executed > 0 and cycles_ok and not bad else 1


if __name__ == '__main__':
    sys.exit(main())

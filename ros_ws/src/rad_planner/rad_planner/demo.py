"""The main job: bring up the graph, plan and build a scene, write what happened.

    demo [--scene FILE] [--out DIR] [--rtf X] [--time-limit S]

Writes DIR/scene.json, DIR/result.json (rad-result/1), DIR/final.png and, when
the Rerun visualizer is installed, DIR/recording.rrd; node logs in DIR/logs/.
Without --scene it builds the default scene: two-sided, g = 4, generator seed 8.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import rclpy
from rclpy.action import ActionClient

from rad_core.errors import RadError
from rad_core.generator import GeneratorConfig, generate_scene
from rad_core.scene import Scene
from rad_planner.graph import default_params, start_graph

DEFAULT_SCENE = (GeneratorConfig(grid=4, sides=2), 8)


def run(scene: Scene, out: Path, rtf: float, time_limit: float) -> dict:
    from rad_msgs.action import ExecuteAssembly
    from rad_msgs.srv import Sequence
    out.mkdir(parents=True, exist_ok=True)
    scene_path = out / 'scene.json'
    scene_path.write_text(scene.dumps() + '\n')
    overrides = {'twin': {'scene_file': str(scene_path.resolve()), 'real_time_factor': str(rtf)},
                 'viz': {'recording_path': str((out / 'recording.rrd').resolve())}}
    t0 = time.perf_counter()
    graph = start_graph(default_params(), overrides, log_dir=out / 'logs')
    rclpy.init()
    node = rclpy.create_node('rad_demo')
    try:
        client = ActionClient(node, ExecuteAssembly, 'execute_assembly')
        if not client.wait_for_server(timeout_sec=60.0):
            raise RadError(f'the graph did not come up (see {out / "logs"})')
        if not node.create_client(Sequence, 'sequence').wait_for_service(timeout_sec=60.0):
            raise RadError(f'the sequencer did not come up (see {out / "logs"}/sequencer.log)')
        time.sleep(1.0)   # let the twin publish its first motion-capture frames

        def feedback(msg):
            f = msg.feedback
            print(f'  step {f.step + 1}: {f.phase} {f.block_id} {f.message}'.rstrip(), flush=True)

        sent = client.send_goal_async(ExecuteAssembly.Goal(scene_json=scene.dumps(), time_limit_s=time_limit,
                                                           replan=True), feedback_callback=feedback)
        rclpy.spin_until_future_complete(node, sent, timeout_sec=30.0)
        handle = sent.result()
        if handle is None or not handle.accepted:
            raise RadError('the execute_assembly goal was not accepted')
        done = handle.get_result_async()
        rclpy.spin_until_future_complete(node, done, timeout_sec=time_limit + 600.0)
        if done.result() is None:
            raise RadError('no result from execute_assembly in time')
        result = done.result().result
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        codes = graph.stop()
    doc = json.loads(result.result_json) if result.result_json else {}
    doc.setdefault('timings', {})['demo_total'] = time.perf_counter() - t0
    (out / 'result.json').write_text(json.dumps(doc, indent=1) + '\n')
    final = None
    if doc.get('final_blocks'):
        final = Scene.from_dict(dict(scene.to_dict(), blocks=doc['final_blocks']))
        from rad_core.render import save_scene_png
        from rad_core.sim.panda import HOME
        save_scene_png(final, out / 'final.png', robot=HOME)
    return {'result': result, 'doc': doc, 'exit_codes': codes, 'final': final}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='demo', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scene', type=Path, help='rad-scene/1 file (default: the generated default scene)')
    parser.add_argument('--out', type=Path, default=Path('out/demo'))
    parser.add_argument('--rtf', type=float, default=5.0, help='twin speed, simulated s per wall s')
    parser.add_argument('--time-limit', type=float, default=120.0, help='planning time limit, s')
    args = parser.parse_args(argv)
    try:
        scene = Scene.load(args.scene) if args.scene else generate_scene(*DEFAULT_SCENE)
        if not args.rtf > 0 or not args.time_limit > 0:
            raise RadError('--rtf and --time-limit must be positive')
        print(f'demo: {len(scene.blocks)} blocks, {scene.num_target_cells} target cells; starting the graph',
              flush=True)
        run_ = run(scene, args.out, args.rtf, args.time_limit)
    except RadError as e:
        print(f'demo: error: {e}', file=sys.stderr)
        return 2
    result, doc = run_['result'], run_['doc']
    files = ', '.join(str(args.out / f) for f in ('scene.json', 'result.json', 'final.png', 'recording.rrd')
                      if (args.out / f).exists())
    print(f'demo: {"built" if result.success else "stopped"}: {result.steps_executed} steps, '
          f'{result.replans} replans, coverage {result.coverage:.2f}'
          + (f' ({result.reason})' if result.reason else ''))
    print(f'demo: {doc["timings"]["demo_total"]:.1f} s; wrote {files}')
    bad = {n: c for n, c in run_['exit_codes'].items() if c != 0}
    if bad:
        print(f'demo: nodes did not exit cleanly: {bad}', file=sys.stderr)
    return 0 if result.steps_executed > 0 and not bad else 1


if __name__ == '__main__':
    sys.exit(main())

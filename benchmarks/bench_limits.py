"""Franka limits of planned motions, before (velocity-only timing) and after (ruckig, 7 arm joints).

    python benchmarks/bench_limits.py --before-src /tmp/rad_before/ros_ws/src/rad_core
        [--grids 4,5] [--seeds 5] [--first-seed 1000] [--shapes arch,tower,stairs,tee,window]
        [--jobs 2] [--quick] [--results docs/results]

`--before-src` is rad_core of the old code (a worktree of commit ca41401:
``git worktree add /tmp/rad_before ca41401``); without it only the new code runs.

Scenes: generated two-sided scenes of grid 4 and 5 (`generate_scene(GeneratorConfig(grid=g), seed)`,
seeds 1000.. by default: neither the evaluation seeds 0.. nor training's 1 000 000..) and a few of the
hand-made shapes (`rad_core.domain.shapes.shape_scene`).

For each scene and each variant (after-panda: the current code's default timing,
`TimingConfig(robot='panda')`, within the Panda's and the FR3's limits at once; after-fr3:
`TimingConfig(robot='fr3', limits='robot')`, within the FR3's own; before: the old code in a
subprocess with PYTHONPATH set to `--before-src`) the HEUR sequencer plans the whole assembly in-process (CP-SAT
allocation, GAMP), then the in-process twin executes the plan step by step (stopping at
the first step that fails) and settles 0.3 s; the coverage is measured on the twin's
registered scene (`measured_coverage`; a block that registration refuses, one that fell
on its side, fills nothing and is counted as dropped).

Every arm trajectory, in execution order (the first from HOME, each from the previous
one's last point, at rest), is sampled at 1 kHz as a joint_trajectory_controller
interpolates it and its peak |v|, |a|, |jerk| are compared with the Panda's and the
FR3's published limits (`rad_core.cell.robot_model`): after, with
`rad_core.cell.trajectory.limit_ratios` (quintic; the joints renamed for the other robot);
before, the old 9-joint trajectories' arm columns, cubic with velocities
(`rad_core.cell.trajectory.Spline`), with the acceleration at rest before t = 0 (the step
into the first cubic is a jerk the robot sees). A trajectory is over when any ratio
exceeds 1 (the twin's rule, `limit_violation`); "over 1.001" counts those over by more than
rounding.

Motion time per build: after, the arm trajectories' durations plus the gripper's moves
(|travel| at 0.05 m/s per finger, at least 0.1 s each); before, the trajectories'
durations (the fingers moved inside them). Prints per scene set the worst ratios, the
trajectories over the limits, motion time and coverage before / after; writes the page,
<results>/limits.md (`common.write_page`, one table), and one compact JSON line per (scene, variant)
(limits.rows.jsonl, each with the sha256 of the rad_core it ran, `source_digest`).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from common import RESULTS, write_page

VARIANTS = ('before', 'panda', 'fr3')
MODELS = ('panda', 'fr3')
GRIPPER_SPEED = 0.05       # m/s per finger (franka_gripper's 0.1 m/s of width; the twin's gripper_speed)
GRIPPER_MIN_S = 0.1        # s, the shortest gripper move
MATERIAL = 1e-3            # a ratio over 1 + this is over by more than rounding
SETTLE_S = 0.3
DEFAULT_SHAPES = 'arch,tower,stairs,tee,window'


# ---- workers: plan and execute in one process (new code, or old code under --before-src) ----------

def _coverage(twin) -> tuple[float, list[str]]:
    """measured_coverage of the twin's registered scene; bodies registration refuses are left out."""
    from rad_core.cell.mocap import RegistrationConfig, register_scene
    from rad_core.domain.coverage import measured_coverage
    from rad_core.domain.errors import RadError
    try:
        return measured_coverage(twin.current_scene()), []
    except RadError:
        pass
    template = twin.world.scene
    types = {b.id: b.type for b in template.blocks}
    config = RegistrationConfig(body_map={bid: (bid, types[bid]) for bid in twin.world.blocks})
    good, dropped = [], []
    for body in twin.bodies():
        try:
            register_scene([body], template, config)
            good.append(body)
        except RadError:
            dropped.append(body.name)
    try:
        return measured_coverage(register_scene(good, template, config)), dropped
    except RadError:
        return float('nan'), dropped


def worker(variant: str, scenes_file: str, out_file: str) -> None:
    """Plan and execute every scene of scenes_file with the importable rad_core; write the raw results."""
    import rad_core
    from rad_core.allocation import solve
    from rad_core.domain.scene import Scene
    from rad_core.gamp.action import MotionPlanner
    from rad_core.sequencing import HeurPolicy
    from rad_core.sequencing.planning.plan import local_motion_planner, plan_assembly
    from rad_core.sim.twin import Twin
    from rad_core.sim.world import World
    new = variant != 'before'
    if new:
        from rad_core.cell.motion import Motion
        from rad_core.gamp.planner import GampConfig
        from rad_core.gamp.trajectory import TimingConfig
        from rad_core.sim.twin import TwinConfig
        # panda: the default timing (within both robots' limits); fr3: the FR3's own limits only.
        timing = TimingConfig(robot=variant, limits='both' if variant == 'panda' else 'robot')
        planner = MotionPlanner(GampConfig(timing=timing))
    else:
        planner = MotionPlanner()
    plan_motion = local_motion_planner(planner)
    rows = []
    for item in json.loads(Path(scenes_file).read_text()):
        scene = Scene.from_dict(item['scene'])
        row = {'set': item['set'], 'scene': item['name'], 'variant': variant, 'rad_core': rad_core.__file__}
        try:
            t0 = time.perf_counter()
            plan = plan_assembly(scene, solve, plan_motion, HeurPolicy(), seed=0)
            t1 = time.perf_counter()
            row.update(plan_success=bool(plan.success), plan_reason=plan.reason, steps=len(plan.steps),
                       predicted_coverage=float(plan.predicted_coverage), plan_s=t1 - t0,
                       motions=[s.motion if new else {'trajectories': [s.trajectory], 'gripper': []}
                                for s in plan.steps])
            failures = []
            with World(scene) as world:
                twin = Twin(world, TwinConfig(robot=variant)) if new else Twin(world)
                sim0 = twin.time
                for k, step in enumerate(plan.steps):
                    try:
                        problem = (twin.execute_motion(Motion.from_dict(step.motion)) if new
                                   else (twin.execute(step.trajectory), '')[1])
                    except Exception as e:   # noqa: BLE001 (the old twin raises on what it refuses)
                        problem = f'{type(e).__name__}: {e}'
                    if problem:
                        failures.append({'step': k, 'block': step.block, 'problem': problem})
                        break
                sim_s = twin.time - sim0
                twin.settle(SETTLE_S)
                coverage, dropped = _coverage(twin)
            row.update(executed_steps=len(plan.steps) if not failures else failures[0]['step'],
                       exec_failures=failures, coverage=coverage, dropped=dropped, exec_sim_s=sim_s,
                       exec_s=time.perf_counter() - t1)
        except Exception:   # noqa: BLE001 (a core error: reported, the run goes on)
            row['error'] = traceback.format_exc()
        rows.append(row)
        print(f'  [{variant}] {item["name"]}: {row.get("steps", "-")} steps, coverage '
              f'{row.get("coverage", float("nan")):.3f}{"  ERROR" if "error" in row else ""}', flush=True)
    planner.close()
    Path(out_file).write_text(json.dumps(rows))


# ---- analysis (current rad_core) ------------------------------------------------------------------

def _renamed(doc: dict, model) -> dict:
    """An arm trajectory dict with its joints named as `model` names them (joint k stays joint k)."""
    names = [model.arm_joint_names[int(n.rsplit('joint', 1)[1]) - 1] for n in doc['joint_names']]
    return {**doc, 'joint_names': names}


def _old_arm(doc: dict, model):
    """The arm part (7 columns, model order) of an old 9-joint trajectory, cubic with velocities."""
    from rad_core.cell.trajectory import Trajectory, TrajectoryPoint
    names = list(doc['joint_names'])
    idx = [names.index(f'panda_joint{k}') for k in range(1, 8)]
    pts = [TrajectoryPoint([p['positions'][i] for i in idx],
                           [p['velocities'][i] for i in idx] if p.get('velocities') else [],
                           float(p['time_from_start'])) for p in doc['points']]
    return Trajectory(model.arm_joint_names, pts)


def _spline_ratios(traj, start, model, dt: float = 1e-3) -> dict[str, float]:
    """limit_ratios without the controller's parse (the old trajectories may leave a model's range), and
    with the arm at rest (a = 0) before t = 0."""
    from rad_core.cell.trajectory import Spline
    spline = Spline(traj, np.asarray(start, dtype=float)[:7])
    ts = np.arange(0.0, spline.duration + dt / 2, dt)
    _, v, a = spline(ts)
    a = np.vstack([np.zeros((1, a.shape[1])), a])
    j = np.diff(a, axis=0) / dt
    v_max, a_max, j_max = model.limits()
    return {'velocity': float((np.abs(v) / v_max).max()), 'acceleration': float((np.abs(a) / a_max).max()),
            'jerk': float((np.abs(j) / j_max).max())}


def _out_of_range(traj, model) -> bool:
    q = traj.positions()
    return bool(np.any(q < np.asarray(model.q_min) - 1e-3) or np.any(q > np.asarray(model.q_max) + 1e-3))


def gripper_time(motion: dict, fingers: float) -> tuple[float, float]:
    """Seconds of the motion's gripper moves from `fingers` (per finger, m), and where the fingers end."""
    total = 0.0
    for g in motion.get('gripper') or []:
        stop = g.get('expected_position', g['position']) if g['action'] == 'grasp' else g['position']
        total += max(GRIPPER_MIN_S, abs(stop - fingers) / GRIPPER_SPEED)
        fingers = stop
    return total, fingers


def analyse(row: dict) -> dict:
    """Limit ratios per model and motion time of a worker's row (the raw motions dropped)."""
    from rad_core.cell.panda import FINGER_OPEN, HOME
    from rad_core.cell.robot_model import robot_model
    from rad_core.cell.trajectory import Trajectory, limit_ratios
    motions = row.pop('motions', None)
    if motions is None:
        return row
    new = row['variant'] != 'before'
    start, fingers = np.asarray(HOME[:7], dtype=float), FINGER_OPEN
    limits = {m: {'velocity': 0.0, 'acceleration': 0.0, 'jerk': 0.0, 'over': 0, 'over_material': 0,
                  'out_of_range': 0}
              for m in MODELS}
    arm_s = grip_s = 0.0
    n = 0
    for motion in motions:
        g_s, fingers = gripper_time(motion, fingers) if new else (0.0, fingers)
        grip_s += g_s
        for doc in motion['trajectories']:
            n += 1
            for name in MODELS:
                model = robot_model(name)
                if new:
                    traj = Trajectory.from_dict(_renamed(doc, model))
                    r = limit_ratios(traj, start, model)
                else:
                    traj = _old_arm(doc, model)
                    r = _spline_ratios(traj, start, model)
                lim = limits[name]
                for key in ('velocity', 'acceleration', 'jerk'):
                    lim[key] = max(lim[key], r[key])
                lim['over'] += int(max(r.values()) > 1.0)
                lim['over_material'] += int(max(r.values()) > 1.0 + MATERIAL)
                lim['out_of_range'] += int(_out_of_range(traj, model))
            arm_s += float(doc['points'][-1]['time_from_start'])
            end = doc['points'][-1]['positions']
            start = (np.asarray(end[:7], dtype=float) if new
                     else np.asarray(_old_arm(doc, robot_model('panda')).points[-1].positions))
    row.update(trajectories=n, limits=limits, arm_s=arm_s, gripper_s=grip_s, motion_s=arm_s + grip_s)
    return row


# ---- driver -----------------------------------------------------------------------------------------

def scene_sets(args) -> dict[str, list[tuple[str, object]]]:
    from rad_core.domain import shapes
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    n = 2 if args.quick else args.seeds
    sets = {}
    for g in (int(x) for x in args.grids.split(',') if x):
        sets[f'g{g}'] = [(f'g{g}-seed{s}', generate_scene(GeneratorConfig(grid=g), s))
                         for s in range(args.first_seed, args.first_seed + n)]
    names = [x for x in args.shapes.split(',') if x][:2 if args.quick else None]
    if names:
        sets['shapes'] = [(name, shapes.shape_scene(name)) for name in names]
    return sets


def run_task(variant: str, items: list[dict], before_src: str | None, tmp: Path) -> list[dict]:
    """One worker subprocess: a variant over some scenes."""
    tag = f'{variant}-{items[0]["set"]}'
    scenes_file, out_file = tmp / f'{tag}-in.json', tmp / f'{tag}-out.json'
    scenes_file.write_text(json.dumps(items))
    env = dict(os.environ)
    if variant == 'before':
        env['PYTHONPATH'] = before_src + os.pathsep + env.get('PYTHONPATH', '')
    cmd = [sys.executable, __file__, '--worker', variant, '--worker-in', str(scenes_file),
           '--worker-out', str(out_file)]
    proc = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout.splitlines():
        if line.startswith('  ['):
            print(line, flush=True)
    if proc.returncode != 0 or not out_file.exists():
        tail = '\n'.join(proc.stdout.splitlines()[-30:])
        return [{'set': it['set'], 'scene': it['name'], 'variant': variant,
                 'error': f'worker exited {proc.returncode}:\n{tail}'} for it in items]
    rows = json.loads(out_file.read_text())
    if variant == 'before':
        for r in rows:
            if not r.get('rad_core', '').startswith(str(Path(before_src).resolve())):
                r['error'] = f'the before worker imported {r.get("rad_core")}, not {before_src}'
    return [analyse(r) for r in rows]


def source_digest(package_dir: Path) -> str:
    """sha256 (first 12 hex) of a rad_core package's .py files: which code a result came from."""
    import hashlib
    h = hashlib.sha256()
    for f in sorted(package_dir.rglob('*.py')):
        h.update(str(f.relative_to(package_dir)).encode() + b'\0' + f.read_bytes())
    return h.hexdigest()[:12]


def _mean(xs) -> float:
    xs = [x for x in xs if x is not None and np.isfinite(x)]
    return float(np.mean(xs)) if xs else float('nan')


def summarize(rows: list[dict], sets: list[str]) -> dict:
    out = {}
    for s in sets:
        by = {v: {r['scene']: r for r in rows if r['set'] == s and r['variant'] == v and 'error' not in r}
              for v in VARIANTS}
        errors = sum(1 for r in rows if r['set'] == s and 'error' in r)
        summ = {'errors': errors, 'variants': {}}
        for v, rs in by.items():
            if not rs:
                continue
            vals = list(rs.values())
            lim = {m: {k: max(r['limits'][m][k] for r in vals) for k in ('velocity', 'acceleration', 'jerk')}
                   | {k: sum(r['limits'][m][k] for r in vals) for k in ('over', 'over_material', 'out_of_range')}
                   for m in MODELS}
            entry = {'scenes': len(vals), 'trajectories': sum(r['trajectories'] for r in vals), 'limits': lim,
                     'steps': _mean([r['steps'] for r in vals]), 'motion_s': _mean([r['motion_s'] for r in vals]),
                     'coverage': _mean([r['coverage'] for r in vals]),
                     'exec_failures': sum(len(r['exec_failures']) for r in vals),
                     'dropped': sum(len(r['dropped']) for r in vals)}
            if v != 'before' and by['before']:
                common = [k for k in rs if k in by['before']]
                b = by['before']
                entry['common_scenes'] = len(common)
                if common:
                    entry['motion_s_before'] = _mean([b[k]['motion_s'] for k in common])
                    entry['motion_ratio'] = _mean([rs[k]['motion_s'] for k in common]) / entry['motion_s_before']
                    entry['motion_ratio_same_steps'] = _mean(
                        [rs[k]['motion_s'] / b[k]['motion_s'] for k in common if rs[k]['steps'] == b[k]['steps']])
                    diffs = [abs(rs[k]['coverage'] - b[k]['coverage']) for k in common]
                    entry['coverage_before'] = _mean([b[k]['coverage'] for k in common])
                    entry['coverage_max_diff'] = float(max(diffs))
                    entry['same_steps'] = sum(rs[k]['steps'] == b[k]['steps'] for k in common)
            summ['variants'][v] = entry
        out[s] = summ
    return out


HEADERS = ('scenes', 'timed for', 'checked on', 'trajectories', 'v', 'a', 'jerk', 'over 1.0', 'over 1.001',
           'outside q range', 'motion s/build', 'coverage')


def table(summary: dict) -> list[list]:
    """A line per (scene set, timing, robot checked on): peak ratios to the limits, and per timing the motion
    time and coverage of its builds."""
    out = []
    for s, summ in summary.items():
        for v, e in summ['variants'].items():
            for m in ((v,) + tuple(x for x in MODELS if x != v) if v != 'before' else MODELS):
                lim = e['limits'][m]
                out.append([s + (f' ({summ["errors"]} runs with errors, left out)' if summ['errors'] else ''),
                            'before (velocity rule)' if v == 'before' else f'after ({v})', m, e['trajectories'],
                            f'{lim["velocity"]:.3f}', f'{lim["acceleration"]:.3f}', f'{lim["jerk"]:.3f}',
                            lim['over'], lim['over_material'], lim['out_of_range'], f'{e["motion_s"]:.1f}',
                            f'{e["coverage"]:.3f}'])
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--before-src', help='rad_core of the old code (its ros_ws/src/rad_core)')
    p.add_argument('--grids', default='4,5')
    p.add_argument('--seeds', type=int, default=5, help='generated scenes per grid')
    p.add_argument('--first-seed', type=int, default=1000)
    p.add_argument('--shapes', default=DEFAULT_SHAPES, help='hand-made shapes (rad_core.domain.shapes.SPECS names)')
    p.add_argument('--jobs', type=int, default=2, help='worker processes at once')
    p.add_argument('--quick', action='store_true', help='2 scenes per set (a smoke run)')
    p.add_argument('--results', default=str(RESULTS), help='folder of limits.md and limits.rows.jsonl')
    p.add_argument('--worker', choices=VARIANTS, help=argparse.SUPPRESS)
    p.add_argument('--worker-in', help=argparse.SUPPRESS)
    p.add_argument('--worker-out', help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        worker(args.worker, args.worker_in, args.worker_out)
        return 0
    variants = [v for v in VARIANTS if v != 'before' or args.before_src]
    if args.before_src and not (Path(args.before_src) / 'rad_core' / '__init__.py').exists():
        p.error(f'--before-src {args.before_src}: no rad_core package there')
    sets = scene_sets(args)
    import rad_core
    digests = {'after': source_digest(Path(rad_core.__file__).resolve().parent)}
    if args.before_src:
        digests['before'] = source_digest(Path(args.before_src).resolve() / 'rad_core')
    t0 = time.perf_counter()
    tasks = [(v, [{'set': s, 'name': name, 'scene': scene.to_dict()} for name, scene in items])
             for s, items in sets.items() for v in variants]
    tasks.sort(key=lambda t: (t[1][0]['set'] != 'shapes', t[0] == 'before'))   # the long ones first
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        for result in pool.map(lambda t: run_task(t[0], t[1], args.before_src, Path(tmp)), tasks):
            rows.extend(result)
    wall = time.perf_counter() - t0
    summary = summarize(rows, list(sets))
    lines = table(summary)
    print()
    print('\n'.join(' | '.join(map(str, line)) for line in lines))
    errors = [r for r in rows if 'error' in r]
    for r in errors:
        print(f'ERROR {r["variant"]} {r["scene"]}:\n{r["error"]}')
    for r in rows:
        for f in r.get('exec_failures', []):
            print(f'execution stopped: {r["variant"]} {r["scene"]} step {f["step"]} ({f["block"]}): {f["problem"]}')
    print(f'wall time {wall:.0f} s')
    for r in rows:   # which code the row came from: its digest, not the path it was imported from
        r.pop('rad_core', None)
        r['rad_core_sha256'] = digests['before' if r['variant'] == 'before' else 'after']
    note = ('Peak |v|, |a| and |jerk| over all trajectories, sampled at 1 kHz as the controller interpolates, over '
            'the robot\'s published limit; "over 1.0": trajectories a real Franka would stop on, "over 1.001": over '
            'by more than rounding. "before": the old velocity rule over 9 joints (--before-src); "after": ruckig '
            'over the 7 arm joints, timed for the Panda or the FR3. Motion time: arm trajectories plus gripper moves; '
            'coverage measured on the twin after executing the plan.')
    page = write_page('limits', 'Franka limits of planned motions', HEADERS, lines, note, rows, results=args.results)
    print(f'wrote {page}')
    return 1 if errors else 0


if __name__ == '__main__':
    sys.exit(main())

"""What a planning-twin step costs, and that a faster one decides the same.

    python benchmarks/bench_planning_step.py --record out/bench_planning_step/record.json
    python benchmarks/bench_planning_step.py --compare out/bench_planning_step/record.json [--profile 25]
    python benchmarks/bench_planning_step.py --compare out/bench_planning_step/record.json --page

A planning-twin step is `RobotAssemblyEnv.step` with teleporting execution (GAMP decides, the block
is put at its pose, physics settles the structure): what the sequencer's searches and the branch and
bound run thousands of times, between `snapshot()` and `restore()`. The other planning call is the
gamp node's and /plan_assembly's `gamp.action.MotionPlanner.__call__` (a scene state loaded into a
planning world of its own, then `plan_action`).

The fixed set: generated scenes (g = 4 and 5, seeds from 500: never trained on) and hand-made
shapes held out of training (`shapes.SPLITS['holdout']`). In each, from the start state and then
from each state the walk reaches, up to `--candidates` actions of the CP-SAT allocation
(deterministic: a seeded draw among the fully supported ones, then one that is not) are each
stepped from a snapshot and restored; GAMP's MotionPlanner plans the first of them from the same
state; then the walk advances with the first candidate that succeeded, stepped again after the
restores (a snapshot/restore round trip that must repeat the first verdict).

Every step records its outcome, reason, every block's pose afterwards (1e-5 m, 1e-5 of a
quaternion), the arm's joints, GAMP's grasp, hand yaw, final joints and every trajectory point of
its motion (1e-6 rad); restores record whether the world came back exactly. `--record FILE` saves
the record, `--compare FILE` checks against a saved one (exit 1, listing the differences): text
and integers (outcomes, reasons, grasps) equal, numbers within `--tol` (see `differences`);
with `--verdicts` only what each step decides (`verdicts`: outcomes, GAMP's success, reasons
without their numbers), the check the settling's early end is held to. Both
print the time per step and per GAMP call (wall and process CPU: the machine may be shared), and
`--profile N` the N entries of a cProfile run that take the most time (a second pass).
`--page [DIR]` writes DIR/planning_step.md (DIR: docs/results) with one row per scene (steps, ms a
step, MotionPlanner calls and ms a call, exact restores; with --compare, whether it matched the
record) and planning_step.rows.jsonl.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import re
import sys
import time
from pathlib import Path

import numpy as np
from common import HARD_TABLE, RESULTS, candidates, wide_scenes, write_page
from rad_core.allocation import solve
from rad_core.allocation.guide import AllocationGuide
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.shapes import SPECS, build_scene
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig
from rad_core.gamp.action import MotionPlanner, SceneAction

# (name, generator settings, seed): the generator's defaults, and harder tables (blocks packed 5 mm
# apart out to the edge of reach and a structure farther out; 4 cm units) where grasps and reach fail.
GENERATED = [('g4', dict(grid=4), 500), ('g4', dict(grid=4), 501), ('g5', dict(grid=5), 500),
             ('g5', dict(grid=5), 501), ('g5-tight', dict(grid=5, **HARD_TABLE), 502),
             ('g5-tight', dict(grid=5, **HARD_TABLE), 503), ('g5-u4', dict(grid=5, unit=0.04, gap=0.01), 504),
             ('g4-far', dict(grid=4, structure_x=0.84, reach=0.9, table_x=(0.3, 0.9)), 505)]
# (held-out shape, unit in m)
SHAPES = [('tee', 0.05), ('overhangs', 0.05), ('pillars', 0.05), ('corbel_arch', 0.05), ('window', 0.04)]


def fixed_scenes(quick: bool = False, wide: int = 0) -> list[tuple[str, object]]:
    """The benchmark's scenes, by name (quick: one generated and one hand-made). wide: instead, the
    settling benchmark's wider set (`common.wide_scenes`: six kinds of generated scene, `wide` seeds
    each from 6000, and every hand-made shape), for checks of verdicts beyond the fixed set."""
    if wide:
        return wide_scenes(wide)
    gen = GENERATED[:1] if quick else GENERATED
    shapes = SHAPES[:1] if quick else SHAPES
    out = [(f'{label}-seed{s}', generate_scene(GeneratorConfig(**kw), s)) for label, kw, s in gen]
    return out + [(f'shape-{name}-u{unit * 100:g}', build_scene(SPECS[name], 0, unit)) for name, unit in shapes]


def world_digest(world) -> dict:
    """Every block's pose (rounded) and the arm's joints, as the record keeps them."""
    poses = {}
    for bid in sorted(world.blocks):
        p, q = world.block_pose(bid)
        poses[bid] = [round(float(v), 5) for v in p] + [round(float(v), 5) for v in q]
    return {'poses': poses, 'joints': [round(float(v), 6) for v in world.joint_positions()]}


def exact_state(world) -> tuple:
    """Unrounded block poses and joints: a restore must bring them back bit for bit."""
    p, cid = world.pybullet, world.client
    bodies = tuple(p.getBasePositionAndOrientation(b, physicsClientId=cid) for b in world.blocks.values())
    return bodies, tuple(world.joint_positions().tolist())


def plan_record(plan) -> dict:
    """GAMP's answer, as the record keeps it: the verdict, the grasp, and every trajectory point."""
    if plan is None:
        return {}
    out = {'success': plan.success, 'failure': plan.failure, 'reason': plan.reason}
    if plan.success:
        out.update(grasp=str(plan.grasp), hand_yaw_deg=round(plan.hand_yaw_deg, 6),
                   final_joints=[round(float(v), 6) for v in plan.motion.final_joints()],
                   points=[[round(float(v), 6) for v in pt.positions]
                           for tr in plan.motion.trajectories for pt in tr.points],
                   gripper=[[g.action, round(g.position, 6), g.before] for g in plan.motion.gripper])
    return out


class Timer:
    """Wall and CPU seconds of one kind of call."""

    def __init__(self):
        self.n, self.wall, self.cpu = 0, 0.0, 0.0

    def __call__(self, fn, *args):
        w, c = time.perf_counter(), time.process_time()
        try:
            return fn(*args)
        finally:
            self.add(time.perf_counter() - w, time.process_time() - c)

    def add(self, wall: float, cpu: float) -> None:
        self.wall += wall
        self.cpu += cpu
        self.n += 1

    def line(self, name: str) -> str:
        n = max(self.n, 1)
        return (f'{name:<22} {self.n:5d} calls  {self.wall / n * 1e3:8.2f} ms wall  '
                f'{self.cpu / n * 1e3:8.2f} ms CPU per call  ({self.wall:.2f} s wall in all)')


def scene_action(env, action) -> SceneAction:
    """The MDP action named the way messages name it (MotionPlanner's input)."""
    scene = env.scene
    region, (cell,) = env.grid.region_cells([action.cell])
    return SceneAction(scene.blocks[action.block].id, action.unit, scene.targets[region].name, tuple(cell),
                       action.rotation)


def run_scene(name: str, scene, args, timers: dict, planner: MotionPlanner) -> list[dict]:
    """The fixed walk through one scene; one record entry per step, GAMP call and restore."""
    rows = []
    rng = np.random.default_rng(args.seed)
    renv = RobotAssemblyEnv(scene, RobotEnvConfig(execution='teleport'))
    try:
        renv.reset()
        env = renv.env
        guide = AllocationGuide(scene, solve(scene).placements)
        rows.append({'scene': name, 'kind': 'allocation',
                     'placements': [[p.type, p.target, [list(c) for c in p.cells], p.yaw] for p in guide.placements]})
        for depth in range(args.depth):
            if env.state.done:
                break
            acts = candidates(env, guide, rng, args.candidates)
            if not acts:
                break
            first = None
            for i, action in enumerate(acts):
                before = exact_state(renv.world)
                snap = timers['snapshot'](renv.snapshot)
                result = timed_step(renv, action, timers)
                rows.append(step_row(name, depth, 'step', action, result, renv))
                if first is None and not result.outcome.is_invalid:
                    first = action
                timers['restore'](renv.restore, snap)
                rows.append({'scene': name, 'depth': depth, 'kind': 'restore', 'action': list(action),
                             'exact': exact_state(renv.world) == before})
                if i == 0:
                    current = renv.current_scene()
                    gamp, _, _ = timers['MotionPlanner'](planner, current, scene_action(env, action),
                                                         renv.world.joint_positions())
                    rows.append({'scene': name, 'depth': depth, 'kind': 'motion_planner', 'action': list(action),
                                 'plan': plan_record(gamp)})
            if first is None:
                break
            result = timed_step(renv, first, timers)
            rows.append(step_row(name, depth, 'advance', first, result, renv))
    finally:
        renv.close()
    return rows


def timed_step(renv, action, timers: dict):
    """renv.step(action), timed under 'step' and, when it asked GAMP, under 'step via GAMP' too."""
    renv.last_plan = None       # set again only when the step asks GAMP
    w, c = time.perf_counter(), time.process_time()
    result = renv.step(action)
    w, c = time.perf_counter() - w, time.process_time() - c
    timers['step'].add(w, c)
    if renv.last_plan is not None:
        timers['step via GAMP'].add(w, c)
    return result


def step_row(name, depth, kind, action, result, renv) -> dict:
    return {'scene': name, 'depth': depth, 'kind': kind, 'action': list(action), 'outcome': result.outcome.value,
            'reason': result.reason, 'plan': plan_record(renv.last_plan), **world_digest(renv.world)}


def run_all(args) -> tuple[list[dict], dict, dict]:
    """The record, the timers, and per scene what each timer spent on it: {scene: {timer: (n, wall, cpu)}}."""
    timers = {k: Timer() for k in ('step', 'step via GAMP', 'snapshot', 'restore', 'MotionPlanner')}
    rows, spent = [], {}
    planner = MotionPlanner()
    try:
        for name, scene in fixed_scenes(args.quick, args.wide):
            if args.only not in name:
                continue
            before = {k: (t.n, t.wall, t.cpu) for k, t in timers.items()}
            rows += run_scene(name, scene, args, timers, planner)
            spent[name] = {k: tuple(v - w for v, w in zip((t.n, t.wall, t.cpu), before[k])) for k, t in timers.items()}
    finally:
        planner.close()
    return rows, timers, spent


def differences(old: list[dict], new: list[dict], tol: float) -> tuple[list[str], tuple[float, str]]:
    """Where two records disagree, one line each, and the largest numeric deviation seen (and where).

    Text, integers and booleans (outcomes, reasons, grasps, actions) must be equal; numbers
    (poses, joints, trajectory points) within `tol`: Bullet's contact solver orders its
    contacts by its broadphase's pair cache, whose history every probe of the planner
    touches, so the settled poses move by up to a few micrometres with the planning that
    came before (measured on the unchanged code: see docs/results/planning_step.md).
    """
    out, worst = [], [0.0, '']

    def walk(a, b, path: str) -> list[str]:
        if isinstance(a, float) or isinstance(b, float):
            if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
                if abs(a - b) > worst[0]:
                    worst[:] = [abs(a - b), path]
                return [] if abs(a - b) <= tol else [f'{path}: {a!r} -> {b!r}']
            return [f'{path}: {a!r} -> {b!r}']
        if isinstance(a, dict) and isinstance(b, dict):
            if set(a) != set(b):
                return [f'{path}: keys {sorted(a)} -> {sorted(b)}']
            return [d for k in a for d in walk(a[k], b[k], f'{path}.{k}')]
        if isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                return [f'{path}: {len(a)} items -> {len(b)}']
            return [d for i, (x, y) in enumerate(zip(a, b)) for d in walk(x, y, f'{path}[{i}]')]
        return [] if a == b else [f'{path}: {a!r} -> {b!r}']

    if len(old) != len(new):
        out.append(f'{len(old)} entries recorded, {len(new)} now')
    for i, (a, b) in enumerate(zip(old, new)):
        found = walk(a, b, '')
        if found:
            where = f"#{i} {a.get('scene')} depth {a.get('depth')} {a.get('kind')} {a.get('action')}"
            out.append(f'{where}: ' + '; '.join(found[:4]) + (f' (+{len(found) - 4} more)' if len(found) > 4 else ''))
    return out, (worst[0], worst[1])


def verdicts(rows: list[dict]) -> list[dict]:
    """What a step decides, as the issue's and the robot training's outcome checks read it: per
    entry the outcome and GAMP's success, the reasons with their numbers left out (how far a
    falling block got depends on when it is read); restores and the allocation as they are."""
    def mask(text: str) -> str:
        return re.sub(r'-?\d+(\.\d+)?', '#', text)
    out = []
    for r in rows:
        if r['kind'] in ('allocation', 'restore'):
            out.append(r)
            continue
        plan = r['plan']
        out.append({k: r[k] for k in ('scene', 'depth', 'kind', 'action')}
                   | {'outcome': r.get('outcome'), 'reason': mask(r.get('reason', '')),
                      'gamp': [plan.get('success'), plan.get('failure'), mask(plan.get('reason', ''))] if plan else []})
    return out


def summary(rows: list[dict]) -> str:
    steps = [r for r in rows if r['kind'] in ('step', 'advance')]
    kinds = {}
    for r in steps:
        key = r['outcome']
        if r['outcome'] in ('invalid_grasp', 'invalid_placement'):
            key += ' (' + r['reason'].split(':')[0] + ')'
        kinds[key] = kinds.get(key, 0) + 1
    gamp = sum(1 for r in steps if r['plan'])
    restores = [r for r in rows if r['kind'] == 'restore']
    return (f'{len(steps)} steps ({gamp} through GAMP), {len(restores)} restores '
            f'({sum(r["exact"] for r in restores)} exact); outcomes: '
            + ', '.join(f'{k} {v}' for k, v in sorted(kinds.items())))


def scene_rows(rows: list[dict], spent: dict, compared: tuple[list[dict], list[dict]] | None, tol: float) -> list[dict]:
    """One row per scene for the page: steps, their wall and CPU ms, MotionPlanner calls, exact restores,
    and with compared (the record and this run, as --compare checks them) the differences found."""
    out = []
    for name, t in spent.items():
        (n, wall, cpu), (m, m_wall, _) = t['step'], t['MotionPlanner']
        restores = [r for r in rows if r['scene'] == name and r['kind'] == 'restore']
        row = {'scene': name, 'steps': n, 'step_ms': wall / max(n, 1) * 1e3, 'step_cpu_ms': cpu / max(n, 1) * 1e3,
               'motion_planner': m, 'motion_planner_ms': m_wall / max(m, 1) * 1e3,
               'restores': len(restores), 'exact': sum(r['exact'] for r in restores)}
        if compared:
            old, new = ([r for r in side if r['scene'] == name] for side in compared)
            row['differences'] = len(differences(old, new, tol)[0])
        out.append(row)
    return out


def page_table(per_scene: list[dict], compared: bool) -> tuple[list[str], list[list]]:
    """Headers and rows of the page's table: each scene, then all of them."""
    headers = ['scene', 'steps', 'ms a step (wall)', 'ms a step (CPU)', 'MotionPlanner calls',
               'ms a MotionPlanner call', 'exact restores'] + ['the record'] * compared
    total = {k: sum(r[k] for r in per_scene) for k in ('steps', 'motion_planner', 'restores', 'exact')}
    for key, calls in (('step_ms', 'steps'), ('step_cpu_ms', 'steps'), ('motion_planner_ms', 'motion_planner')):
        total[key] = sum(r[key] * r[calls] for r in per_scene) / max(total[calls], 1)
    if compared:
        total['differences'] = sum(r['differences'] for r in per_scene)
    table = []
    for r in [*per_scene, {'scene': f'all ({len(per_scene)} scenes)', **total}]:
        table.append([r['scene'], r['steps'], f'{r["step_ms"]:.2f}', f'{r["step_cpu_ms"]:.2f}', r['motion_planner'],
                      f'{r["motion_planner_ms"]:.2f}', f'{r["exact"]} of {r["restores"]}']
                     + ([f'{r["differences"]} differences' if r['differences'] else 'the same'] if compared else []))
    return headers, table


def write_step_page(args, per_scene: list[dict]) -> Path:
    """DIR/planning_step.md and planning_step.rows.jsonl (DIR: --page's)."""
    which = (f'the wider set ({args.wide} seeds of each generated kind)' if args.wide
             else 'the quick set' if args.quick else 'the fixed set')
    only = f" whose name contains '{args.only}'" if args.only else ''
    check = ''
    if args.compare:
        what = 'verdicts only (`--verdicts`)' if args.verdicts else f'every number within {args.tol:g}'
        check = f' The record: `--compare {args.compare}`, {what}.'
    note = ('A planning-twin step is `RobotAssemblyEnv.step` with teleporting execution, between `snapshot()` and '
            '`restore()`, as the searches and the branch and bound run it; a MotionPlanner call is GAMP planning one '
            f'action from a scene state, as /plan_assembly does. Scenes: {which}{only}, {args.candidates} candidates '
            f'from each of up to {args.depth} states (seed {args.seed}); wall and process CPU time, the machine may '
            f'be shared.{check}')
    headers, table = page_table(per_scene, bool(args.compare))
    return write_page('planning_step', 'A planning-twin step: what it costs', headers, table, note, per_scene,
                      results=args.page)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group()
    g.add_argument('--record', type=Path, help='save the record of every step here')
    g.add_argument('--compare', type=Path, help='compare every step with this saved record (exit 1 on a difference)')
    p.add_argument('--candidates', type=int, default=4, help='actions tried from each state')
    p.add_argument('--depth', type=int, default=5, help='states the walk advances through per scene')
    p.add_argument('--seed', type=int, default=0, help='seed of the candidates draw')
    p.add_argument('--quick', action='store_true', help='two scenes only (a smoke run)')
    p.add_argument('--wide', type=int, default=0,
                   help='the wider set of bench_at_rest.py instead (this many seeds of each generated kind)')
    p.add_argument('--tol', type=float, default=1e-4,
                   help='--compare: numbers (m, rad) may differ by this much; text and integers must be equal')
    p.add_argument('--verdicts', action='store_true',
                   help='--compare the verdicts only: outcomes, GAMP success and reasons with their numbers '
                        'left out (what a step decides; the motions and poses may differ)')
    p.add_argument('--only', default='', help='only the scenes whose name contains this (a look at one)')
    p.add_argument('--profile', type=int, default=0, help='then a cProfile pass: print its N costliest entries')
    p.add_argument('--page', type=Path, nargs='?', const=RESULTS, metavar='DIR',
                   help='write DIR/planning_step.md and its rows (DIR: docs/results)')
    args = p.parse_args()

    t0 = time.perf_counter()
    rows, timers, spent = run_all(args)
    wall = time.perf_counter() - t0
    print(summary(rows))
    for name, timer in timers.items():
        print(timer.line(name))
    print(f'whole run {wall:.1f} s wall')
    status, compared = 0, None
    if args.record:
        args.record.parent.mkdir(parents=True, exist_ok=True)
        args.record.write_text(json.dumps({'args': {k: getattr(args, k) for k in ('candidates', 'depth', 'seed',
                                                                                   'quick', 'only', 'wide')},
                                           'rows': rows}, indent=None) + '\n')
        print(f'record of {len(rows)} entries -> {args.record}')
    if args.compare:
        saved = json.loads(args.compare.read_text())
        old, new = saved['rows'], json.loads(json.dumps(rows))
        if args.verdicts:
            old, new = verdicts(old), verdicts(new)
        compared = old, new
        diffs, worst = differences(old, new, args.tol)
        print(f'largest numeric deviation from the record: {worst[0]:.2e} at {worst[1]} (tolerance {args.tol:g})')
        if diffs:
            print(f'{len(diffs)} DIFFERENCES from {args.compare}:')
            for line in diffs[:40]:
                print('  ' + line)
            status = 1
        else:
            print(f'the same as {args.compare} ({len(rows)} entries)')
    if args.page:
        print(f'wrote {write_step_page(args, scene_rows(rows, spent, compared, args.tol))}')
    if args.profile:
        prof = cProfile.Profile()
        prof.enable()
        run_all(args)
        prof.disable()
        text = io.StringIO()
        pstats.Stats(prof, stream=text).sort_stats('tottime').print_stats(args.profile)
        print('\ncProfile, by own time:')
        print('\n'.join(text.getvalue().splitlines()[4:]))
    return status


if __name__ == '__main__':
    sys.exit(main())

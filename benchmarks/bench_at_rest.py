"""Does a planning-twin step that stops settling at rest decide as the full settling does?

    python benchmarks/bench_at_rest.py [--depth 6] [--candidates 4] [--rows out/bench_at_rest/rows.jsonl]

A teleporting step (`RobotAssemblyEnv.step`, `RobotEnvConfig(execution='teleport')`) puts the
block at its pose and lets physics settle for `settle_s` = 0.5 s before the poses are judged.
With `RobotEnvConfig.at_rest` (the default) the settling ends once every block is at rest
(`AtRest`: from 0.1 s on, two checks 25 ms apart with every block under 2 mm/s and 0.05 rad/s).

Here each action is stepped twice from the same snapshot: once with the full 0.5 s and once with
the early end (GAMP's plan is the same: its answers are remembered per world). The verdicts
must be equal: outcome, and the reason with its numbers left out (a falling block is measured
where it lies, which moves with the moment it is read). Printed: how many agree, the worst pose
difference of a block between the two (m, placed blocks and the rest apart), and the simulated
seconds settled. Scenes: generated ones from seeds the project never used elsewhere (6000 up;
g = 4, 5, 6, tight tables, 4 cm units, far structures) and every hand-made shape
(`shapes.SPECS`: training and held-out ones alike: this checks physics, not a policy).
The walk draws its candidates as `bench_planning_step` does and goes on with the first one that
succeeded under the full settling.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import candidates, wide_scenes  # noqa: E402
from rad_core.allocation import solve  # noqa: E402
from rad_core.allocation.guide import AllocationGuide  # noqa: E402
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig  # noqa: E402


def scenes(n_seeds: int) -> list[tuple[str, object]]:
    return wide_scenes(n_seeds)


def verdict(result) -> tuple[str, str]:
    return result.outcome.value, re.sub(r'-?\d+(\.\d+)?', '#', result.reason)


def poses(world) -> dict[str, np.ndarray]:
    return {b: np.concatenate(world.block_pose(b)) for b in world.blocks}


def run_scene(name: str, scene, args, totals: dict) -> list[dict]:
    rows = []
    rng = np.random.default_rng(args.seed)
    full_cfg = RobotEnvConfig(execution='teleport', at_rest=None)
    rest_cfg = RobotEnvConfig(execution='teleport')
    renv = RobotAssemblyEnv(scene, full_cfg)
    try:
        renv.reset()
        env = renv.env
        guide = AllocationGuide(scene, solve(scene).placements)
        for depth in range(args.depth):
            if env.state.done:
                break
            acts = candidates(env, guide, rng, args.candidates)
            first = None
            for action in acts:
                placed = {scene.blocks[b].id for b in env.state.placed}
                snap = renv.snapshot()
                out = {}
                for label, cfg in (('full', full_cfg), ('rest', rest_cfg)):
                    renv.config = cfg
                    sim0 = renv.twin.time
                    result = renv.step(action)
                    out[label] = (verdict(result), poses(renv.world), renv.twin.time - sim0, renv.last_plan is not None)
                    renv.restore(snap)
                renv.config = full_cfg
                (vf, pf, sf, gamp), (vr, pr, sr, _) = out['full'], out['rest']
                through = gamp and vf[0] not in ('invalid_grasp', 'invalid_placement')
                d_placed = max((float(np.abs(pf[b] - pr[b]).max()) for b in pf if b in placed), default=0.0)
                d_rest = max((float(np.abs(pf[b] - pr[b]).max()) for b in pf if b not in placed), default=0.0)
                row = {'scene': name, 'depth': depth, 'action': list(action), 'outcome': vf[0],
                       'reason': vf[1][:60], 'equal': vf == vr, 'settled': through, 'sim_s_full': round(sf, 4),
                       'sim_s_rest': round(sr, 4), 'dpose_placed': float(f'{d_placed:.3g}'),
                       'dpose_other': float(f'{d_rest:.3g}')}
                if not row['equal']:
                    row['rest'] = list(vr)
                rows.append(row)
                totals['steps'] += 1
                totals['equal'] += row['equal']
                if through:
                    totals['settled'] += 1
                    totals['sim_full'] += sf
                    totals['sim_rest'] += sr
                if not row['equal']:
                    print(f'  DIFFERENT {name} depth {depth} {list(action)}: {vf} -> {vr}', flush=True)
                if first is None and not vf[0].startswith('invalid'):
                    first = action
            if first is None:
                break
            renv.step(first)
    finally:
        renv.close()
    return rows


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--seeds', type=int, default=3, help='generated scenes per kind (seeds 6000 up)')
    p.add_argument('--candidates', type=int, default=4, help='actions tried from each state')
    p.add_argument('--depth', type=int, default=6, help='states the walk advances through per scene')
    p.add_argument('--seed', type=int, default=0, help='seed of the candidates draw')
    p.add_argument('--rows', type=Path, default=None, help='write one compact JSON row per step here')
    args = p.parse_args()

    totals = dict(steps=0, equal=0, settled=0, sim_full=0.0, sim_rest=0.0)
    rows = []
    t0 = time.perf_counter()
    for name, scene in scenes(args.seeds):
        rows += run_scene(name, scene, args, totals)
    wall = time.perf_counter() - t0
    n = max(1, totals['settled'])
    settled = [r for r in rows if r['settled']]
    print(f'{len({r["scene"] for r in rows})} scenes, {totals["steps"]} actions stepped twice, '
          f'{totals["settled"]} of them settled (through GAMP), in {wall:.0f} s')
    print(f'verdicts equal: {totals["equal"]} of {totals["steps"]}')
    print(f'simulated seconds settled per step that reached physics: {totals["sim_full"] / n:.3f} full, '
          f'{totals["sim_rest"] / n:.3f} at rest ({totals["sim_full"] / max(totals["sim_rest"], 1e-9):.2f}x fewer '
          f'physics steps)')
    if settled:
        ok = [r for r in settled if not r['outcome'].startswith('invalid')]

        def most(rs, key):
            return max((r[key] for r in rs), default=0.0)
        print('worst pose difference of a block, full against at rest (m or quaternion component): '
              f"placed {most(settled, 'dpose_placed'):.2e}, others {most(settled, 'dpose_other'):.2e}; "
              f"after the {len(ok)} successful steps: placed {most(ok, 'dpose_placed'):.2e}, "
              f"others {most(ok, 'dpose_other'):.2e}")
    if args.rows:
        args.rows.parent.mkdir(parents=True, exist_ok=True)
        args.rows.write_text(''.join(json.dumps(r, separators=(',', ':')) + '\n' for r in rows))
        print(f'{len(rows)} rows -> {args.rows}')
    return 0 if totals['equal'] == totals['steps'] else 1


if __name__ == '__main__':
    sys.exit(main())

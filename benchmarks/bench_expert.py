"""Expert iteration's training settings on collected demonstrations (a benchmark, not a test).

    rad expert --out runs/expert-s1 --rounds 2 --scenes 100           # collects rR's demonstrations
    python benchmarks/bench_expert.py --run runs/expert-s1 --round 0 --steps 400 \\
        --settings 1e-4,0.1,1,0 3e-5,0.02,1,0 3e-5,0.02,0,10 3e-5,0.02,1,10

Each setting (lr, margin, td_weight, anchor_weight) trains the shipped mixed network (`--init`) on
the run's training demonstrations of `--round` (every round up to it) with `expert.dqfd_loss`, as
a round 0 of `rad expert` with those fields does (`ExpertIteration.train`, the run's other fields at
their defaults, `--seed` its seed), and prints every 100 steps how often the network's own choice is
the expert's: on the training demonstrations and on the held-out scenes' ones. `--save DIR` keeps
each setting's network after the last step (for `rad eval --checkpoint`). One torch thread (the
config's default); seconds in the table are wall-clock on whatever else runs.
"""

from __future__ import annotations

import argparse
import glob
import pickle
import tempfile
import time
from pathlib import Path

from rad_core.learning import checkpoint as ckpt
from rad_core.training.expert import ExpertConfig, ExpertIteration, agreement


def demos(run: Path, last_round: int) -> tuple[list, list]:
    train, held = [], []
    for r in range(last_round + 1):
        for path in sorted(glob.glob(str(run / 'demos' / f'r{r}' / '*.pkl'))):
            with open(path, 'rb') as f:      # files `rad expert` wrote
                result = pickle.load(f)
            (held if result['held_out'] else train).extend(result['demos'])
    return train, held


def one(setting: str, init: str, train: list, held: list, steps: int, seed: int, save: Path | None) -> list[dict]:
    """One setting trained exactly as a round 0 of `rad expert` with these fields would train it;
    the agreements every 100 steps."""
    lr, margin, td_weight, anchor_weight = (float(v) for v in setting.split(','))
    cfg = ExpertConfig(init=init, lr=lr, margin=margin, td_weight=td_weight, anchor_weight=anchor_weight,
                       steps=steps, seed=seed)
    with tempfile.TemporaryDirectory() as out:
        expert = ExpertIteration(cfg, out)
        q = expert.q

        def measure(step: int) -> None:
            if step % 100 and step != steps:
                return
            rows.append({'step': step, 'train': agreement(q, train, 'cpu'), 'held': agreement(q, held, 'cpu'),
                         's': time.perf_counter() - t0})
            print(f'  {setting} step {step}: agreement {rows[-1]["train"]:.3f} / held out {rows[-1]["held"]:.3f}',
                  flush=True)
        rows = [{'step': 0, 'train': agreement(q, train, 'cpu'), 'held': agreement(q, held, 'cpu'), 's': 0.0}]
        t0 = time.perf_counter()
        expert.train(train, held, 0, lambda _: None, after_step=measure)
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
        ckpt.atomic_save({**expert.init_doc, 'weights': q.state_dict()}, save / f'{setting.replace(",", "_")}.pt')
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--run', required=True, type=Path, help='a `rad expert` run folder')
    ap.add_argument('--round', type=int, default=0, help='use the demonstrations of rounds 0..R')
    ap.add_argument('--init', default='milp-dqn-mixed')
    ap.add_argument('--steps', type=int, default=400)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--settings', nargs='+', default=['1e-4,0.1,1,0', '3e-5,0.02,1,0', '3e-5,0.02,0,10',
                                                      '3e-5,0.02,1,10'], help='lr,margin,td_weight,anchor_weight')
    ap.add_argument('--save', type=Path, help="keep each setting's network here")
    args = ap.parse_args()
    train, held = demos(args.run, args.round)
    print(f'{len(train)} training and {len(held)} held-out demonstrations from {args.run} rounds 0..{args.round}')
    table = []
    for setting in args.settings:
        rows = one(setting, args.init, train, held, args.steps, args.seed, args.save)
        table.append((setting, rows))
    print('\n| lr, margin, TD weight, anchor weight | agreement before (train / held out) | lowest held out '
          '| after (train / held out) |')
    print('|---|---|---|---|')
    for setting, rows in table:
        low = min(rows, key=lambda r: r['held'])
        print(f'| {setting} | {rows[0]["train"]:.3f} / {rows[0]["held"]:.3f} | {low["held"]:.3f} (step {low["step"]}) '
              f'| {rows[-1]["train"]:.3f} / {rows[-1]["held"]:.3f} |')


if __name__ == '__main__':
    main()

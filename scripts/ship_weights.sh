#!/usr/bin/env bash
# Copy the trained model files that ship with rad into the package (small files:
# weights and config only, no replay). Which run ships under each name is written
# in docs/results/table1.md; by default the MILP-DQN seed with the best greedy validation
# return ships as milp-dqn.
#   bash scripts/ship_weights.sh [milp-dqn-run]
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source scripts/env.sh
W=ros_ws/src/rad_core/rad_core/learning/weights
mkdir -p "$W"
best=${1:-$(python - <<'PY'
import torch, glob
runs = sorted(glob.glob('runs/milp-dqn-s[0-9]*/model.pt'))
best = max(runs, key=lambda p: torch.load(p, weights_only=True)['train']['best_eval_return'])
print(best.split('/')[1])
PY
)}
cp "runs/$best/model.pt" "$W/milp-dqn.pt"
cp runs/dqn-s0/model.pt "$W/dqn.pt"
cp runs/dqn-rel-s0/model.pt "$W/dqn-rel.pt"
cp runs/milp-dqn-mixed-s0/model.pt "$W/milp-dqn-mixed.pt"
echo "shipped: milp-dqn <- $best, dqn <- dqn-s0, dqn-rel <- dqn-rel-s0, milp-dqn-mixed <- milp-dqn-mixed-s0"
ls -la "$W"
# The runs' learning curves travel with the weights (bench_table1.py plots them).
mkdir -p data/training
for r in runs/*/; do
    name=$(basename "$r")
    [ -f "$r/curves.png" ] && [ "$name" != smoke ] && cp "$r/progress.csv" "data/training/$name.csv"
done
echo "copied progress.csv of the finished runs to data/training/"

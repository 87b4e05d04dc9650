#!/usr/bin/env bash
# Train the shipped sequencing agents (docs/results/table1.md, the paper's Table I condition:
# train at g = 3, evaluate at g = 3..6 on unseen seeds). Resumable: run it again and
# every run continues from its last checkpoint; finished runs are skipped.
#   bash scripts/train_agents.sh            # all runs, two at a time (one per core)
#   bash scripts/train_agents.sh milp-dqn-s0 dqn-s0   # only these runs
# Logs: runs/<name>/{progress.csv,tb/,train.log,curves.png}; weights: runs/<name>/model.pt.
# scripts/ship_weights.sh copies the chosen model files into the package.
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
source scripts/env.sh

DATA=data/train-g3.jsonl.gz
[ -f "$DATA" ] || rad dataset build --grids 3 --scenes 50000 -o "$DATA"
# The default agent's data: g = 3, 4, 5 and the training split of the hand-made shapes,
# with the stability-aware allocation.
MIXED=data/train-mixed-stable.jsonl.gz
[ -f "$MIXED" ] || rad dataset build --grids 3,4,5 --scenes 10000 --shapes train --shape-seeds 20 \
    --support stable -o "$MIXED"

declare -A ARGS=(
    [milp-dqn-s0]="--method milp-dqn --seed 0 --total-steps 30000"
    [milp-dqn-s1]="--method milp-dqn --seed 1 --total-steps 30000"
    [milp-dqn-s2]="--method milp-dqn --seed 2 --total-steps 30000"
    [milp-dqn-double-s0]="--method milp-dqn --seed 0 --total-steps 30000 --double true"
    [dqn-s0]="--method dqn --seed 0 --total-steps 20000"
    [dqn-rel-s0]="--method dqn-rel --seed 0 --total-steps 20000"
    [milp-dqn-mixed-s0]="--method milp-dqn --seed 0 --total-steps 30000 --eval-grid 4 --dataset $MIXED"
)
ORDER=(milp-dqn-s0 milp-dqn-s1 milp-dqn-s2 dqn-s0 dqn-rel-s0 milp-dqn-double-s0 milp-dqn-mixed-s0)
[ $# -gt 0 ] && ORDER=("$@")

one() {  # one NAME: start or resume it; skip it when finished
    local name=$1 out=runs/$1
    mkdir -p "$out"
    if [ -f "$out/curves.png" ] && [ -f "$out/model.pt" ]; then
        echo "$name: finished"; return 0
    fi
    if [ -f "$out/checkpoint.pt" ]; then
        rad train --out "$out" --resume >>"$out/train.log" 2>&1
    else
        # A later --dataset in ARGS wins over this default.
        rad train --out "$out" --dataset "$DATA" ${ARGS[$name]} >>"$out/train.log" 2>&1
    fi
    echo "$name: $(tail -n 1 "$out/train.log")"
}

# Two at a time: each run uses one torch thread, so each gets a core.
for ((i = 0; i < ${#ORDER[@]}; i += 2)); do
    one "${ORDER[$i]}" &
    [ -n "${ORDER[$((i + 1))]:-}" ] && one "${ORDER[$((i + 1))]}" &
    wait
done

#!/usr/bin/env bash
# Fine-tune the no-robot MILP-DQN with the robot in the loop (the paper's Table II
# agent): GAMP plans every grasp and placement, teleport execution, physics judges;
# f_g, f_p, a disturbance or instability ends the episode with -1. Starts from the
# shipped milp-dqn-mixed (stable allocation, g = 3..5 + shapes) on its own training
# data; validation with the robot at g = 4. Resumable: run it again and it continues
# from runs/<name>/checkpoint.pt (atomic, every 2 minutes and on SIGINT).
#   nohup bash scripts/train_robot.sh >/dev/null 2>&1 &     # the shipped run
#   bash scripts/train_robot.sh milp-dqn-robot-scratch      # the from-scratch comparison
# Logs: runs/<name>/{train.log,progress.csv,tb/,curves.png}; model: runs/<name>/model.pt
# (shipped as rad_core/learning/weights/milp-dqn-robot.pt). One training at a time.
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source scripts/env.sh

DATA=data/train-mixed-stable.jsonl.gz
COMMON="--robot --method milp-dqn --dataset $DATA --eval-grid 4 --eval-scenes 30 --buffer-size 30000 \
--learning-starts 1000 --target-update 1000 --checkpoint-every-s 120"
declare -A ARGS=(
    # From the no-robot network: little exploration (it already builds), a smaller step size,
    # one gradient step per 2 robot steps (robot steps are dear, gradient steps cheap).
    [milp-dqn-robot]="$COMMON --init milp-dqn-mixed --seed 0 --total-steps 20000 --eval-every 2000 \
--eps-start 0.2 --eps-end 0.05 --eps-fraction 0.3 --lr 1e-4 --train-every 2 --learning-starts 500"
    # From scratch (lr 3e-4, epsilon 1 -> 0.05 as the no-robot recipe; the same replay ratio), for the
    # comparison at equal steps.
    [milp-dqn-robot-scratch]="$COMMON --seed 0 --total-steps 2000 --eval-every 1000 --train-every 2 --learning-starts 500"
)
name=${1:-milp-dqn-robot}
out=runs/$name
mkdir -p "$out"
if [ -f "$out/curves.png" ] && [ -f "$out/model.pt" ]; then
    echo "$name: finished"; exit 0
fi
if [ -f "$out/checkpoint.pt" ]; then
    echo "$(date -Is) resume: rad train --out $out --resume" >>"$out/train.log"
    rad train --out "$out" --resume >>"$out/train.log" 2>&1
else
    echo "$(date -Is) rad train --out $out ${ARGS[$name]}" >>"$out/train.log"
    # shellcheck disable=SC2086
    rad train --out "$out" ${ARGS[$name]} >>"$out/train.log" 2>&1
fi
echo "$name: $(tail -n 1 "$out/train.log")"

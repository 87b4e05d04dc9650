#!/usr/bin/env bash
# Does this machine run two busy processes at twice the speed of one? No Dask involved: the same
# two plain `rad eval` runs (20 g = 4 scenes each, greedy agent, robot in the loop, serial), first
# one after the other, then side by side; REPS times. Prints each process's wall and CPU seconds,
# the speed-up of the pair over the two solo runs, and the steal ticks /proc/stat counted meanwhile.
#   bash benchmarks/bench_process_pair.sh [REPS]        (docs/results/distributed.md)
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../scripts/env.sh"
REPS=${1:-3}
steal() { awk '/^cpu /{print $9}' /proc/stat; }
now() { date +%s.%N; }
one() { /usr/bin/time -f "  seed $1: %e s wall, %U+%S s CPU" rad eval --agent greedy --robot --grid 4 --sides 2 \
        --scenes 20 --seed "$1" 2>&1 | grep 'wall,'; }
for rep in $(seq "$REPS"); do
    s0=$(steal); t0=$(now); one 0; one 20; t1=$(now); s1=$(steal)
    solo=$(python3 -c "print(round($t1 - $t0, 2))")
    echo "rep $rep solo, one after the other: $solo s (steal $((s1 - s0)) ticks)"
    s0=$(steal); t0=$(now); one 0 & one 20 & wait; t1=$(now); s1=$(steal)
    pair=$(python3 -c "print(round($t1 - $t0, 2))")
    echo "rep $rep side by side: $pair s (steal $((s1 - s0)) ticks); speed-up $(python3 -c "print(round($solo / $pair, 2))")x"
done

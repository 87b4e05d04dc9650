#!/usr/bin/env bash
# `make test`: set up (idempotent), then run the whole test suite with the
# loopback-only DDS settings of scripts/env.sh. Extra arguments go to pytest.
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh
source scripts/env.sh
export RAD_TEST_HARNESS=1  # lets tests tell they run under this script

start=$SECONDS
status=0
# Every test gets a time limit, so a hung node fails its test instead of the run.
python -m pytest tests --timeout="${RAD_TEST_TIMEOUT:-300}" --durations=30 "$@" || status=$?
elapsed=$((SECONDS - start))

case $status in
    0) echo "test.sh: passed${*:+ (pytest $*)} (${elapsed} s)" ;;
    5) echo "test.sh: FAILED: pytest collected no tests" >&2; exit 1 ;;
    *) echo "test.sh: FAILED: pytest exit code $status (${elapsed} s)" >&2 ;;
esac
exit "$status"

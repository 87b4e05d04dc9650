#!/usr/bin/env bash
# `make test-fast`: set up (idempotent), then run the fast tier: the pure-core and
# message tests, without the `slow` ones (training, Dask clusters, simulated execution)
# and without the `dds` ones (nodes, DDS, end to end). `make test` runs every tier.
# Extra arguments go to pytest.
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh
source scripts/env.sh
export RAD_TEST_HARNESS=1  # lets tests tell they run under a test script

start=$SECONDS
status=0
python -m pytest tests -m "not slow and not dds" --timeout="${RAD_TEST_TIMEOUT:-300}" --durations=15 "$@" \
    || status=$?
elapsed=$((SECONDS - start))

case $status in
    0) echo "test_fast.sh: the fast tier passed (${elapsed} s)" ;;
    5) echo "test_fast.sh: FAILED: pytest collected no tests" >&2; exit 1 ;;
    *) echo "test_fast.sh: FAILED: pytest exit code $status (${elapsed} s)" >&2 ;;
esac
exit "$status"

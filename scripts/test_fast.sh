#!/usr/bin/env bash
# `make test-fast`: set up (idempotent), then run the fast tier: the pure-core and
# message tests, without the `slow` ones (training, Dask clusters, simulated execution)
# and without the `dds` ones (nodes, DDS, end to end). `make test` runs every tier.
# Extra arguments go to pytest. It is scripts/test.sh with a marker filter.
exec bash "$(dirname "${BASH_SOURCE[0]}")/test.sh" -m "not slow and not dds" --durations=15 "$@"

#!/usr/bin/env bash
# `make demo`: set up (idempotent), then run the end-to-end demo with the
# loopback-only DDS settings of scripts/env.sh. Output goes to out/demo/.
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh
source scripts/env.sh
rad demo --out out/demo "$@"

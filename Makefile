# Entry points of rad. Each target is a script in scripts/, usable without make.
.PHONY: help setup test test-fast demo

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-10s %s\n", $$1, $$2}'

setup:  ## create .venv, install requirements/, build ros_ws (idempotent)
	@bash scripts/setup.sh

test:  ## set up, then run every test (all tiers) with the loopback-only DDS settings
	@bash scripts/test.sh

test-fast:  ## set up, then run the fast tier: pure-core and message tests, no slow or DDS ones
	@bash scripts/test_fast.sh

demo:  ## set up, then run `rad demo --out out/demo`
	@bash scripts/demo.sh

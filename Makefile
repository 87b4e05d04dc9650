# Entry points of rad. Each target is a script in scripts/, usable without make.
.PHONY: help setup test demo

help:  ## list the targets
	@grep -E '^[a-z]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-6s %s\n", $$1, $$2}'

setup:  ## create .venv, install requirements/, build ros_ws (idempotent)
	@bash scripts/setup.sh

test:  ## set up, then run every test with the loopback-only DDS settings
	@bash scripts/test.sh

demo:  ## set up, then run `rad demo --out out/demo`
	@bash scripts/demo.sh

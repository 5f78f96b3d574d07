# Tests, benchmarks and the demo run in their own network namespace (scripts/isolated.sh): only loopback.
# Every target bootstraps .venv on first use (scripts/bootstrap.sh; idempotent, quick when nothing changed).
VENV := .venv
PY := $(VENV)/bin/python
BOOT := bash scripts/bootstrap.sh
export AMENT_PREFIX_PATH := $(abspath $(VENV))

.PHONY: setup vm-setup test bench demo lint clean

setup:
	@$(BOOT)

# SocketCAN VM tools for tests/vcan (qemu, Debian kernel, busybox-static, virtme-ng); idempotent, TMS_VM=0 skips
vm-setup: setup
	@bash scripts/vm/setup.sh

test: setup vm-setup
	scripts/isolated.sh $(PY) -m pytest tests $(PYTEST_ARGS)

bench: setup
	scripts/isolated.sh $(PY) -m tests.bench $(BENCH_ARGS)

# SCENARIO=paper (default), fleet, design or embankment picks the seed and launch file (scripts/demo.sh); DEMO_LAUNCH replaces the launch file
DEMO_LAUNCH ?=
demo: setup
	SCENARIO=$(or $(SCENARIO),paper) scripts/isolated.sh scripts/demo.sh $(DEMO_LAUNCH) $(DEMO_ARGS)

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check . || true

clean:
	rm -rf build .pytest_cache

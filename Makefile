# Two commands on a fresh machine with Python 3.11 and make:  make demo  |  make test
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-system compose-test compose-image lint setup wire-doc clean

# The project and its tools into .venv: by uv (the same packages from the same index in about a
# fifth of pip's time, docs/benchmarks.md), by pip where uv cannot be had or fails.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	( $(BIN)/python -m pip install --quiet 'uv==0.13.9' && \
	  $(BIN)/uv pip install --quiet --python $(BIN)/python -e '.[dev]' ) || \
	  $(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

# The marker detector's loop built ahead of time (common/markers_aot.py; with no C++ compiler
# it says so and the detector uses numba's JIT), again whenever the loop changes.
KERNEL := $(VENV)/.kernel
$(KERNEL): $(STAMP) common/markers_kernel.py common/markers_aot.py
	$(BIN)/python -m common.markers_aot
	touch $(KERNEL)

setup: $(KERNEL)

## The whole local lab (router + every service that exists) with a live view; Ctrl-C stops it.
demo: $(KERNEL)
	$(BIN)/stb up --lab $(or $(LAB),config/demo.toml)

## Lint and type-check, then the test suite but for the long whole-lab runs, on two workers
## (pytest-xdist; about 4 minutes on 2 cores).
test: $(STAMP)
	$(BIN)/ruff check common services tests benchmarks compose_test
	# the type check beside the detector's loop being built: each takes one core for ~20 s
	$(BIN)/mypy & typecheck=$$!; $(MAKE) --no-print-directory $(KERNEL); built=$$?; \
	  wait $$typecheck && test $$built = 0
	$(BIN)/python -m pytest -q -m "not system" -n 2

## The long whole-lab runs on real time (fault campaign, demo calibration, live vs experiment,
## commissioning, collection and recording end to end, the lens at several zooms, the page in a
## browser against the whole lab, several hosts):
## 11–15 minutes (11.7 in the last clean-clone run) on 2 cores (docs/benchmarks.md, "Where CI's time goes"). CI runs both.
test-system: $(KERNEL)
	$(BIN)/python -m pytest -q -m system -n 2 --dist loadgroup --durations=25

## The lab under a real Docker engine (root; installs Debian's docker.io when missing):
## build, docker compose up with the sim, crash, router restart, down/up (docs/deployment.md §7).
# the compose test's engine and image made ahead (.ci/run: beside make test)
compose-image: $(STAMP)
	$(BIN)/python -m compose_test.prepare

compose-test: $(KERNEL)
	$(BIN)/python -m pytest -q -p no:cacheprovider compose_test --timeout 2400 --durations=15

wire-doc: $(STAMP)
	$(BIN)/python -m common.wiredoc > docs/wire-format.md

clean:
	rm -rf $(VENV) run .pytest_cache .ruff_cache .mypy_cache

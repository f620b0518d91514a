# Two commands on a fresh machine with Python 3.11 and make:  make demo  |  make test
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test compose-test lint setup wire-doc clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

setup: $(STAMP)

## The whole local lab (router + every service that exists) with a live view; Ctrl-C stops it.
demo: $(STAMP)
	$(BIN)/stb up --lab $(or $(LAB),config/demo.toml)

## Lint, then the full test suite.
test: $(STAMP)
	$(BIN)/ruff check common services tests benchmarks compose_test
	$(BIN)/python -m pytest -q

## The lab under a real Docker engine (root; installs Debian's docker.io when missing):
## build, docker compose up with the sim, crash, router restart, down/up (docs/deployment.md §7).
compose-test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider compose_test --timeout 2400

wire-doc: $(STAMP)
	$(BIN)/python -m common.wiredoc > docs/wire-format.md

clean:
	rm -rf $(VENV) run .pytest_cache .ruff_cache

# slipkit: `make help` lists the targets. Every target creates .venv itself.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The CPU wheel of torch is installed first so that no CUDA build is ever pulled.
TORCH  := torch==2.13.0

.DEFAULT_GOAL := help
.PHONY: help install demo test test-full lint bench clean

help: ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*## "} {printf "  %-10s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e '.[train,dev]'
	touch $(STAMP)

install: $(STAMP) ## create .venv and install slipkit with its dev tools

demo: $(STAMP) ## run the main job on the built-in default data
	$(BIN)/slipkit demo

test: $(STAMP) ## run the default test suite (no slow tests)
	$(BIN)/python -m pytest -m "not slow" -q

test-full: $(STAMP) ## run every test, slow ones included
	$(BIN)/python -m pytest -q

lint: $(STAMP) ## ruff and mypy on src/
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks
	$(BIN)/mypy

bench: $(STAMP) ## run the benchmarks in benchmarks/
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean: ## remove the virtual environment, caches and demo output
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis outputs multirun runs data/demo

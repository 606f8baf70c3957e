# slipkit: `make help` lists the targets. Every target creates .venv itself.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The CPU wheel of torch is installed first so that no CUDA build is ever pulled.
TORCH  := torch==2.13.0

.DEFAULT_GOAL := help
.PHONY: help install demo test test-full lint docs bench bench-report wheel wheelhouse clean

help: ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*## "} {printf "  %-10s %s\n", $$1, $$2}'

# One line per step, and pip's own progress (no --quiet): the first install takes minutes.
$(STAMP): pyproject.toml
	@echo "[install 1/4] virtual environment $(VENV)"
	$(PYTHON) -m venv $(VENV)
	@echo "[install 2/4] pip upgrade"
	$(BIN)/python -m pip install --quiet --upgrade pip
	@echo "[install 3/4] $(TORCH)"
	$(BIN)/python -m pip install --progress-bar on $(TORCH)
	@echo "[install 4/4] slipkit[train,dev] (editable)"
	$(BIN)/python -m pip install --progress-bar on -e '.[train,dev]'
	touch $(STAMP)
	@echo "[install] done: $(VENV)"

install: $(STAMP) ## create .venv and install slipkit with its dev tools

demo: $(STAMP) ## run the main job on the built-in default data
	$(BIN)/slipkit demo

test: $(STAMP) ## run the default test suite (no slow tests)
	$(BIN)/python -m pytest -m "not slow" -q

test-full: $(STAMP) ## run every test, slow ones included
	$(BIN)/python -m pytest -q

lint: $(STAMP) ## ruff, mypy and the import layers (lint-imports) on src/
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks
	$(BIN)/mypy
	$(BIN)/lint-imports --no-cache

docs: $(STAMP) ## build the docs site (user guide + API reference) into site/
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict -d site

bench: $(STAMP) ## run the benchmarks in benchmarks/
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

bench-report: $(STAMP) ## run the benchmarks' short settings and rewrite docs/benchmarks.md
	$(BIN)/python benchmarks/report.py

wheel: $(STAMP) ## build dist/slipkit-<version>-py3-none-any.whl (pure Python)
	$(BIN)/python -m pip wheel --quiet --no-deps --no-build-isolation -w dist .

# The runtime's dependencies at the versions installed (and tested) here, as wheels for an
# offline install on a gripper PC (docs/deploy.md). For another Python or platform on the
# PC, e.g. WHEELHOUSE_ARGS="--python-version 3.10 --platform manylinux2014_x86_64".
WHEELHOUSE_ARGS ?=
wheelhouse: wheel ## wheel + numpy and onnxruntime wheels in wheelhouse/ for an offline install
	mkdir -p wheelhouse
	cp dist/slipkit-*-py3-none-any.whl wheelhouse/
	$(BIN)/python -m pip download --quiet --only-binary=:all: -d wheelhouse $(WHEELHOUSE_ARGS) \
	  $$($(BIN)/python -c 'import numpy, onnxruntime; print(f"numpy=={numpy.__version__} onnxruntime=={onnxruntime.__version__}")')

clean: ## remove the virtual environment, caches and demo output
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis outputs multirun runs data/demo dist wheelhouse site

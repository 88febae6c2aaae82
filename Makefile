# Two entry points for a fresh machine: `make demo` (the main job) and `make test`.
# Both create .venv, install the pinned dependencies (torch 2.13.0 CPU build) and the package.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1
export MPLBACKEND ?= Agg

.PHONY: venv demo test lint bench clean

$(BIN)/activate: requirements.lock pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r requirements.lock
	$(BIN)/python -m pip install -q --no-deps -e .
	touch $(BIN)/activate

venv: $(BIN)/activate

demo: venv
	$(BIN)/parknss demo --out runs/demo --overwrite

test: venv
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -n auto --maxprocesses 4

bench: venv
	set -e; for f in benchmarks/bench_*.py; do echo "== $$f"; $(BIN)/python $$f; done

clean:
	rm -rf $(VENV) runs .pytest_cache .ruff_cache

# Two commands (see README):  make table1   and   make test
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup test table1 compare bench clean

# torch==2.13.0 first: the CPU wheel kept on these machines. An unpinned torch would pull a CUDA build.
setup: $(VENV)/.installed
$(VENV)/.installed: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[test,slurm]'
	touch $@

test: setup
	$(BIN)/python -m pytest

# '-': a failed job must not cost the table; the report lists it as failed
table1: setup
	-$(BIN)/python train.py experiment=table1
	$(BIN)/python -m selpres.report outputs/sweeps/table1

compare: setup
	-$(BIN)/python train.py experiment=compare
	$(BIN)/python -m selpres.report outputs/sweeps/compare

bench: setup
	$(BIN)/python scripts/bench_engine.py

clean:
	rm -rf $(VENV) outputs/runs outputs/sweeps

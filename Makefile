# The two commands (see README):  make table1   and   make test
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup test test-fast test-fallback lint format table1 readme compare bench clean

# torch==2.13.0 first: the CPU wheel kept on these machines. An unpinned torch would pull a CUDA build, and
# Lightning asks for torch: constraints.txt holds the pin while the rest installs. Two distributions, both editable:
# the library (.) and, beside it, the studies and benchmarks (studies/: selpres-studies, selpres-bench).
setup: $(VENV)/.installed
$(VENV)/.installed: pyproject.toml setup.py studies/pyproject.toml constraints.txt
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -c constraints.txt -e '.[test,slurm,search,lightning,robots]' -e ./studies
	touch $@

# the suite on PYTEST_WORKERS processes (pytest-xdist; 0: in this process), a test file per worker at a time, so a
# file's module-scoped fixtures (a wheel build, a trained run) are built once: `make test PYTEST_WORKERS=0` is serial
PYTEST_WORKERS ?= 2
XDIST := -n $(PYTEST_WORKERS) --dist loadfile

test: setup            ## the whole suite (what CI runs, with lint and the fallback tier)
	$(BIN)/python -m pytest $(XDIST)

test-fast: setup       ## the edit loop: no subprocesses, sweeps or exhaustive grids (2-3 minutes here)
	$(BIN)/python -m pytest $(XDIST) -m "not slow"

test-fallback: setup   ## the fast tier with the native kernel disabled: the pure-torch path stays green
	SELPRES_NO_NATIVE=1 $(BIN)/python -m pytest $(XDIST) -m "not slow"

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: setup
	$(BIN)/ruff check --fix .
	$(BIN)/ruff format .

# '-': a failed job must not cost the table; the report lists it as failed
table1: setup
	-$(BIN)/python train.py experiment=table1
	$(BIN)/selpres-report outputs/sweeps/table1

# the README's Table 1 section, regenerated from a fresh Table 1 run (nothing in it is pasted by hand)
readme: table1
	$(BIN)/selpres-report outputs/sweeps/table1 --readme README.md > /dev/null

compare: setup
	-$(BIN)/python train.py experiment=compare
	$(BIN)/selpres-report outputs/sweeps/compare

bench: setup
	$(BIN)/selpres-bench

clean:
	rm -rf $(VENV) outputs/runs outputs/sweeps

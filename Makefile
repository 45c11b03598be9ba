# The two entry points of the README.  Both create .venv when it is missing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint unit vcan suite reference perf docs docs-site rtcheck reliability faults clean

# pip builds the plant's core and the controller's core with their bindings (setup.py);
# tools/need-cc installs their compiler and headers first when it may. Both cores are
# required (the controller has one engine, its core; the Python step is the tests' oracle).
$(STAMP): pyproject.toml setup.py plant_rt/_cplant.c $(wildcard plant_rt/core/*.[ch]) controller/_cctl.c $(wildcard controller/core/*.[ch])
	test -x $(BIN)/pip || tools/make-venv $(PYTHON) $(VENV)
	tools/need-cc $(BIN)/python
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev,dask,docs,mf4,parquet]'
	$(BIN)/python -c 'import plant_rt'
	$(BIN)/python -c 'import controller'
	# the bytecode of every module, once: each bench process (a run starts three) would
	# else compile its modules again where PYTHONDONTWRITEBYTECODE is set (about 0.3 s each)
	$(BIN)/python -m compileall -q bench controller plant_rt dbc
	touch $(STAMP)

# The bench's main job: a paper scenario between two processes over CAN.
demo: $(STAMP)
	$(BIN)/bench run wen-5.1 --estimator tt-dq --out runs/demo

# The whole test suite: lint, format, types, then the unit and process tests and
# the SocketCAN tests on vcan (natively, or inside User-Mode Linux) side by side
# (tools/test-stages; `make unit` and `make vcan` run each alone).
test: lint
	MAKE="$(MAKE)" tools/test-stages

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

unit: $(STAMP)
	tools/need-tmux
	$(BIN)/pytest -m "not socketcan"

vcan: $(STAMP)
	tools/vcan-tests

# The paper suite into a new folder (SUITE_OUT); `make reference` replaces the
# committed reference (docs/results and the README's claims table).
SUITE_OUT ?= runs/suite-$(shell date -u +%Y%m%dT%H%M%SZ)
suite: $(STAMP)
	$(BIN)/bench suite paper --out $(SUITE_OUT)

# The committed reference (docs/results, the README's claims table): in-process,
# which gives the two-process runs' traces (tests/test_bench_loop.py), on all three plants.
# A change that moves only a few runs regenerates just those (minutes, not an hour):
#   bench suite paper --inprocess --out docs/results --update --scenarios S1,S2 \
#       --estimators E --plants P   (keeps every other record and run folder)
#   bench suite report docs/results --readme README.md
reference: $(STAMP)
	$(BIN)/bench suite paper --inprocess --out docs/results --overwrite
	$(BIN)/bench suite report docs/results --readme README.md

# Benchmarks: docs/perf/perf.json, and docs/BENCHMARKS.md, the README's perf
# block and docs/REALTIME.md's native block rendered from it (a few minutes).
perf: $(STAMP)
	$(BIN)/bench perf --out docs/perf --doc docs/BENCHMARKS.md --readme README.md --realtime-doc docs/REALTIME.md

# The scenario reference, from the schema (tests/test_scenarios_doc.py checks it).
docs: $(STAMP)
	$(BIN)/bench schema --doc docs/SCENARIOS.md

# The reference site: the guides (docs/*.md) and the API reference from the
# docstrings (docs/conf.py), warnings as errors, into docs/_build/html.
docs-site: $(STAMP)
	$(BIN)/sphinx-build -W --keep-going -q -b html docs docs/_build/html

rtcheck: $(STAMP)
	$(BIN)/bench rtcheck --out docs/realtime --doc docs/REALTIME.md

# Reliability: fuzzing, injected faults, kills, signals, load and parallel runs;
# docs/reliability/soak.json and docs/RELIABILITY.md rendered from it (a few minutes).
reliability: $(STAMP)
	mkdir -p docs/reliability
	$(BIN)/bench soak --processes --out docs/reliability/soak.json --doc docs/RELIABILITY.md

# Fault study: every fault kind for every shipped estimator on the drive plant in-process
# (about 30 min on 2 cores), and the bus kinds with the controller as a process: Python node,
# native node, external controller (about 10 min more); docs/faults/faults.json,
# docs/FAULTS.md and the README's block.
faults: $(STAMP)
	$(BIN)/bench suite faults --out docs/faults --doc docs/FAULTS.md --readme README.md

clean:
	rm -rf $(VENV) runs .pytest_cache .mypy_cache .ruff_cache

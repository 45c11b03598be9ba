# The two entry points of the README.  Both create .venv when it is missing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint unit vcan suite perf rtcheck reliability clean

# pip builds the compiled plant engine (setup.py); tools/need-cc installs its
# compiler and headers first when it may, and the last line says when the
# plant runs in pure Python instead.
$(STAMP): pyproject.toml setup.py plant_rt/_cplant.c
	test -x $(BIN)/pip || tools/make-venv $(PYTHON) $(VENV)
	tools/need-cc $(BIN)/python
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	$(BIN)/python -c 'import plant_rt; w = plant_rt.compiled_engine_missing(); w and print(w)'
	touch $(STAMP)

# The bench's main job: a paper scenario between two processes over CAN.
demo: $(STAMP)
	$(BIN)/bench run wen-5.1 --estimator tt-dq --out runs/demo

# The whole test suite: lint, format, types, unit and process tests, and the
# SocketCAN tests on vcan (natively, or inside User-Mode Linux).
test: lint unit vcan

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

unit: $(STAMP)
	tools/need-tmux
	$(BIN)/pytest -m "not socketcan"

vcan: $(STAMP)
	tools/vcan-tests

suite: $(STAMP)
	$(BIN)/bench suite paper --out docs/results
	$(BIN)/bench suite report docs/results --readme README.md

# Benchmarks: docs/perf/perf.json, and docs/BENCHMARKS.md and the README's
# perf block rendered from it (a few minutes).
perf: $(STAMP)
	$(BIN)/bench perf --out docs/perf --doc docs/BENCHMARKS.md --readme README.md

rtcheck: $(STAMP)
	$(BIN)/bench rtcheck --out docs/realtime --doc docs/REALTIME.md

# Reliability: fuzzing, injected faults, kills, signals, load and parallel runs;
# docs/reliability/soak.json and docs/RELIABILITY.md rendered from it (a few minutes).
reliability: $(STAMP)
	mkdir -p docs/reliability
	$(BIN)/bench soak --processes --out docs/reliability/soak.json --doc docs/RELIABILITY.md

clean:
	rm -rf $(VENV) runs .pytest_cache .mypy_cache .ruff_cache

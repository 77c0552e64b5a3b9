# Two commands on a fresh clone: `make demo` and `make test`. Both create .venv themselves.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SHARED ?= ../shared/data

.PHONY: demo test lint typecheck bench data bless schemas figures check-figures clean dhs

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	# torch first and pinned: here pip finds the local CPU wheel; unpinned, it pulls CUDA.
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e '.[dev]'
	# The ROS 2 wheels' .pth re-executes every interpreter of the venv, and setuptools' editable
	# hook imports pathlib and re in each: the first goes (the processes that use rclpy set their
	# own environment: runtime/ros2_env.py), the second becomes lazy (benchmarks/python_startup.py).
	$(BIN)/python -m objsearch.runtime.ros2_env --setup
	# nav2_msgs, vision_msgs, tf2_msgs, objsearch_msgs have no wheel: generated and compiled into
	# .venv for rclpy (--transport ros2), as a ROS 2 workspace would (runtime/ros2_types.py).
	$(BIN)/python -m objsearch.runtime.ros2_types
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/objsearch demo --out out/demo --force

# The suite in two worker processes (pytest-xdist). Idle 2-core machine: pytest 528-642 s in two
# workers (three runs), 1040 s in one (s39's end, before the kill tests' cut; not an A/B); 681-713 s
# in two at s52's end (2,120 tests); 616-631 s at s53's end (2,171 tests; the whole `make test`
# 630-637 s); 537-572 s at s54's end (2,194 tests; the whole `.ci/run` 542 s, and 601 s when a
# pyproject change made it reinstall the package: issue 46's 10-minute target met), scopes
# handed out longest expected first (devtools/xdist_scopes.py), the lake batteries' queries
# forked from a warm process (devtools/query_server.py). tests/conftest.py keeps a module's
# tests in one worker and all of tests/runtime in one.
TEST_WORKERS ?= 2

# ros2_types rebuilds only what changed (a no-op, ~0.3 s, after the install built it). The suite
# starts hundreds of Python processes; where PYTHONDONTWRITEBYTECODE is set (our machines) each
# would compile the sources it imports anew (~0.1-0.25 CPU-s a command), so they are compiled
# once here (compileall writes bytecode whatever that variable says; only stale files again).
test: $(STAMP) lint typecheck
	$(BIN)/python -m objsearch.runtime.ros2_env --setup
	$(BIN)/python -m objsearch.runtime.ros2_types
	$(BIN)/python -m compileall -q -x '/\.' .
	$(BIN)/pytest -n $(TEST_WORKERS) --dist loadscope

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The editable install maps objsearch.agent -> agent/ through an import hook mypy cannot follow, so
# mypy reads the package through a tree of symlinks generated from pyproject's package-dir (the
# table setuptools builds the wheel from; nothing to keep in step by hand). Tests and benchmarks
# are checked too, each in its own pass: benchmarks are scripts run by path, so benchmarks/events.py
# is a module `events`, as is the test package tests/events. devtools/ (the harnesses, not in the
# wheel) is a package of the checkout, found from here.
TYPECHECK := $(VENV)/typecheck
typecheck: $(STAMP)
	$(BIN)/python tests/typecheck_tree.py $(TYPECHECK)
	MYPYPATH=$(TYPECHECK) $(BIN)/mypy -p objsearch
	MYPYPATH=$(TYPECHECK) $(BIN)/mypy -p devtools
	MYPYPATH=$(TYPECHECK) $(BIN)/mypy tests
	MYPYPATH=$(TYPECHECK) $(BIN)/mypy benchmarks

bench: $(STAMP)
	$(BIN)/python benchmarks/planner.py
	$(BIN)/python benchmarks/mapping.py
	$(BIN)/python benchmarks/events.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/ingest.py
	$(BIN)/python benchmarks/bench_paper.py
	$(BIN)/python benchmarks/bad_inputs.py

# objsearch bench dhs: the Dynamic House Simulator's dependencies (docs/results-dhs.md); its code is
# a checkout of the pinned commit that the user names with --source or OBJSEARCH_DHS_SOURCE.
dhs: $(STAMP)
	$(BIN)/pip install --quiet -e '.[dev,dhs]'
	$(BIN)/python -m objsearch.runtime.ros2_env --setup

data: $(STAMP)
	$(BIN)/objsearch data build --source $(SHARED)

# Write events/schema/*.json from the records in agent/catalogue.py (never edit those files).
schemas: $(STAMP)
	$(BIN)/python -m objsearch.agent.schema_files

# Re-record the golden logs after a change that is meant to alter decisions (tests/replay).
GOLDEN ?= tests/replay/golden
bless: $(STAMP)
	$(BIN)/python -m objsearch.experiments.golden $(GOLDEN)

# Figures in the docs that a command prints live between <!-- figures:NAME --> markers
# (experiments/figures.py). `figures` reruns every command and rewrites its block; `check-figures`
# compares every block with a fresh run (about 2 minutes, bench paper the longest), exit 1 naming
# the stale ones. `make test` checks only the cheap ones (tests/experiments/test_figures.py).
FIGURE_DOCS := README.md docs/replay.md
figures: $(STAMP)
	$(BIN)/python -m objsearch.experiments.figures $(FIGURE_DOCS)

check-figures: $(STAMP)
	$(BIN)/python -m objsearch.experiments.figures --check $(FIGURE_DOCS)

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache

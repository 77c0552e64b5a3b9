# Two commands on a fresh clone: `make demo` and `make test`. Both create .venv themselves.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SHARED ?= ../shared/data

.PHONY: demo test lint typecheck bench data bless clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	# torch first and pinned: here pip finds the local CPU wheel; unpinned, it pulls CUDA.
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/objsearch demo --out out/demo --force

test: $(STAMP) lint typecheck
	$(BIN)/pytest

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The editable install maps objsearch.agent -> agent/ through an import hook mypy cannot follow,
# so mypy reads the package through a tree of symlinks laid out the way it is installed.
TYPECHECK := $(VENV)/typecheck
typecheck: $(STAMP)
	rm -rf $(TYPECHECK) && mkdir -p $(TYPECHECK)/objsearch
	ln -s $(CURDIR)/objsearch/*.py $(CURDIR)/objsearch/py.typed $(TYPECHECK)/objsearch/
	for d in agent events sim replay pipeline runtime experiments; do ln -s $(CURDIR)/$$d $(TYPECHECK)/objsearch/$$d; done
	MYPYPATH=$(TYPECHECK) $(BIN)/mypy -p objsearch

bench: $(STAMP)
	$(BIN)/python benchmarks/planner.py
	$(BIN)/python benchmarks/mapping.py
	$(BIN)/python benchmarks/events.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/ingest.py
	$(BIN)/python benchmarks/bench_paper.py

data: $(STAMP)
	$(BIN)/objsearch data build --source $(SHARED)

# Re-record the golden logs after a change that is meant to alter decisions (tests/replay).
GOLDEN ?= tests/replay/golden
bless: $(STAMP)
	$(BIN)/python -m objsearch.replay.golden $(GOLDEN)

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache

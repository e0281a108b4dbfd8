# roachplan: `make run` sets everything up and starts the app; `make test` sets up and tests.
# `make lint` and `make docs` add their tools (pyproject's extras) to the same .venv.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.installed-docs
LINT_STAMP := $(VENV)/.installed-lint
SCENE  ?= double_bridge
HOST   ?= 127.0.0.1
PORT   ?= 8080

RUN_DEBS  := openscad libusb-1.0-0
TEST_DEBS := $(RUN_DEBS) chromium

LINTED := src tests examples benchmarks scripts

.PHONY: setup run test test-fast lint docs fuzz bench loadtest clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)
	@scripts/install-system-deps.sh $(RUN_DEBS)

run: setup
	$(BIN)/roachplan serve --scene $(SCENE) --host $(HOST) --port $(PORT)

# Every test, in TEST_WORKERS processes (pytest-xdist; a test file stays in one, in its order);
# the 25 slowest are listed at the end. TEST_WORKERS=0 runs them in this process. Then, with
# the machine to themselves, the tests marked alone (they measure real time).
TEST_WORKERS ?= 2
test: $(STAMP)
	@scripts/install-system-deps.sh $(TEST_DEBS)
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile -m "not alone" --durations=25
	$(BIN)/python -m pytest -m alone --durations=5

# The edit-test loop: every test not marked slow (no browser, batch, real capture or hostile
# corpus), under 3 minutes on 2 cores.
test-fast: $(STAMP)
	@scripts/install-system-deps.sh $(RUN_DEBS)
	$(BIN)/python -m pytest -m "not slow" --durations=10

# Long property-based fuzzing of the readers and the scene loader; SEED=N repeats a run.
SEED ?= $(shell date +%s)
fuzz: $(STAMP)
	ROACHPLAN_FUZZ=1 $(BIN)/python -m pytest -q tests/test_fuzz_*.py --hypothesis-seed=$(SEED)

bench: setup
	$(BIN)/python benchmarks/bench_cli.py
	$(BIN)/python benchmarks/bench_trial.py
	$(BIN)/python benchmarks/bench_planning.py
	$(BIN)/python benchmarks/bench_experiment.py
	$(BIN)/python benchmarks/bench_perception.py
	$(BIN)/python benchmarks/bench_captures.py
	$(BIN)/python benchmarks/bench_app.py
	$(BIN)/python benchmarks/bench_drivable.py
	$(BIN)/python benchmarks/bench_choose.py
	$(BIN)/python benchmarks/bench_engines.py
	$(BIN)/python benchmarks/bench_fidelity.py
	$(BIN)/python benchmarks/bench_edges.py
	$(BIN)/python benchmarks/bench_guard.py
	$(BIN)/python benchmarks/bench_page_robot.py
	$(BIN)/python benchmarks/load_test.py

# Five browsers clicking and uploading at once for 2 minutes; needs chromium.
loadtest: setup
	$(BIN)/python benchmarks/load_test.py

$(DOCS_STAMP): $(STAMP)
	$(BIN)/pip install -q -e '.[test,docs]'
	touch $(DOCS_STAMP)

# (the docs' tools too: pyright checks scripts/griffe_lazy_exports.py, which imports Griffe)
$(LINT_STAMP): $(STAMP)
	$(BIN)/pip install -q -e '.[test,lint,docs]'
	touch $(LINT_STAMP)

# The documentation site (mkdocs.yml, docs/) into site/, warnings as errors. The variable
# quiets Material's banner about its end of life (May 2027) and MkDocs 2.
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

# ruff (lint and format) and pyright over the package, tests, examples, benchmarks and
# scripts (not the top-level links, which would be the same files twice). Every check runs,
# and the target fails if any did.
lint: $(LINT_STAMP)
	@status=0; \
	$(BIN)/ruff check $(LINTED) || status=1; \
	$(BIN)/ruff format --check $(LINTED) || status=1; \
	$(BIN)/pyright || status=1; \
	exit $$status

clean:
	rm -rf $(VENV) *.egg-info .pytest_cache test-artifacts site

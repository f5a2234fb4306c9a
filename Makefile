# The two set-up commands of the README, and a few developer conveniences.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test test-fast lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $(STAMP)

## run: install into .venv and start the embedded stack (all stages + API on 127.0.0.1:8000) with a demo robot
run: $(STAMP)
	$(BIN)/aisle run --demo $(ARGS)

# pytest over one process per core (pytest-xdist), each module's tests in one process so its fixtures are built
# once; tests/conftest.py puts the end-to-end modules first
PYTEST_PARALLEL := -n auto --dist loadscope --no-loadscope-reorder

## test: the whole test suite (PostgreSQL tests run when AISLE_TEST_POSTGRES_URL is set)
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy shared services atlas api migrations bench tests
	$(BIN)/pytest $(PYTEST_PARALLEL)

## test-fast: skip the slow end-to-end runs
test-fast: $(STAMP)
	$(BIN)/pytest $(PYTEST_PARALLEL) -m "not slow"

bench: $(STAMP)
	for f in bench/bench_*.py; do PYTHONPATH=. $(BIN)/python $$f; done

clean:
	rm -rf $(VENV) var build *.egg-info

# Two commands a new user needs (see README.md):
#   make run    — set up .venv from pyproject.toml and reproduce every study (tables; PNGs in results/)
#   make demo   — the 10,000-run Monte Carlo demo (results/demo)
#   make test   — set up .venv from pyproject.toml and run the test suite
# Everything is installed from the project's own files into ./.venv; nothing by hand.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: install run demo test test-slow clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,notebooks]"
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(BIN)/jaxtrack reproduce all --out results

demo: $(STAMP)
	$(BIN)/jaxtrack demo --out results/demo

# The suite runs in three pytest processes: the fault-injection cases (which run JAX in worker
# threads, some ending in runtime errors raised from XLA callbacks) and the property tests (many
# compilations) each get a fresh process, so nothing they leave behind can reach other tests.
ISOLATED := tests/test_faults.py tests/test_properties.py

test: $(STAMP)
	$(BIN)/pytest $(PYTEST_ARGS) $(addprefix --ignore=,$(ISOLATED))
	$(BIN)/pytest $(PYTEST_ARGS) tests/test_faults.py
	$(BIN)/pytest $(PYTEST_ARGS) tests/test_properties.py

test-slow: $(STAMP)
	$(BIN)/pytest --runslow $(PYTEST_ARGS) $(addprefix --ignore=,$(ISOLATED))
	$(BIN)/pytest --runslow $(PYTEST_ARGS) $(ISOLATED)

clean:
	rm -rf $(VENV) results .pytest_cache

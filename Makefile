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

test: $(STAMP)
	$(BIN)/pytest $(PYTEST_ARGS)

test-slow: $(STAMP)
	$(BIN)/pytest --runslow $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) results .pytest_cache

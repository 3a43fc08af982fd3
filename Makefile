# Two commands a new user needs (see README.md):
#   make run    — set up .venv from pyproject.toml and run the main job (results/ holds tables + PNGs)
#   make test   — set up .venv from pyproject.toml and run the test suite
# Everything is installed from the project's own files into ./.venv; nothing by hand.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: install run test test-slow clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,notebooks]"
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(BIN)/jaxtrack demo --out results/demo

test: $(STAMP)
	$(BIN)/python -m pytest $(PYTEST_ARGS)

test-slow: $(STAMP)
	$(BIN)/python -m pytest --runslow $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) results .pytest_cache

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

.PHONY: install run demo test test-slow clean docs

# jaxtrack needs Python >= 3.11 (pyproject's requires-python). Checked before anything is made,
# with a message that says which interpreter was found and how to pick another.
PY_OK := import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)

# A venv is reused only if a previous install finished (the stamp). Without the stamp it may be
# half made (an older Python, no pip because python3-venv is missing, an interrupted install):
# it is then removed and made again, so a failed attempt never needs `make clean`.
$(STAMP): pyproject.toml
	@$(PYTHON) -c '$(PY_OK)' 2>/dev/null || { \
	  echo "jaxtrack needs Python >= 3.11, but PYTHON=$(PYTHON) is: $$($(PYTHON) --version 2>&1 || echo 'not found')." >&2; \
	  echo "Install Python 3.11+ (with its venv module, e.g. Debian's python3-venv) and run: make PYTHON=python3.11 $(MAKECMDGOALS)" >&2; \
	  exit 1; }
	@if [ -e $(VENV) ] && ! { [ -x $(BIN)/python ] && $(BIN)/python -c '$(PY_OK)' 2>/dev/null && $(BIN)/python -m pip --version >/dev/null 2>&1; }; then \
	  echo "$(VENV) is incomplete or made by another Python: removing it and making it again"; \
	  rm -rf $(VENV); \
	fi
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,notebooks,docs,export]"
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(BIN)/jaxtrack reproduce all --out results

demo: $(STAMP)
	$(BIN)/jaxtrack demo --out results/demo

# The suite runs in four pytest processes: the fault-injection cases (which run JAX in worker
# threads, some ending in runtime errors raised from XLA callbacks) and the property tests (many
# compilations) each get a fresh process, and the rest is split in two by file name. XLA's CPU
# compiler has crashed (SIGSEGV inside backend_compile) twice late in a long single process
# (after ~500 tests, in an unremarkable compilation; not reproducible alone), so no process is
# left to accumulate the whole suite's compilations; tests/conftest.py also clears JAX's caches
# after each test module.
ISOLATED := tests/test_faults.py tests/test_properties.py
FIRST    := $(filter-out $(ISOLATED),$(sort $(wildcard tests/test_[a-m]*.py)))
SECOND   := $(filter-out $(ISOLATED) $(FIRST),$(sort $(wildcard tests/test_*.py)))

test: $(STAMP)
	$(BIN)/pytest $(PYTEST_ARGS) $(FIRST)
	$(BIN)/pytest $(PYTEST_ARGS) $(SECOND)
	$(BIN)/pytest $(PYTEST_ARGS) tests/test_faults.py
	$(BIN)/pytest $(PYTEST_ARGS) tests/test_properties.py
	$(MAKE) docs

test-slow: $(STAMP)
	$(BIN)/pytest --runslow $(PYTEST_ARGS) $(FIRST)
	$(BIN)/pytest --runslow $(PYTEST_ARGS) $(SECOND)
	$(BIN)/pytest --runslow $(PYTEST_ARGS) $(ISOLATED)

# The documentation site (mkdocs.yml), built offline and strictly into build/site. The gallery
# renders the executed notebooks in docs/gallery/, which tests/test_notebooks.py writes; only a
# missing copy, or one older than its notebook, is executed here (tools/execute_notebooks.py, the
# code path of the test). tools/check_site.py then counts the figures of every gallery page and
# looks up every public name of the API reference.
GALLERY := $(patsubst notebooks/%.ipynb,docs/gallery/%.ipynb,$(wildcard notebooks/*.ipynb))

docs/gallery/%.ipynb: notebooks/%.ipynb | $(STAMP)
	$(BIN)/python tools/execute_notebooks.py $<

docs: $(STAMP) $(GALLERY)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir build/site
	$(BIN)/python tools/check_site.py build/site

clean:
	rm -rf $(VENV) results .pytest_cache

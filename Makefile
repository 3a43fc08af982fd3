# Two commands a new user needs (see README.md):
#   make run    — set up .venv from pyproject.toml and reproduce every study (tables; PNGs in results/)
#   make demo   — the 10,000-run Monte Carlo demo (results/demo)
#   make test   — set up .venv from pyproject.toml and run the test suite
# Everything is installed from the project's own files into ./.venv; nothing by hand: the
# packages of pyproject.toml at the exact versions of requirements.lock (pip constraints), so a
# fresh clone gets the versions the suite passed with. `make lock` refreshes the lock file.
# pip installs the locked pip and uv, and uv the rest (the same constraints, the same index,
# PyPI): a fresh clone's install 57 -> 27 s (pip resolves and unpacks on one core). Compiled to
# bytecode at install, as pip does: without it every process of the suite (xdist workers, notebook
# kernels, CLI children) compiled jax & co. again at import (PYTHONDONTWRITEBYTECODE is set here),
# and the suite's first half took 524 s against 453.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=
LOCK   := requirements.lock
EXTRAS := test,notebooks,docs,export

.PHONY: install run demo test test-slow clean docs lock test-oracle-versions

# jaxtrack needs Python >= 3.11 (pyproject's requires-python). Checked before anything is made,
# with a message that says which interpreter was found and how to pick another.
PY_OK := import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)

# A venv is reused only if a previous install finished (the stamp). Without the stamp it may be
# half made (an older Python, no pip because python3-venv is missing, an interrupted install):
# it is then removed and made again, so a failed attempt never needs `make clean`.
$(STAMP): pyproject.toml $(LOCK)
	@$(PYTHON) -c '$(PY_OK)' 2>/dev/null || { \
	  echo "jaxtrack needs Python >= 3.11, but PYTHON=$(PYTHON) is: $$($(PYTHON) --version 2>&1 || echo 'not found')." >&2; \
	  echo "Install Python 3.11+ (with its venv module, e.g. Debian's python3-venv) and run: make PYTHON=python3.11 $(MAKECMDGOALS)" >&2; \
	  exit 1; }
	@if [ -e $(VENV) ] && ! { [ -x $(BIN)/python ] && $(BIN)/python -c '$(PY_OK)' 2>/dev/null && $(BIN)/python -m pip --version >/dev/null 2>&1; }; then \
	  echo "$(VENV) is incomplete or made by another Python: removing it and making it again"; \
	  rm -rf $(VENV); \
	fi
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip uv -c $(LOCK)
	$(BIN)/uv pip install --quiet --compile-bytecode --python $(BIN)/python -c $(LOCK) -e ".[$(EXTRAS)]"
	touch $(STAMP)

# Refresh requirements.lock: resolve pyproject.toml's ranges afresh (newest versions the index
# serves, in a throw-away venv), then freeze every installed distribution. Run `make test` after
# it and commit the lock only if the suite passes; the bench extra is locked too.
LOCK_VENV := .lock-venv
lock:
	@$(PYTHON) -c '$(PY_OK)' || { echo "make lock needs Python >= 3.11 (PYTHON=$(PYTHON))" >&2; exit 1; }
	rm -rf $(LOCK_VENV)
	$(PYTHON) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(LOCK_VENV)/bin/python -m pip install --quiet -e ".[$(EXTRAS),bench]" uv
	{ echo "# Exact versions the test suite passed with: pip constraints for make install (pyproject.toml"; \
	  echo "# keeps the compatible ranges for library users). Made by 'make lock' with Python $$($(LOCK_VENV)/bin/python -c 'import platform; print(platform.python_version(), platform.system(), platform.machine())')."; \
	  $(LOCK_VENV)/bin/python -m pip freeze --all --exclude-editable | grep -v '^jaxtrack'; } > $(LOCK).tmp
	mv $(LOCK).tmp $(LOCK)
	rm -rf $(LOCK_VENV)
	@echo "wrote $(LOCK); now run make test before committing it"

install: $(STAMP)

run: $(STAMP)
	$(BIN)/jaxtrack reproduce all --out results

demo: $(STAMP)
	$(BIN)/jaxtrack demo --out results/demo

# The suite runs as three pytest sessions, each on two worker processes (pytest-xdist, one per
# core; XDIST= runs them in one process each): the two halves of the suite by file name, then the
# fault-injection cases (JAX in worker threads, some ending in runtime errors raised from XLA
# callbacks) with the property tests (many compilations). Every session compiles with XLA:CPU's
# former emitters, in less than half the fusion emitters' time (tests/conftest.py); test-slow
# also holds the multi-target contract to its reference bit for bit at the fusion emitters the
# reference was computed with. Each test module is one work unit of a worker, longest first (tests/conftest.py). XLA's CPU compiler has crashed (SIGSEGV inside
# backend_compile) twice late in a long single process (after ~500 tests, in an unremarkable
# compilation; not reproducible alone), so no worker is left to accumulate the whole suite's
# compilations (about 250 tests each here); tests/conftest.py also clears JAX's in-memory caches
# after each test module, and JAX's persistent compilation cache (.cache/jax, empty in a fresh
# clone) lets a program compiled once in the run be loaded, not compiled, wherever it recurs.
# The Ctrl-C tests (SIGINT to the test process and to a CLI child, with latency bounds) run first,
# in a process of their own, without xdist: both failed together in two of four full runs (once in
# a worker after other modules, once in this serial process after the other sessions: the
# in-process SIGINT was not seen, the CLI child took > 5 s to stop), and passed every time run
# alone (6 times, cold or warm cache, CI=true or not); the cause was not found. A failure is
# rerun once; a second failure fails make test.
# Where the time goes: JAXTRACK_TEST_PROFILE=DIR make test, then python tools/suite_profile.py DIR
# (per module: wall, XLA compile, trace seconds; about 80% of the suite is JAX compiling and tracing).
ISOLATED := tests/test_faults.py tests/test_properties.py
SIGNALS  := tests/test_cli_robustness.py
# tests/conftest.py compiles the suite with most of XLA's optimisations off (LLVM -O0; most modules
# are compile-bound: 2301 -> 2163 worker-s), and the few runtime-bound modules (pytest.mark.
# xla_optimized) at the default level, each in its own session's worker. A session of their own
# was measured too and gained nothing (the extra session and the compilations no longer shared
# through the persistent cache ate it: 20:35 against 19:57).
FIRST    := $(filter-out $(ISOLATED) $(SIGNALS),$(sort $(wildcard tests/test_[a-m]*.py)))
SECOND   := $(filter-out $(ISOLATED) $(SIGNALS) $(FIRST),$(sort $(wildcard tests/test_*.py)))
# --no-loadscope-reorder: keep the longest-first order of the work units of tests/conftest.py (xdist
# would otherwise hand them out by test count, leaving the one-test notebooks for the end).
XDIST    ?= -n 2 --dist loadscope --no-loadscope-reorder

test: $(STAMP)
	$(BIN)/pytest $(PYTEST_ARGS) $(SIGNALS) || { echo "The Ctrl-C tests failed (latency bounds on a busy machine): running them once more" >&2; \
	  $(BIN)/pytest $(PYTEST_ARGS) $(SIGNALS); }
	$(BIN)/pytest $(XDIST) $(PYTEST_ARGS) $(FIRST)
	$(BIN)/pytest $(XDIST) $(PYTEST_ARGS) $(SECOND)
	$(BIN)/pytest $(XDIST) $(PYTEST_ARGS) $(ISOLATED)
	$(MAKE) docs

test-slow: $(STAMP)
	$(BIN)/pytest --runslow $(XDIST) $(PYTEST_ARGS) $(FIRST)
	$(BIN)/pytest --runslow $(XDIST) $(PYTEST_ARGS) $(SECOND)
	$(BIN)/pytest --runslow $(XDIST) $(PYTEST_ARGS) $(ISOLATED)
	JAXTRACK_TEST_FUSION_EMITTERS=1 $(BIN)/pytest --runslow $(PYTEST_ARGS) tests/test_multitarget_contract.py
	$(BIN)/pytest --runslow $(PYTEST_ARGS) $(SIGNALS)

# statsmodels, the MLE oracle, on its 0.14 line as well as the locked version: installs 0.14.x
# into a throw-away folder ahead of the venv's packages and runs the statsmodels comparison.
test-oracle-versions: $(STAMP)
	rm -rf .oracle-014
	$(BIN)/python -m pip install --quiet --no-deps --target .oracle-014 "statsmodels>=0.14,<0.15"
	PYTHONPATH=.oracle-014 $(BIN)/pytest -p no:cacheprovider -k statsmodels tests/test_learning_mle.py
	$(BIN)/pytest -p no:cacheprovider -k statsmodels tests/test_learning_mle.py
	rm -rf .oracle-014

# The documentation site (mkdocs.yml), built offline and strictly into build/site. The gallery
# renders the executed notebooks in docs/gallery/, which tests/test_notebooks.py writes; only a
# missing copy, or one older than its notebook, is executed here (tools/execute_notebooks.py, the
# code path of the test). tools/check_site.py then counts the figures of every gallery page and
# looks up every public name of the API reference.
GALLERY := $(patsubst notebooks/%.ipynb,docs/gallery/%.ipynb,$(wildcard notebooks/*.ipynb))

# jaxtrack/_progress.py: a copy executed before it shows tqdm's "IProgress not found" warning, which
# tools/check_site.py rejects; such a copy is older than the file and is executed again.
docs/gallery/%.ipynb: notebooks/%.ipynb jaxtrack/_progress.py | $(STAMP)
	$(BIN)/python tools/execute_notebooks.py $<

docs: $(STAMP) $(GALLERY)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir build/site
	$(BIN)/python tools/check_site.py build/site

clean:
	rm -rf $(VENV) results .pytest_cache

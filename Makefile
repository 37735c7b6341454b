# The commands of the README: `make demo`, `make test` and `make docs`.
# Each creates .venv if missing and installs kinred (editable) with what it needs.

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: demo test bench docs clean chromium

WARM_FAILED := make test: a kernel warm-up run failed (ignored: pytest compiles on first use)
# The suite starts many Python processes (CLI subprocesses, Dask workers, examples); each
# would compile kinred's modules from source where PYTHONDONTWRITEBYTECODE is set (about 0.5 s
# each): compileall writes the bytecode once (__pycache__ is git-ignored).
PYC_FAILED  := make test: compileall failed (ignored: modules compile on import)
# pytest rewrites the assertions of every test module on import (about 8 s per process for
# this suite) and caches the result as bytecode, which PYTHONDONTWRITEBYTECODE forbids: each
# xdist worker would then rewrite them all again. pytest runs without it; a collection before
# the suite writes the cache once.
PYTEST := env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest
COLLECT_FAILED := make test: collecting the tests failed (the suite will say why)

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed-base: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[test]"
	@touch $@ $(VENV)/.installed-base

$(VENV)/.installed-docs: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	@touch $@ $(VENV)/.installed-base

demo: $(VENV)/.installed-base
	$(BIN)/kinred demo

# The suite runs on every core (pytest-xdist; work stealing keeps both busy to the end) and
# lists its slowest tests. The report's browser
# test needs Debian's chromium: installed here with apt when run as root, otherwise one line
# says the command to run (kinred.report._browser.find_chromium is the one place that looks).
test: $(VENV)/.installed-test chromium
	@$(BIN)/python -m compileall -q -j 0 kinred tests >/dev/null || echo "$(PYC_FAILED)"
	@echo "make test: compiling the numba kernels and the tests' assertions (two processes; cached for the suite)"
	@$(BIN)/python tests/_warm_kernels.py demo w1 steps >/dev/null 2>&1 & pid=$$!; \
	  $(BIN)/python tests/_warm_kernels.py fig4 twins >/dev/null 2>&1 || echo "$(WARM_FAILED)"; \
	  $(PYTEST) --collect-only -q >/dev/null 2>&1 || echo "$(COLLECT_FAILED)"; \
	  wait $$pid || echo "$(WARM_FAILED)"
	$(PYTEST) -n auto --dist worksteal --durations=15

chromium: $(VENV)/.installed-base
	@$(BIN)/python -c "from kinred.report._browser import find_chromium as f; f()" 2>/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "make test: installing chromium with apt-get (for tests/test_report_browser.py)"; \
	    apt-get update -qq >/dev/null && \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  else \
	    echo "make test: tests/test_report_browser.py needs Chromium; install it with: sudo apt-get install chromium"; \
	    exit 2; \
	  fi; }

# HTML into docs/_build/html (git-ignored); any warning fails the build. The gallery pages
# are regenerated in docs/auto_examples (git-ignored) by running every example.
docs: $(VENV)/.installed-docs
	$(BIN)/python -m sphinx -W --keep-going -E -b html docs docs/_build/html
	@echo "documentation: docs/_build/html/index.html"

bench: $(VENV)/.installed-test
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis build dist *.egg-info
	rm -rf docs/_build docs/auto_examples docs/sg_execution_times.rst
	find . -name __pycache__ -type d -prune -exec rm -rf {} +

# tofpose: `make run` (the server), `make test` (the whole suite), `make bench` (docs/results.md).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python

.PHONY: run test lint bench clean system-deps

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

run: $(VENV)/.installed
	$(VENV)/bin/tofpose serve

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports

# System tools the tests use: pdftoppm (poppler-utils) renders report PDFs to PNG.
system-deps:
	@command -v pdftoppm >/dev/null || { apt-get update -qq && apt-get install -y -qq poppler-utils; }

test: lint system-deps
	$(PY) -m pytest -q

bench: $(VENV)/.installed
	$(PY) bench/report.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache

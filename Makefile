# tofpose: `make run` (the server), `make test` (the whole suite), `make bench` (docs/results.md).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python

.PHONY: run test lint bench clean kernels-clean system-deps frontend

FRONTEND_SRC := $(shell find frontend/src -type f 2>/dev/null) frontend/index.html frontend/vite.config.ts frontend/tsconfig.json

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	$(VENV)/bin/tofpose warm-up  # compile the pipeline kernels into numba's cache (~1 min once)
	touch $@

# The dashboard: npm ci from the lock file, then type-check and build into frontend/dist.
frontend/node_modules/.package-lock.json: frontend/package.json frontend/package-lock.json
	cd frontend && npm ci --no-audit --no-fund --loglevel=error

frontend/dist/index.html: frontend/node_modules/.package-lock.json $(FRONTEND_SRC)
	cd frontend && npm run build --silent

frontend: frontend/dist/index.html

run: $(VENV)/.installed frontend
	$(VENV)/bin/tofpose serve

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports

# System tools the tests use: pdftoppm (poppler-utils) renders report PDFs to PNG;
# Debian's chromium runs the dashboard's browser tests.
system-deps:
	@missing=""; command -v pdftoppm >/dev/null || missing="$$missing poppler-utils"; \
	command -v chromium >/dev/null || missing="$$missing chromium"; \
	if [ -n "$$missing" ]; then apt-get update -qq && apt-get install -y -qq $$missing; fi

test: lint system-deps frontend
	$(PY) -m pytest -q

bench: $(VENV)/.installed
	$(PY) bench/report.py

clean: kernels-clean
	rm -rf $(VENV) .pytest_cache .ruff_cache frontend/node_modules frontend/dist

# numba's on-disk cache of the compiled kernels (stale for callers after a kernel edit)
kernels-clean:
	find tofpose -name '*.nbi' -delete -o -name '*.nbc' -delete

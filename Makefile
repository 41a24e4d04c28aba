# tofpose: `make run` (the server), `make test` (the whole suite), `make bench` (docs/results.md).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python

.PHONY: run test lint bench clean kernels-clean system-deps frontend

FRONTEND_SRC := $(shell find frontend/src -type f 2>/dev/null) frontend/index.html frontend/vite.config.ts frontend/tsconfig.json

# The venv with what the server needs: the server compiles the pipeline kernels itself, in
# the background, on its first start (frames stream meanwhile).
$(VENV)/.installed: pyproject.toml
	@echo "[setup] creating $(VENV) and installing tofpose with its dependencies (pip)"
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --no-compile --disable-pip-version-check -e .
	touch $@

# The test, lint and device tools on top (pytest, playwright, schemathesis, the real
# devices' client libraries): `make test`, `make lint`, `make bench`.
$(VENV)/.dev: $(VENV)/.installed
	@echo "[setup] installing the test tools (pip, the dev extra)"
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

# numba's on-disk cache of the pipeline kernels (~1-2 min once, seconds when cached)
$(VENV)/.kernels: $(VENV)/.dev $(shell find tofpose -name '*.py')
	@echo "[setup] compiling the pipeline kernels into numba's cache (~1-2 min)"
	@# the cache directory is named after a digest of the kernel sources (tofpose/kernels)
	$(VENV)/bin/tofpose warm-up
	touch $@

# The dashboard: npm ci from the lock file, then type-check and build into frontend/dist.
frontend/node_modules/.package-lock.json: frontend/package.json frontend/package-lock.json
	@echo "[setup] installing the dashboard's npm packages (npm ci)"
	cd frontend && npm ci --no-audit --no-fund --loglevel=error

frontend/dist/index.html: frontend/node_modules/.package-lock.json $(FRONTEND_SRC)
	@echo "[setup] building the dashboard (tsc + vite)"
	cd frontend && npm run build --silent

frontend: frontend/dist/index.html

# The venv and the dashboard build in parallel (pip and npm each wait on their own I/O).
run:
	@$(MAKE) --no-print-directory -j2 $(VENV)/.installed frontend
	@echo "[run] starting the server (on a first start it compiles the pipeline kernels in the background: poses come from the NumPy reference implementation meanwhile, the compiled kernels take over after ~2-3 min)"
	$(VENV)/bin/tofpose serve

lint: $(VENV)/.dev
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports
	$(VENV)/bin/mypy

# System tools the tests and the bench use: pdftoppm (poppler-utils) renders report PDFs to PNG;
# Debian's chromium runs the dashboard's browser tests.
system-deps:
	@missing=""; command -v pdftoppm >/dev/null || missing="$$missing poppler-utils"; \
	command -v chromium >/dev/null || missing="$$missing chromium"; \
	if [ -n "$$missing" ]; then apt-get update -qq && apt-get install -y -qq $$missing; fi

# The load-sensitive tests (marker load_sensitive: timing depends on machine load) run
# after the rest, on their own; both runs always run, and the target fails if either does.
test: lint system-deps frontend $(VENV)/.kernels
	$(PY) -m pytest -q -m "not load_sensitive"; rest=$$?; \
	$(PY) -m pytest -q -m load_sensitive; load=$$?; \
	[ $$rest -eq 0 ] && [ $$load -eq 0 ]

# docs/results.md and the README's generated tables; one section alone with
# BENCH_ARGS="--only SECTION" (e.g. --only goals: issue 47's goals table).
bench: system-deps frontend $(VENV)/.kernels
	$(PY) bench/report.py $(BENCH_ARGS)

clean: kernels-clean
	rm -rf $(VENV) .pytest_cache .ruff_cache frontend/node_modules frontend/dist

# numba's on-disk cache of the compiled kernels (one directory per state of their sources)
kernels-clean:
	find tofpose -name '*.nbi' -delete -o -name '*.nbc' -delete
	find tofpose -type d -name 'tofpose-kernels-*' -prune -exec rm -rf {} +
	rm -f $(VENV)/.kernels

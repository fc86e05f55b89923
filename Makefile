# Two commands on a fresh machine: `make run` and `make test`.
PYTHON ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed
OUT ?= out

.PHONY: run test test-slow test-all venv browser lint bench clean

# (Re)install only when pyproject.toml changed: idempotent and fast on a warm tree.
$(STAMP): pyproject.toml
	@test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e ".[test]"
	@# compile the numba kernels of the mu bounds once (cached on disk next to the module)
	$(VENV)/bin/python -c "from oos_drake.robust.mu_kernels import warm_up; print(f'mu kernels compiled in {warm_up():.0f} s')"
	@touch $(STAMP)

# The browser of the report's tests (tests/test_report*.py): Debian's chromium, installed when
# missing and we are root (CI containers); otherwise install it yourself, the tests say so (and
# fail in CI, tests/conftest.py).
CHROMIUM := /usr/bin/chromium

browser:
	@if [ ! -x $(CHROMIUM) ] && [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing chromium (the report's browser tests)"; \
		apt-get install -y -q chromium >/dev/null 2>&1 || \
		{ apt-get update -q >/dev/null && apt-get install -y -q chromium >/dev/null; }; \
	fi
	@test -x $(CHROMIUM) || echo "warning: $(CHROMIUM) missing: the report's browser tests skip (fail in CI)"

venv: $(STAMP) browser

run: $(STAMP)
	$(VENV)/bin/oos run --out $(OUT) $(ARGS)

test: $(STAMP) browser
	$(VENV)/bin/python -m pytest -q

# the end-to-end checks behind the headline results (about 20 min on 2 cores); CI runs them
test-slow: $(STAMP) browser
	$(VENV)/bin/python -m pytest -q --runslow -m slow --durations=15

test-all: $(STAMP) browser
	$(VENV)/bin/python -m pytest -q --runslow

lint: $(STAMP)
	$(VENV)/bin/ruff check oos_drake tests benchmarks

bench: $(STAMP)
	for f in benchmarks/bench_*.py; do $(VENV)/bin/python $$f || exit 1; done

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache

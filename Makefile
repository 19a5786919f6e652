# One command each (see README): `make demo` runs the main job, `make test` every test (`make
# test-fast` the quick subset, without the slow independent checks),
# `make bench` regenerates every performance page (docs/performance.md, docs/bench/), `make
# pages` every generated docs page (docs/pages.md; hours: `make pages-quick` the cheap ones).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

$(BIN)/activate: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[test]"
	touch $(BIN)/activate

.PHONY: demo test test-fast test-isa lint bench pages pages-quick
demo: $(BIN)/activate
	$(BIN)/jaxdeploy simulate --out results/demo --overwrite

# On every core (pytest-xdist), tests handed out one at a time to whichever worker is free.
PYTEST_WORKERS := -n auto --dist load --maxschedchunk 1

# ruff, then every test, the slow checks against independent references included (-m
# overrides pyproject's addopts), longest first (tests/durations.json): what CI runs.
test: $(BIN)/activate
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/pytest $(PYTEST_WORKERS) -m "slow or not slow"

# Every test with XLA compiling for another instruction set (ISA=AVX2, the default, or
# SSE4_2): CI's hosts differ (AVX-512 and AVX2 both seen), and a bound that rests on one
# build's round-off fails on another (three slow tests did, on an AVX-512 host). Run it
# before setting a tolerance on round-off. XLA only warns about a name it does not know and
# then compiles for the host, so an unknown ISA is refused here instead of passing unlimited.
ISA ?= AVX2
ISAS := SSE4_2 AVX AVX2 AVX512
test-isa: $(BIN)/activate
	@case " $(ISAS) " in *" $(ISA) "*) ;; *) echo "error: ISA=$(ISA) is not one of: $(ISAS)" >&2; exit 2;; esac
	XLA_FLAGS="--xla_cpu_max_isa=$(ISA) $$XLA_FLAGS" $(BIN)/pytest $(PYTEST_WORKERS) -m "slow or not slow"

# The quick subset for development: ruff and every test not marked slow.
test-fast: $(BIN)/activate
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/pytest $(PYTEST_WORKERS)

# Measures the committed code (refuses a dirty tree); ~20 min on 2 quiet cores. Run it on a
# quiet machine: the page records the load average at the start and the end.
$(VENV)/.bench-extra: pyproject.toml $(BIN)/activate
	$(BIN)/pip install --quiet -e ".[bench]"
	touch $@

bench: $(VENV)/.bench-extra
	$(BIN)/python -m benchmarks all

# Every generated page, in order, on committed code (tools/pages.py lists them with their
# measured cost; each refuses a dirty tree). Includes `make bench`'s pages. JOBS=2: two at a
# time where they share no page (make bench still alone), about half the wall time on 2 cores.
JOBS ?= 1
pages: $(VENV)/.bench-extra
	$(BIN)/python -m tools.pages --jobs $(JOBS)

pages-quick: $(VENV)/.bench-extra
	$(BIN)/python -m tools.pages --quick

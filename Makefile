# Two commands do all set-up on a fresh machine (Python >= 3.11 and pip):
#   make demo   install, then match the bundled sample trace on the embedded network
#   make test   install the dev extras, then lint, type-check and run the whole test suite
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP_RUN := $(VENV)/.installed-run
STAMP_DEV := $(VENV)/.installed-dev

.PHONY: demo test lint pytest install install-dev bench clean clean-kernels

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# After installing, `mapmatch network build` caches the embedded network and compiles the
# matcher's kernels for every kind of input into numba's on-disk cache (a few minutes, once per
# install), so that the first match of every later process starts in a fraction of a second.
$(STAMP_RUN): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[viz]"
	$(BIN)/mapmatch network build
	touch $@

$(STAMP_DEV): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	$(BIN)/mapmatch network build
	touch $@ $(STAMP_RUN)

install: $(STAMP_RUN)
install-dev: $(STAMP_DEV)

demo: $(STAMP_RUN)
	$(BIN)/mapmatch match mapmatch/data/sample_trace.csv --out demo-out --format geojson

lint: $(STAMP_DEV)
	$(BIN)/ruff format --check .
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/lint-imports

pytest: $(STAMP_DEV)
	$(BIN)/python -m pytest

test: lint pytest

bench: $(STAMP_DEV)
	$(BIN)/python benchmarks/bench_network.py
	$(BIN)/python benchmarks/bench_match.py

clean:
	rm -rf $(VENV) demo-out .pytest_cache .mypy_cache .ruff_cache

# numba's on-disk cache of a kernel is keyed by its own file only: after editing a compiled
# function that kernels in other files call, drop the caches (the next match recompiles)
clean-kernels:
	find mapmatch roadnets -name '*.nbi' -delete -o -name '*.nbc' -delete

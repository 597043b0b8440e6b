PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test test-fast lint bench fuzz clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e ".[test,dask,view,export,peers]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/undertow demo --out results

# three pytest-xdist workers on the two cores: the real-time tests (SITL, the autopilot, the
# live links) wait on the clock much of their time, and a numba kernel two workers need at once
# is compiled by one of them (tests/conftest.py); the tests of one xdist_group (the study, SITL,
# a live module with module fixtures) stay on one worker (pytest < 9.2, see pyproject.toml)
test: $(STAMP)
	$(BIN)/pytest -n 3 --dist loadgroup

# the inner loop: everything but the tests marked slow (two workers: these wait on no clock;
# about 2 minutes on this machine)
test-fast: $(STAMP)
	$(BIN)/pytest -n 2 --dist loadgroup -m "not slow"

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples
	$(BIN)/ruff format --check src tests benchmarks examples

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py $(ONLY)

# the readers' fuzzing campaign (docs/reliability.md): N mutated inputs through `undertow info`
fuzz: $(STAMP)
	$(BIN)/python fuzz/run.py --inputs $(or $(N),10000) --seed $(or $(SEED),0) --jobs $(or $(JOBS),2)

clean:
	rm -rf $(VENV) results

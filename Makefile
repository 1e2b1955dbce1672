# Two commands on a fresh machine: `make demo` runs the main job, `make test` the fast
# tests (in-process, a few minutes); `make test-all` runs every test, as CI does.
# The virtualenv is created once in .venv and reused (pin, for the simulator, is a
# ~700 MB wheel set); `make setup` re-installs when pyproject.toml or setup.py change.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo teach test test-all lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml setup.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[learn,sim,dev,view,inputs,logs,ros,ros2,cluster,franky]'
	touch $(STAMP)

demo: setup
	$(BIN)/sctd demo --skill skills/pour.yaml --seconds 40

# Teach 10 pours in the simulator, have the learner train a vector-field skill, check it,
# swap it into the running daemon, then evaluate it next to the shipped one.
teach: setup
	$(BIN)/sctd teach --task pour --then-learn vf --swap --out $$(mktemp -d)/pour-taught

# The tiers (tests/tiers.py): the fast tier is every test not marked slow; it starts no
# process, and runs on $(JOBS) workers. test-all runs every test that does not need the
# wall clock to itself on $(JOBS) workers too, a module to a worker (--dist loadscope:
# a module's shared daemon is started once; the longest modules first, as tests/tiers.py
# collects them, not xdist's reordering by count), and then the tests marked realtime in one
# process, one at a time: they compare what runs at the wall clock's pace (a trial, a
# router restart across hosts), and two of them side by side on this 2-core machine
# miss deadlines they are there to keep.
JOBS ?= 2
PYTEST := $(BIN)/python -m pytest -q

test: setup
	$(PYTEST) -m "not slow" -n $(JOBS)

test-all: setup
	$(PYTEST) -m "not realtime" -n $(JOBS) --dist loadscope --no-loadscope-reorder --durations=15; a=$$?; \
	$(PYTEST) -m realtime -p no:xdist --durations=5; b=$$?; \
	test $$a -eq 0 -a $$b -eq 0

lint: setup
	$(BIN)/ruff check .
	$(BIN)/mypy sctd services sim
	$(BIN)/lint-imports
	$(BIN)/python tools/check_function_length.py

bench: setup
	$(BIN)/sctd bench latency

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache .hypothesis

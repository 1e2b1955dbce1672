# Two commands on a fresh machine: `make demo` runs the main job, `make test` the tests.
# The virtualenv is created once in .venv and reused (pin, for the simulator, is a
# ~700 MB wheel set); `make setup` re-installs when pyproject.toml or setup.py change.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo teach test lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml setup.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[learn,sim,dev,view,inputs,logs,ros]'
	touch $(STAMP)

demo: setup
	$(BIN)/sctd demo --skill skills/pour.yaml --seconds 40

# Teach 10 pours in the simulator, have the learner train a vector-field skill, check it,
# swap it into the running daemon, then evaluate it next to the shipped one.
teach: setup
	$(BIN)/sctd teach --scene pour --then-learn vf --swap --out $$(mktemp -d)/pour-taught

test: setup
	$(BIN)/python -m pytest -q

lint: setup
	$(BIN)/ruff check .
	$(BIN)/mypy sctd services sim
	$(BIN)/lint-imports

bench: setup
	$(BIN)/sctd bench latency

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache .hypothesis

# Two commands on a fresh machine:
#   make run    create .venv, install kalcal, run the main job on its built-in default
#   make test   create .venv, install kalcal with its test extras, run the test suite
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip install --quiet --disable-pip-version-check

.PHONY: run test test-slow bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.run-installed: pyproject.toml | $(BIN)/python
	$(PIP) -e .
	touch $@

$(VENV)/.test-installed: pyproject.toml | $(BIN)/python
	$(PIP) -e '.[test]'
	touch $@

run: $(VENV)/.run-installed
	$(BIN)/kalcal verify --out kalcal-out
	@echo "report: $(CURDIR)/kalcal-out/report.html"

test: $(VENV)/.test-installed
	$(BIN)/python -m pytest -n 2 -q

test-slow: $(VENV)/.test-installed
	$(BIN)/python -m pytest -n 2 -q -m slow

bench: $(VENV)/.test-installed
	$(PIP) -e '.[bench]'
	$(BIN)/python benchmarks/bench_montecarlo.py

clean:
	rm -rf $(VENV) kalcal-out .pytest_cache

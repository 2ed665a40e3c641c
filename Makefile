# Two entry points for a newcomer on a fresh machine (see README.md):
#   make demo   set everything up, start the default service, run the paper's experiment
#   make test   set everything up and run the whole test suite
#   make lint   ruff (lint and format) over the tree, mypy --strict over the modules pyproject.toml
#               lists, import-linter over the layers ([tool.importlinter] in pyproject.toml)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin

.PHONY: setup demo test lint clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml setup.py fxis_shm/shm/_ordered.c scripts/install-system-packages.sh
	bash scripts/install-system-packages.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,bench,aravis,genicam,record,foxglove,ros2]"
	touch $@

demo: setup
	$(BIN)/python bench/latency.py

test: setup lint
	$(BIN)/python -m pytest

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/lint-imports

clean:
	rm -rf $(VENV) build *.egg-info bench/results

# Two entry points for a newcomer on a fresh machine (see README.md):
#   make demo   set everything up, start the default service, run the paper's experiment
#   make test   set everything up and run the whole test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin

.PHONY: setup demo test clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml setup.py fxis_shm/_ordered.c scripts/install-system-packages.sh
	bash scripts/install-system-packages.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,bench,aravis,genicam,foxglove]"
	touch $@

demo: setup
	$(BIN)/python bench/latency.py

test: setup
	$(BIN)/python -m pytest

clean:
	rm -rf $(VENV) build *.egg-info bench/results

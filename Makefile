# Quick start:  make run   (install, then run the main job: dualarm reproduce -> reports/reproduction/report.md)
#               make test  (install, then run the test suite)
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin

.PHONY: install run test clean

install: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

run: install
	$(BIN)/dualarm reproduce

test: install
	$(BIN)/python -m pytest

clean:
	rm -rf $(VENV) recordings/*/ reports/*/ .pytest_cache

# Quick start:  make run   (install, then run the main job: dualarm reproduce -> reports/reproduction/report.md)
#               make test  (install, then run the test suite)
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin

.PHONY: install run test lint typecheck clean

install: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

run: install
	$(BIN)/dualarm reproduce

test: install
	$(BIN)/python -m pytest -n auto --dist loadfile

# ruff (lint and format) and mypy; CI runs this before the tests, pre-commit on every commit.
lint: install typecheck
	$(BIN)/ruff check pipeline tests examples robots tasks
	$(BIN)/ruff format --check pipeline tests examples robots tasks

# mypy cannot follow the editable install's import hook: build/typecheck/dualarm links to pipeline/.
typecheck: install
	mkdir -p build/typecheck
	ln -sfn ../../pipeline build/typecheck/dualarm
	$(BIN)/mypy

clean:
	rm -rf $(VENV) build recordings/*/ reports/*/ .pytest_cache .mypy_cache .ruff_cache viewers/foxglove/node_modules

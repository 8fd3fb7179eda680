# Quick start:  make run   (install, then run the main job: dualarm reproduce -> reports/reproduction/report.md)
#               make test  (install, then run the test suite)
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin

.PHONY: install run test lint typecheck docs clean

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

# ruff (lint and format), mypy and the layers (import-linter: an upward import fails); CI runs this
# before the tests, pre-commit on every commit.
lint: install typecheck
	$(BIN)/ruff check pipeline tests examples robots tasks
	$(BIN)/ruff format --check pipeline tests examples robots tasks
	$(BIN)/lint-imports

typecheck: install
	$(BIN)/mypy

# The documentation site (mkdocs.yml, docs/) into site/; strict, as CI builds it: a broken link,
# anchor or cross-reference, or any other warning, fails the build. (The two variables silence
# banners that Material and a plugin print about MkDocs 2; they are not warnings of the build.)
docs: install
	NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(BIN)/mkdocs build --strict --site-dir site

clean:
	rm -rf $(VENV) build site recordings/*/ reports/*/ .pytest_cache .mypy_cache .ruff_cache viewers/foxglove/node_modules

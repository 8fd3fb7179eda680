# Quick start:  make run        (install, then run the main job: dualarm reproduce -> reports/reproduction/report.md)
#               make test       (install, then run every test: both tiers, the viewers' too where Node.js is)
#               make test-fast  (the unit tier alone: no PyBullet world, Dask cluster, subprocess or viewer, no run recorded)
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin

# Foxglove Studio's packages, which tests/record/test_viewer_foxglove.py runs; npm's own record of an install
# (node_modules/.package-lock.json) is the stamp, so ``npm ci`` runs once per change of the lock file.
FOXGLOVE := viewers/foxglove
FOXGLOVE_STAMP := $(FOXGLOVE)/node_modules/.package-lock.json

.PHONY: install viewers run test test-fast lint typecheck docs clean

install: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

run: install
	$(BIN)/dualarm reproduce

viewers: $(FOXGLOVE_STAMP)

$(FOXGLOVE_STAMP): $(FOXGLOVE)/package-lock.json
	@if command -v npm >/dev/null; then \
		echo "npm ci --prefix $(FOXGLOVE)"; \
		npm ci --prefix $(FOXGLOVE) --loglevel=error >/dev/null && touch $@ \
			|| { rm -f $@; echo "warning: npm ci --prefix $(FOXGLOVE) failed: the Foxglove tests will be skipped" >&2; }; \
	else \
		echo "npm not found: the Foxglove viewer tests will be skipped (they need Node.js >= 20)"; \
	fi

# Every test, both tiers (pyproject.toml's markers; tests/tiers.py guards them).
test: install viewers
	$(BIN)/python -m pytest -n auto --dist loadfile

# The unit tier: what make test runs but the tests marked integration; pre-commit runs it.
test-fast: install
	$(BIN)/python -m pytest -n auto --dist loadfile -m "not integration"

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

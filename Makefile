# Two commands do everything on a fresh machine (idempotent; a second run skips what is done):
#   make repro   set up, then run the whole pipeline (dvc repro) at the scale in params.yaml
#   make test    set up, then lint and run the test suite
SHELL := /bin/bash
VENV := .venv
BIN := $(abspath $(VENV))/bin
export PATH := $(BIN):$(PATH)
export DVC_NO_ANALYTICS := 1
export PYTHONUNBUFFERED := 1
STAMP := $(VENV)/.installed-$(shell cat requirements.lock pyproject.toml 2>/dev/null | sha1sum | cut -c1-12)

.PHONY: setup system venv repro test lint bench learning-curve clean-venv

setup: system venv .dvc/config

system:
	@bash scripts/setup_system.sh

venv: $(STAMP)

$(STAMP): requirements.lock pyproject.toml
	@test -x $(BIN)/python || python3 -m venv $(VENV)
	# torch first and pinned: a looser spec pulls the multi-GB CUDA build (shared/PLATFORM.md)
	$(BIN)/python -m pip install -q --disable-pip-version-check torch==2.13.0
	$(BIN)/python -m pip install -q --disable-pip-version-check -c requirements.lock -e '.[dev]'
	@rm -f $(VENV)/.installed-*
	@touch $@

.dvc/config:
	$(BIN)/dvc init -q

repro: setup
	dvc repro

lint: setup
	ruff check src stages tests
	ruff format --check src stages tests

test: lint
	python -m pytest -q tests

bench: setup
	python -m clutterbench.bench

# cp_focal retrained on 1/4 and 1/2 of its training scenes (after dvc repro; ~1.5x its
# training time): reports/learning_curve/cp_focal.{md,csv,png}
learning-curve: setup
	python -m clutterbench.collapse.learning_curve cp_focal --fractions 0.25 0.5

clean-venv:
	rm -rf $(VENV)

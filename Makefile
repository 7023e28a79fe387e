# Two commands do everything on a fresh machine (idempotent; a second run skips what is done):
#   make repro   set up, then run the whole pipeline (dvc repro) at the scale in params.yaml
#   make test    set up, then lint and run the test suite
#   make shell   set up, then a bash with .venv activated (dvc, clutterbench, stages/*.py)
# torch: the pinned CPU build by default; a CUDA build for paper scale on a GPU, e.g.
#   make TORCH_SPEC=torch==2.13.0+cu128 TORCH_INDEX_URL=https://download.pytorch.org/whl/cu128 repro
# and train on it with CLUTTERBENCH_TRAIN_DEVICE=cuda (docs/platform.md)
SHELL := /bin/bash
VENV := .venv
BIN := $(abspath $(VENV))/bin
export PATH := $(BIN):$(PATH)
export DVC_NO_ANALYTICS := 1
export PYTHONUNBUFFERED := 1
# torch is installed first, alone: TORCH_SPEC from TORCH_INDEX_URL (default: the pinned CPU
# build from the ordinary index). Another choice gives another stamp, so `make` reinstalls.
TORCH_SPEC ?= torch==2.13.0
TORCH_INDEX_URL ?=
TORCH_PIP_ARGS := $(if $(TORCH_INDEX_URL),--index-url $(TORCH_INDEX_URL))
TORCH_CHOICE := $(if $(filter-out torch==2.13.0,$(TORCH_SPEC))$(TORCH_INDEX_URL),echo '$(TORCH_SPEC) $(TORCH_INDEX_URL)';)
STAMP := $(VENV)/.installed-$(shell ($(TORCH_CHOICE) cat requirements.lock pyproject.toml) 2>/dev/null | sha1sum | cut -c1-12)

.PHONY: setup system venv repro repro-full test lint bench learning-curve designs benchmark-scenes clean-venv shell

setup: system venv .dvc/config

system:
	@bash scripts/setup_system.sh

venv: $(STAMP)

$(STAMP): requirements.lock pyproject.toml
	@test -x $(BIN)/python || python3 -m venv $(VENV)
	# torch first and pinned: a looser spec pulls the multi-GB CUDA build (docs/platform.md)
	$(BIN)/python -m pip install -q --disable-pip-version-check $(TORCH_PIP_ARGS) '$(TORCH_SPEC)'
	$(BIN)/python -m pip install -q --disable-pip-version-check -c requirements.lock -e '.[dev]'
	@rm -f $(VENV)/.installed-*
	@touch $@

.dvc/config:
	$(BIN)/dvc init -q

repro: setup
	dvc repro

# The same with the opt-in conditions too (trials.opt_in: rows no headline figure reads, left
# out of `make repro`; their cost: docs/run-times.md). A dvc experiment, as any -S switch:
# params.yaml is left with trials.opt_in.run: true.
repro-full: setup
	dvc exp run -S trials.opt_in.run=true

# An interactive bash inside the environment (exit to leave); the same as
# `source .venv/bin/activate` in the shell you are in.
shell: setup
	@echo "clutterbench environment: $(abspath $(VENV)) (exit to leave)"
	@bash --rcfile <(cat ~/.bashrc 2>/dev/null; echo 'source $(abspath $(VENV))/bin/activate') -i

lint: setup
	ruff check src stages tests experiments
	ruff format --check src stages tests experiments

# params.yaml checked first (clutterbench check: every section at every scale, in a second or
# two, no data), so a typo fails here rather than in the stage that reads it, and the
# rechecks' experiments/params.yaml beside it (python -m experiments.check). Then two
# workers (pytest-xdist), a file each at a time: the tiny end-to-end repro (collected first)
# on one, every other file on the other.
test: lint
	clutterbench check
	python -m experiments.check
	python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder --durations=25 tests

bench: setup
	python -m clutterbench.bench

# After a whole `make repro`: the wall time each stage recorded (reports/timing/stages/), as the
# measured record reports/run_times/<scale>_<cpu>.{json,md}; the README's run-time table and
# docs/run-times.md's list of records are rewritten from them
.PHONY: run-times
run-times: setup
	python -m clutterbench.bench.run_times
	python -m clutterbench.readme

# Score a pull-consequence predictor (a Python file with predict(depth_m, masks, camera_K,
# pulled)) on the test set, the run's own or the published copy: set up, then
# clutterbench evaluate-predictor. One command on a fresh clone:
#   make score PREDICTOR=path/to/my_predictor.py
# Published-set scores are on trust (its labels are public); a trusted score draws new scenes
# from an unpublished seed and labels them on the spot: make score PREDICTOR=... FRESH=200
# On the sensed track (the same scenes, the depth through a sensor model): ... TRACK=d415
.PHONY: score
score: setup
	@test -n "$(PREDICTOR)" || { echo "make score: name the predictor: make score PREDICTOR=path/to/file.py" >&2; exit 2; }
	clutterbench evaluate-predictor "$(PREDICTOR)" $(if $(FRESH),--fresh $(FRESH)) $(if $(TRACK),--track $(TRACK))

# The README's generated blocks (results at a glance, the leaderboard, run times) rewritten from
# the committed files they quote (clutterbench.readme; a unit test fails while one is stale)
.PHONY: readme
readme: setup
	python -m clutterbench.readme

# Does this machine reproduce the recorded results? A tiny pipeline with 400 test scenes and
# 300 episodes each of multi_step and oracle in a temporary copy, compared statistically
# with reports/crosscheck/expected.json (docs/determinism.md); exit 1 when a rate differs.
.PHONY: crosscheck
crosscheck: setup
	python -m clutterbench.crosscheck

# cp_focal retrained on 1/4 and 1/2 of its training scenes (after dvc repro; ~1.5x its
# training time): reports/learning_curve/cp_focal.{md,csv,png}
learning-curve: setup
	python -m clutterbench.collapse.learning_curve cp_focal --fractions 0.25 0.5

# Collapse network designs at equal training time (params designs:; ~45 min at default
# scale on 2 free cores; needs split@ch6) -> reports/learning_curve/designs.{csv,md,png}
designs: setup
	python -m clutterbench.collapse.designs

include experiments/Makefile

# The benchmark scenes (data/benchmark/: every table's test-stream starts and targets, the
# same bytes on every CPU), regenerated for the tiny and default profiles. Never run by a
# stage: the new scenes are used once params.yaml pins the printed manifest hash.
benchmark-scenes: setup
	python -m clutterbench.cli.benchmark_scenes --scales tiny default

clean-venv:
	rm -rf $(VENV)

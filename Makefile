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

.PHONY: setup system venv repro test lint bench learning-curve designs dev-ch4-piles dev-ch5-planner dev-perturbed-fit dev-ch6-pull dev-ch6-pull-thresholds dev-ch6-pull-watch dev-ch6-no-plan dev-ch6-no-plan-thresholds dev-ch6-idle-hold dev-ch6-clear dev-ch6-hold dev-ch6-vs-pfd dev-ch6-box dev-ch6-box-physics dev-ch6-box-hold dev-ch6-fit-hypotheses dev-ch6-box-contact dev-ch6-box-cp-max dev-ch6-box-edge dev-ch6-release dev-box-head-data dev-box-physics-fusion benchmark-scenes clean-venv shell

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

# An interactive bash inside the environment (exit to leave); the same as
# `source .venv/bin/activate` in the shell you are in.
shell: setup
	@echo "clutterbench environment: $(abspath $(VENV)) (exit to leave)"
	@bash --rcfile <(cat ~/.bashrc 2>/dev/null; echo 'source $(abspath $(VENV))/bin/activate') -i

lint: setup
	ruff check src stages tests
	ruff format --check src stages tests

# params.yaml checked first (clutterbench check: every section at every scale, in a second or
# two, no data), so a typo fails here rather than in the stage that reads it. Then two
# workers (pytest-xdist), a file each at a time: the tiny end-to-end repro (collected first)
# on one, every other file on the other.
test: lint
	clutterbench check
	python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder --durations=25 tests

bench: setup
	python -m clutterbench.bench

# After a whole `make repro`: the wall time each stage recorded (reports/timing/stages/), as the
# measured record reports/run_times/<scale>_<cpu>.{json,md}, and the README's run-time table from them
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
.PHONY: score
score: setup
	@test -n "$(PREDICTOR)" || { echo "make score: name the predictor: make score PREDICTOR=path/to/file.py" >&2; exit 2; }
	clutterbench evaluate-predictor "$(PREDICTOR)" $(if $(FRESH),--fresh $(FRESH))

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

# The ch. 4 training piles rechecked on dev streams (params dev.ch4_piles; ~30 min at default
# scale on 2 free cores): a network per pile range, the risk planner on each dev stream ->
# reports/dev/ch4_piles.{json,md}; scratch data and networks in data/dev/ch4_piles/
dev-ch4-piles: setup
	python -m clutterbench.dev.ch4_piles

# How the ch. 5 planner carries a blocker, rechecked on dev streams (params dev.ch5_planner;
# ~7 min at default scale on 2 cores, after dvc repro of trials_ch5's upstream): each
# variant of trials.ch5's blocker_goal / upright_footprint, the thesis' planner and the one
# that may push (contact), with the detector's and the true clusters, and its oracle
# -> reports/dev/ch5_planner.{json,md}
dev-ch5-planner: setup
	python -m clutterbench.dev.ch5_planner

# No box fit raises out of a stage: both physics-from-depth planners and Table
# 6.2's row on dev scenes of the 3-10 stream with noisy depth (params dev.perturbed_fit; no
# network needed) -> reports/dev/perturbed_fit.{json,md}
dev-perturbed-fit: setup
	python -m clutterbench.dev.perturbed_fit

# What the ch. 6 pull planners do after an abort: trials.ch6.abort_response block vs
# learn for each planner of dev.ch6_pull.planners and both oracles on dev scenes of the 3-10
# stream (reads the support stage's thresholds) -> reports/dev/ch6_pull.{json,md}
dev-ch6-pull: setup
	python -m clutterbench.dev.ch6_pull

# The pull-head CP planners' thresholds: trials.ch6.pull_prob_threshold and
# pull_score_threshold, each variant of dev.ch6_pull_thresholds on dev scenes of the 3-10 stream
# -> reports/dev/ch6_pull_thresholds.{json,md}
dev-ch6-pull-thresholds: setup
	python -m clutterbench.dev.ch6_pull ch6_pull_thresholds

# The pull-head CP planners watching their pull in depth: trials.ch6.pull_watch_m,
# each variant of dev.ch6_pull_watch on dev scenes of the 3-10 stream
# -> reports/dev/ch6_pull_watch.{json,md}
dev-ch6-pull-watch: setup
	python -m clutterbench.dev.ch6_pull ch6_pull_watch

# What the pull planners do when their rule rejects every candidate:
# trials.ch6.when_no_plan, each variant of dev.ch6_no_plan on dev scenes of the 3-10 stream
# -> reports/dev/ch6_no_plan.{json,md}
dev-ch6-no-plan: setup
	python -m clutterbench.dev.ch6_pull ch6_no_plan

# The pull-head CP planners' thresholds once a decision that rejects every candidate pulls the
# least risky one: each variant of dev.ch6_no_plan_thresholds on dev scenes of the
# 3-10 stream -> reports/dev/ch6_no_plan_thresholds.{json,md}
dev-ch6-no-plan-thresholds: setup
	python -m clutterbench.dev.ch6_pull ch6_no_plan_thresholds

# The bimanual pull planners' idle arm: trials.ch6.idle_hold_share, each variant of
# dev.ch6_idle_hold on dev scenes of the 3-10 stream -> reports/dev/ch6_idle_hold.{json,md}
dev-ch6-idle-hold: setup
	python -m clutterbench.dev.ch6_pull ch6_idle_hold

# Whose shares the pull planners' collapse score takes, and clearing around a rejected plan
#: trials.ch6.score_over and when_no_plan clear, each variant of dev.ch6_clear on
# dev scenes of the 3-10 stream -> reports/dev/ch6_clear.{json,md}
dev-ch6-clear: setup
	python -m clutterbench.dev.ch6_pull ch6_clear

# How the bimanual pull planners score and choose a held pull: trials.ch6.truth_hold
# and hold_feared, each variant of dev.ch6_hold on dev scenes of the 3-10 stream
# -> reports/dev/ch6_hold.{json,md}
dev-ch6-hold: setup
	python -m clutterbench.dev.ch6_pull ch6_hold

# The pull-head CP planners against physics from depth, the params' own
# settings, on more dev scenes than a table has -> reports/dev/ch6_vs_pfd.{json,md}
dev-ch6-vs-pfd: setup
	python -m clutterbench.dev.ch6_pull ch6_vs_pfd

dev-ch6-box: setup
	python -m clutterbench.dev.ch6_pull ch6_box

# The learned-plus-physics planners against physics from depth, episode by episode (each
# decision simulates the pulls the box head is unsure of): reports/dev/ch6_box_physics.md
dev-ch6-box-physics: setup
	python -m clutterbench.dev.ch6_pull ch6_box_physics

# How the learned-plus-physics bimanual planner scores a pull made holding a box
# (trials.ch6.box_hold): the held box left out, or the held pull simulated on the fitted boxes
# -> reports/dev/ch6_box_hold.{json,md}
dev-ch6-box-hold: setup
	python -m clutterbench.dev.ch6_pull ch6_box_hold

# How many scenes the learned-plus-physics planners fit to one observation (trials.ch6
# fit_hypotheses, fit_noise_mm), each variant's fusion chosen again on the support stage's val
# scenes -> reports/dev/ch6_fit_hypotheses.{json,md}
dev-ch6-fit-hypotheses: setup
	python -m clutterbench.dev.ch6_pull ch6_fit_hypotheses

# The contact in the learned-plus-physics planners' support edges (trials.ch6.box_contact): the
# box head's, or learned from it and the fitted scenes' contacts, each variant's fusion chosen
# again on the support stage's val scenes -> reports/dev/ch6_box_contact.{json,md}
dev-ch6-box-contact: setup
	python -m clutterbench.dev.ch6_pull ch6_box_contact

# The collapse score over which the learned-plus-physics planners reject or stop a pull
# (trials.ch6.box_cp_max): the support stage's outcome threshold or lower
# -> reports/dev/ch6_box_cp_max.{json,md}
dev-ch6-box-cp-max: setup
	python -m clutterbench.dev.ch6_pull ch6_box_cp_max

# The learned-plus-physics planners' support graph (trials.ch6.box_contact, box_edge_precision):
# the support stage's, or the learned contact at the most recall for 0.90 precision on val
# -> reports/dev/ch6_box_edge.{json,md}
dev-ch6-box-edge: setup
	python -m clutterbench.dev.ch6_pull ch6_box_edge

# How the ch. 6 executor lets go of an aborted pull's box and of a held box (trials.ch6
# abort_release, held_release), the oracles under each variant too: reports/dev/ch6_release.md
dev-ch6-release: setup
	python -m clutterbench.dev.ch6_pull ch6_release

# What the box head learns from (after box_head): the stage's train scenes, all of them,
# val scenes its collapse predictor never trained on, more width; each scored on the stage's
# val scenes -> reports/dev/box_head_data.md
dev-box-head-data: setup
	python -m clutterbench.dev.box_head_data

# The box head and physics from depth fused per box (after box_head): each alone and fused,
# cross-fitted over two halves of the box head's val scenes -> reports/dev/box_physics_fusion.md
dev-box-physics-fusion: setup
	python -m clutterbench.dev.box_physics_fusion

# The benchmark scenes (data/benchmark/: every table's test-stream starts and targets, the
# same bytes on every CPU), regenerated for the tiny and default profiles. Never run by a
# stage: the new scenes are used once params.yaml pins the printed manifest hash.
benchmark-scenes: setup
	python -m clutterbench.cli.benchmark_scenes --scales tiny default

clean-venv:
	rm -rf $(VENV)

"""Honest DVC graph: every module a stage imports is one of its deps, and the stages that
only read configs (split, train, evaluate, report) do not load SAPIEN."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
STAGES = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
NO_SAPIEN = {"split", "train", "evaluate", "report"}

PROBE = """
import importlib.util, json, sys
spec = importlib.util.spec_from_file_location("stage", sys.argv[1])
spec.loader.exec_module(importlib.util.module_from_spec(spec))
files = [m.__file__ for k, m in sys.modules.items() if k.startswith("clutterbench") and m.__file__]
print(json.dumps({"files": files, "sapien": "sapien" in sys.modules}))
"""


def imported(stage: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", PROBE, str(ROOT / "stages" / f"{stage}.py")],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_stage_deps_cover_its_imports(stage):
    body = STAGES[stage].get("do", STAGES[stage])
    deps = [str(d).split("$")[0] for d in body["deps"]]
    got = imported(stage)
    missing = []
    for f in got["files"]:
        rel = str(Path(f).resolve().relative_to(ROOT))
        if rel.endswith("__init__.py"):
            continue  # package markers, no logic
        if not any(rel == d or rel.startswith(d.rstrip("/") + "/") for d in deps):
            missing.append(rel)
    assert not missing, f"{stage} imports modules its dvc deps do not list: {missing}"
    if stage in NO_SAPIEN:
        assert not got["sapien"], f"{stage} imports SAPIEN"


CHAPTER_STAGES = {
    "trials/ch3": {"trials_ch3"},
    "planning/ch3": {"trials_ch3"},
    "trials/ch4": {"trials_ch4", "trials_arm"},
    # the thesis' single-step row of Table 6.3 is ch. 4's planner
    "planning/ch4": {"trials_ch4", "trials_arm", "trials", "noise"},
    "trials/ch5": {"trials_ch5"},
    "planning/ch5": {"trials_ch5"},
    "trials/ch6": {"trials", "trials_arm", "noise"},
    "planning/ch6": {"trials", "trials_arm", "noise"},
    "trials/arm": {"trials_arm"},
    "trials/noise": {"noise"},
}
"""A chapter's code -> the stages an edit of it reruns (the arm-level stage executes ch. 4's and
ch. 6's steps; the noise stage replays ch. 6's episodes and runs its search oracles). Table
6.2's support stage also reads ch. 6's support rule, named below, and so does the box head
(stages box_head, box_head_sensed and testset, which scores it); none of them reads the
trials' code (the support layer stands below the trials: its physics-from-depth model is
perception's)."""
SUPPORT_READS = {"planning/ch6/support.py"}
BOX_HEAD_READS = {"planning/ch6/support.py"}
REPORT_READS = "trials/ch6/planners/"
"""The report reads the ch. 6 planners' declarations (their labels, ceilings, truth rows and
baselines), which live in each planner's module."""


def stages_depending_on(path: str) -> set[str]:
    """The stages one of whose deps is `path` or a folder above it."""
    out = set()
    for name, stage in STAGES.items():
        body = stage.get("do", stage)
        for d in body["deps"]:
            d = str(d).rstrip("/")
            if "$" not in d and (path == d or path.startswith(d + "/")):
                out.add(name)
    return out


@pytest.mark.parametrize("chapter", sorted(CHAPTER_STAGES))
def test_an_edit_of_one_chapter_reruns_only_its_stages(chapter):
    files = sorted((ROOT / "src" / "clutterbench" / chapter).rglob("*.py"))
    assert files, f"no chapter code in {chapter}"
    for f in files:
        rel = str(f.relative_to(ROOT / "src" / "clutterbench"))
        want = CHAPTER_STAGES[chapter] | ({"support"} if rel in SUPPORT_READS else set())
        want |= {"box_head", "box_head_sensed", "testset"} if rel in BOX_HEAD_READS else set()
        want |= {"report"} if rel.startswith(REPORT_READS) else set()
        got = stages_depending_on(f"src/clutterbench/{rel}")
        assert got == want, f"an edit of {rel} reruns {sorted(got)}, not {sorted(want)}"

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

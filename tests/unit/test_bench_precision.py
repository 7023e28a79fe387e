"""The fp32-vs-bf16 comparison reads the committed outputs and the working tree's."""

from __future__ import annotations

import json
import subprocess

import pytest

from clutterbench.bench.precision import main
from clutterbench.crosscheck import two_proportion_p


def _write(root, rel, obj):
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj) if not isinstance(obj, str) else obj)


def _summary(k, n, sk, sn, cond="multi_step"):
    keys = ("success_k", "success_n", "step_success_k", "step_success_n")
    return {"condition": cond} | dict(zip(keys, (k, n, sk, sn), strict=True))


def _metrics(iou, prec):
    keys = ("iou", "precision", "recall", "iou_at_val_chosen", "val_chosen_threshold")
    return dict(zip(keys, (iou, 0.8, 0.5, iou + 0.1, 0.4), strict=True)) | {
        "network_precision": prec
    }


@pytest.fixture
def repo(tmp_path):
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path)]
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    _write(tmp_path, "reports/trials/multi_step/summary.json", _summary(96, 200, 196, 297))
    _write(tmp_path, "reports/trials/oracle/summary.json", _summary(127, 200, 200, 270, "oracle"))
    _write(tmp_path, "reports/evaluate/cp/metrics.json", _metrics(0.45, "bf16"))
    csv = "scene,method,precision,recall\n0,cp,1.0,0.5\n1,cp,0.5,1.0\n2,cp,1.0,1.0\n"
    _write(tmp_path, "reports/support/scenes.csv", csv)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "bf16"], check=True)
    return tmp_path


def test_nothing_changed_is_said_and_fails(repo, capsys):
    assert main(["--root", str(repo)]) == 1
    assert "nothing to compare" in capsys.readouterr().out


def test_changed_outputs_are_compared_and_unchanged_left_out(repo):
    _write(repo, "reports/trials/multi_step/summary.json", _summary(110, 200, 205, 290))
    _write(repo, "reports/evaluate/cp/metrics.json", _metrics(0.47, "fp32"))
    csv = "scene,method,precision,recall\n0,cp,1.0,1.0\n1,cp,0.5,1.0\n2,cp,1.0,1.0\n"
    _write(repo, "reports/support/scenes.csv", csv)
    assert main(["--root", str(repo)]) == 0
    out = json.loads((repo / "reports/bench/precision.json").read_text())
    (trial,) = out["trials"]  # the oracle's summary did not change
    assert trial["condition"] == "multi_step"
    assert trial["success"] == [[96, 200], [110, 200]]
    assert trial["success_p"] == pytest.approx(two_proportion_p(96, 200, 110, 200))
    (ev,) = out["evaluation"]
    assert ev["network"] == ["bf16", "fp32"] and ev["iou"] == [0.45, 0.47]
    assert ev["precision"] == [0.8, 0.8]  # the pixel precision, not the arithmetic
    (sup,) = out["support"]
    assert sup["recall"] == [pytest.approx(2.5 / 3), 1.0]
    assert sup["precision_diff_ci"] == [0.0, 0.0]  # the same precision on every scene
    md = (repo / "reports/bench/precision.md").read_text()
    assert "96/200 = 48.0%" in md and "110/200 = 55.0%" in md and "oracle" not in md

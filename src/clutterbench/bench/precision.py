"""Do two runs of the networks' stages give statistically the same tables? (docs/determinism.md)

`make crosscheck` asks that of the data; this asks it of the networks: fp32 against bf16
networks, or the whole pipeline rerun on another CPU. Run the networks' stages on this machine
(e.g. `dvc repro evaluate@cp_focal_ch6_test support` with `precision: auto` on a CPU that
resolves it to fp32, or a whole `make repro`), then compare the outputs in the working tree
with those committed at a git revision (made in the other precision, or on the other CPU):

    python -m clutterbench.bench.precision --against HEAD [--out reports/bench]

Compared, for whatever both sides have: each model's training summary (best epoch, val
scores), each evaluation's pixel scores (Table 5.1 / 6.1 rows), Table 6.2's per-scene
support precision / recall (paired: the test scenes are the same), and each trials
condition's episode and step success (Wilson 95% intervals, two-proportion z-test). Writes
precision.{json,md} into --out (default reports/bench).
"""

from __future__ import annotations

import argparse
import io
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.bench import header, write_result
from clutterbench.crosscheck import Z95, two_proportion_p, wilson_interval
from clutterbench.platform_info import cpu_description

EVAL_KEYS = ("iou", "precision", "recall", "iou_at_val_chosen", "val_chosen_threshold")
TRAIN_KEYS = ("val_iou", "val_precision", "val_recall", "val_loss")


def committed(root: Path, rev: str, path: str) -> str | None:
    """The text of `path` at git revision `rev`, None where it is not there."""
    out = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=root, capture_output=True, text=True)
    return out.stdout if out.returncode == 0 else None


def _json(text: str | None) -> dict[str, Any] | None:
    return None if text is None else json.loads(text)


def _pairs(root: Path, rev: str, pattern: str) -> dict[str, tuple[str | None, str]]:
    """Working-tree files matching `pattern` -> (committed text, new text)."""
    return {
        str(p.relative_to(root)): (committed(root, rev, str(p.relative_to(root))), p.read_text())
        for p in sorted(root.glob(pattern))
    }


def training_rows(root: Path, rev: str) -> list[dict[str, Any]]:
    rows = []
    for old, new in _pairs(root, rev, "reports/train/*/summary.json").values():
        a, b = _json(old), _json(new)
        if a is None or a == b:
            continue  # nothing committed to compare with, or not rerun
        # summaries before precision was recorded came from bf16 runs (train.bf16: true)
        row = {"model": b["model"], "network": [a.get("precision", "bf16"), b["precision"]]}
        row["best_epoch"] = [a["best"]["epoch"], b["best"]["epoch"]]
        row |= {k: [a["best"][k], b["best"][k]] for k in TRAIN_KEYS}
        rows.append(row)
    return rows


def evaluation_rows(root: Path, rev: str) -> list[dict[str, Any]]:
    rows = []
    for path, (old, new) in _pairs(root, rev, "reports/evaluate/*/metrics.json").items():
        a, b = _json(old), _json(new)
        if a is None or a == b:
            continue
        was = a.get("network_precision", "bf16")  # before it was recorded: bf16 inference
        row = {"run": Path(path).parent.name, "network": [was, b["network_precision"]]}
        row |= {k: [a[k], b[k]] for k in EVAL_KEYS}
        rows.append(row)
    return rows


def support_rows(root: Path, rev: str) -> list[dict[str, Any]]:
    """Per method: mean precision / recall over the same test scenes, and the paired mean
    difference new - old with its 95% interval."""
    old = committed(root, rev, "reports/support/scenes.csv")
    new_path = root / "reports/support/scenes.csv"
    if old is None or not new_path.exists() or new_path.read_text() == old:
        return []
    key = ["scene", "method"]
    a = pd.read_csv(io.StringIO(old)).set_index(key)
    b = pd.read_csv(new_path).set_index(key)
    both = a.join(b, lsuffix="_old", rsuffix="_new", how="inner")
    rows = []
    for method, g in both.groupby(level="method", sort=False):
        row: dict[str, Any] = {"method": method, "scenes": len(g)}
        for m in ("precision", "recall"):
            pair = g[[f"{m}_old", f"{m}_new"]].dropna()
            diff = pair[f"{m}_new"] - pair[f"{m}_old"]
            half = Z95 * float(diff.std(ddof=1)) / math.sqrt(len(diff)) if len(diff) > 1 else 0.0
            row[m] = [float(pair[f"{m}_old"].mean()), float(pair[f"{m}_new"].mean())]
            row[f"{m}_diff_ci"] = [float(diff.mean()) - half, float(diff.mean()) + half]
        rows.append(row)
    return rows


def trial_rows(root: Path, rev: str) -> list[dict[str, Any]]:
    rows = []
    for old, new in _pairs(root, rev, "reports/trials/*/summary.json").values():
        a, b = _json(old), _json(new)
        if a is None or a == b:
            continue
        row: dict[str, Any] = {"condition": b["condition"]}
        for kind in ("success", "step_success"):
            k1, n1, k2, n2 = (a[f"{kind}_k"], a[f"{kind}_n"], b[f"{kind}_k"], b[f"{kind}_n"])
            row[kind] = [[k1, n1], [k2, n2]]
            row[f"{kind}_p"] = two_proportion_p(k1, n1, k2, n2)
        rows.append(row)
    return rows


def _share(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{k}/{n} = {100 * k / n:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"


def markdown(result: dict[str, Any]) -> list[str]:
    lines = header("Two runs of the networks: the same tables statistically?", result)
    lines += [
        f"Committed outputs at `{result['against']}` (old) against this working tree (new), for "
        "example fp32 against bf16 networks, or a run on another CPU. Only outputs that differ "
        "are listed.",
        "",
    ]
    if result["training"]:
        lines += [
            "## Training (best epoch by val loss)",
            "",
            "| model | network old -> new | best epoch | val IoU | val precision | val recall |",
            "|---|---|---|---|---|---|",
        ]
        for r in result["training"]:
            cells = [f"{r[k][0]:.3f} -> {r[k][1]:.3f}" for k in TRAIN_KEYS[:3]]
            lines.append(
                f"| {r['model']} | {' -> '.join(r['network'])} | "
                f"{r['best_epoch'][0]} -> {r['best_epoch'][1]} | " + " | ".join(cells) + " |"
            )
        lines.append("")
    if result["evaluation"]:
        lines += [
            "## Evaluation (Tables 5.1 / 6.1; scores at 0.5 and at the val-chosen threshold)",
            "",
            "| run | network old -> new | " + " | ".join(EVAL_KEYS) + " |",
            "|---|---|" + "---|" * len(EVAL_KEYS),
        ]
        for r in result["evaluation"]:
            cells = [r["run"], " -> ".join(r["network"])]
            cells += [f"{r[k][0]:.3f} -> {r[k][1]:.3f}" for k in EVAL_KEYS]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    if result["support"]:
        lines += [
            "## Table 6.2 support (same test scenes; paired difference new - old, 95%)",
            "",
            "| method | scenes | precision | diff | recall | diff |",
            "|---|---|---|---|---|---|",
        ]
        for r in result["support"]:
            p, rc = r["precision"], r["recall"]
            pd_, rd = r["precision_diff_ci"], r["recall_diff_ci"]
            lines.append(
                f"| {r['method']} | {r['scenes']} | {p[0]:.3f} -> {p[1]:.3f} | "
                f"[{pd_[0]:+.3f}, {pd_[1]:+.3f}] | {rc[0]:.3f} -> {rc[1]:.3f} | "
                f"[{rd[0]:+.3f}, {rd[1]:+.3f}] |"
            )
        lines.append("")
    if result["trials"]:
        lines += [
            "## Trials (Wilson 95%; p: two-proportion z-test)",
            "",
            "| condition | episodes old | episodes new | p | steps old | steps new | p |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in result["trials"]:
            (a, b), (c, d) = r["success"], r["step_success"]
            lines.append(
                f"| {r['condition']} | {_share(*a)} | {_share(*b)} | {r['success_p']:.2f} | "
                f"{_share(*c)} | {_share(*d)} | {r['step_success_p']:.2f} |"
            )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m clutterbench.bench.precision")
    parser.add_argument("--against", default="HEAD", help="git revision of the old outputs")
    parser.add_argument("--root", type=Path, default=Path("."), help="repository root")
    parser.add_argument(
        "--out", type=Path, default=Path("reports/bench"), help="folder of the report (in root)"
    )
    args = parser.parse_args(argv)
    root = args.root.resolve()
    result: dict[str, Any] = {
        "against": args.against,
        **cpu_description(),
        "training": training_rows(root, args.against),
        "evaluation": evaluation_rows(root, args.against),
        "support": support_rows(root, args.against),
        "trials": trial_rows(root, args.against),
    }
    if not any(result[k] for k in ("training", "evaluation", "support", "trials")):
        print("precision: no output differs from the committed one; nothing to compare")
        return 1
    write_result(root / args.out, "precision", result, markdown(result))
    print("\n".join(markdown(result)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

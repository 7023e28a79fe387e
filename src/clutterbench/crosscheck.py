"""`make crosscheck`: does this machine reproduce the recorded results, statistically?

In a temporary copy of the repository (as the smoke test makes one) at base.scale=tiny, with
more test scenes and episodes than tiny has (SCENES, EPISODES), it runs
`dvc repro generate@ch6_test` and the trials stage(s) of multi_step and oracle (and what they
need upstream: the ch6 and ch4_various datasets, their splits, cp_focal and ch4_various,
support), then
compares against reports/crosscheck/expected.json:

- ch6_test's family shares (count / scenes) and rejection shares per reason
  (rejections / attempts, attempts = scenes + rejections),
- ch6_test's mean number of objects per scene,
- the per-episode success k/n of the trials multi_step and oracle.

Test: each share is compared with a two-sided two-proportion z-test (pooled), the mean with
a two-sample z-test; a row fails when p < ALPHA / m over its m rows (Bonferroni), so on a
machine that reproduces the results statistically the whole check fails with probability
<= ALPHA = 1%. The Wilson 95% intervals are printed beside. Exit code 0 when every row
passes, 1 otherwise, 2 when the pipeline itself failed. Whether the outputs were
byte-identical to the recorded ones is reported too (expected on the same CPU model with the
same torch thread count), but does not change the exit code.

`python -m clutterbench.crosscheck --record` runs the same and writes the expectations.
The result goes to reports/crosscheck/result.json.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from clutterbench.io import load_npz, read_json, write_json
from clutterbench.platform_info import environment, instruction_set

SCENES = 400  # ch6_test scenes (tiny: 3)
EPISODES = 300  # episodes of multi_step and of oracle (tiny: 2)
DATASET = "ch6_test"
CONDITIONS = ("multi_step", "oracle")
ALPHA = 0.01  # family-wise: Bonferroni over the compared rows
Z95 = 1.959963984540054
COPY = [
    "dvc.yaml",
    "params.yaml",
    "stages",
    "src",
    "reports/thesis_figures.yaml",
    "data/benchmark",
]
# Outputs whose bytes are compared with the recorded ones (md5 over every file).
DIGESTED = [
    "data/generate/ch6",
    "data/generate/ch4_various",
    f"data/generate/{DATASET}",
    "models/cp_focal",
    "models/ch4_various",
    "data/support",
    "reports/support/thresholds.json",
    *(f"data/trials/{c}" for c in CONDITIONS),
    *(f"reports/trials/{c}/records.jsonl" for c in CONDITIONS),
]
EXPECTED = Path("reports/crosscheck/expected.json")
RESULT = Path("reports/crosscheck/result.json")


# --- statistics -------------------------------------------------------------------------


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of k/n; (nan, nan) when n == 0."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def two_proportion_p(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided p-value of the pooled two-proportion z-test of k1/n1 against k2/n2 (1.0
    when the pooled share is 0 or 1: both samples agree exactly)."""
    pooled = (k1 + k2) / (n1 + n2)
    se = math.sqrt(pooled * (1 - pooled) * (1 / n1 + 1 / n2))
    if se == 0:
        return 1.0
    z = (k2 / n2 - k1 / n1) / se
    return math.erfc(abs(z) / math.sqrt(2))


def two_mean_p(m1: float, s1: float, n1: int, m2: float, s2: float, n2: int) -> float:
    """Two-sided p-value of the two-sample z-test of two means (sample SDs s1, s2)."""
    se = math.sqrt(s1 * s1 / n1 + s2 * s2 / n2)
    if se == 0:
        return 1.0 if m1 == m2 else 0.0
    return math.erfc(abs(m2 - m1) / se / math.sqrt(2))


@dataclass
class Row:
    name: str
    expected: str
    got: str
    p: float
    passed: bool = True


def _share(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{k}/{n} = {100 * k / n:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"


def _mean(m: dict) -> str:
    half = Z95 * m["sd"] / math.sqrt(m["n"])
    return f"{m['mean']:.3f} +- {half:.3f} (n={m['n']})"


def compare(expected: dict, got: dict, alpha: float = ALPHA) -> list[Row]:
    """One row per compared quantity of two measure() results; a row passes when its p-value
    is >= alpha / (number of rows)."""
    rows: list[Row] = []
    e, g = expected["dataset"], got["dataset"]
    for fam in sorted(set(e["families"]) | set(g["families"])):
        k1, k2 = e["families"].get(fam, 0), g["families"].get(fam, 0)
        n1, n2 = e["n_scenes"], g["n_scenes"]
        p = two_proportion_p(k1, n1, k2, n2)
        rows.append(Row(f"{DATASET} family {fam} / scenes", _share(k1, n1), _share(k2, n2), p))
    for reason in sorted(set(e["rejected"]) | set(g["rejected"])):
        k1, k2 = e["rejected"].get(reason, 0), g["rejected"].get(reason, 0)
        n1, n2 = e["attempts"], g["attempts"]
        p = two_proportion_p(k1, n1, k2, n2)
        rows.append(
            Row(f"{DATASET} rejected '{reason}' / attempts", _share(k1, n1), _share(k2, n2), p)
        )
    m1, m2 = e["n_objects"], g["n_objects"]
    p = two_mean_p(m1["mean"], m1["sd"], m1["n"], m2["mean"], m2["sd"], m2["n"])
    rows.append(Row(f"{DATASET} objects per scene (mean)", _mean(m1), _mean(m2), p))
    for cond in sorted(set(expected["trials"]) | set(got["trials"])):
        t1 = expected["trials"].get(cond, {"k": 0, "n": 0})
        t2 = got["trials"].get(cond, {"k": 0, "n": 0})
        if t1["n"] == 0 or t2["n"] == 0:
            rows.append(Row(f"trials {cond} success", str(t1), str(t2), 0.0))
            continue
        p = two_proportion_p(t1["k"], t1["n"], t2["k"], t2["n"])
        rows.append(
            Row(
                f"trials {cond} episode success",
                _share(t1["k"], t1["n"]),
                _share(t2["k"], t2["n"]),
                p,
            )
        )
    for row in rows:
        row.passed = row.p >= alpha / len(rows)
    return rows


# --- running the pipeline ---------------------------------------------------------------


def _env() -> dict[str, str]:
    return {
        **os.environ,
        "DVC_NO_ANALYTICS": "1",
        "PATH": f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}",
    }


def copy_pipeline(root: Path, dst: Path, scale: str = "tiny", cores: int | None = None) -> Path:
    """A copy of the repository's pipeline (dvc.yaml, params.yaml, stages, src, the thesis
    figures) at base.scale=`scale` (and base.cores=`cores` unless None), dvc-initialised
    without git: what the smoke test and the crosscheck reproduce."""
    dst.mkdir(parents=True)
    for item in COPY:
        src = root / item
        if not src.exists():  # data/benchmark before its first make benchmark-scenes
            continue
        (dst / item).parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst / item, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(src, dst / item)
    params = yaml.safe_load((dst / "params.yaml").read_text())
    params["base"]["scale"] = scale
    if cores is not None:
        params["base"]["cores"] = cores
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    subprocess.run(["dvc", "init", "--no-scm", "-q"], cwd=dst, env=_env(), check=True)
    return dst


def prepare_copy(root: Path, dst: Path, scenes: int, episodes: int) -> Path:
    """A tiny copy with `scenes` ch6_test scenes and `episodes` episodes per compared
    condition."""
    copy_pipeline(root, dst)
    params = yaml.safe_load((dst / "params.yaml").read_text())
    params["generate"]["datasets"][DATASET]["n_scenes"] = scenes
    for cond in CONDITIONS:
        params["trials"]["conditions"][cond]["episodes"] = episodes
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    return dst


def targets(repo: Path) -> list[str]:
    """generate@ch6_test and the trials of CONDITIONS: trials@<condition> when the trials
    stage is one per condition (foreach), else the one stage `trials`."""
    stages = yaml.safe_load((repo / "dvc.yaml").read_text())["stages"]
    trials = [f"trials@{c}" for c in CONDITIONS] if "foreach" in stages["trials"] else ["trials"]
    return [f"generate@{DATASET}", *trials]


def repro(repo: Path) -> float:
    """`dvc repro` of targets(repo) (and what they need) in `repo`; its wall seconds."""
    t0 = time.perf_counter()
    cmd = ["dvc", "repro", *targets(repo)]
    if subprocess.run(cmd, cwd=repo, env=_env()).returncode != 0:
        print(f"crosscheck: {' '.join(cmd)} failed in {repo}", file=sys.stderr)
        sys.exit(2)
    return time.perf_counter() - t0


def digest(path: Path) -> str | None:
    """md5 over every file below `path` (names and bytes); None when it does not exist."""
    if not path.exists():
        return None
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    h = hashlib.md5()
    for f in files:
        h.update(str(f.relative_to(path)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def _trial_success(repo: Path, cond: str) -> dict[str, int]:
    summary = repo / "reports/trials" / cond / "summary.json"
    data = read_json(summary) if summary.exists() else {}
    if "success_k" in data and "success_n" in data:
        return {"k": int(data["success_k"]), "n": int(data["success_n"])}
    lines = (repo / "reports/trials" / cond / "records.jsonl").read_text().splitlines()
    import json

    records = [json.loads(line) for line in lines if line.strip()]
    return {"k": sum(bool(r["success"]) for r in records), "n": len(records)}


def measure(repo: Path) -> dict[str, Any]:
    """What is compared, read from a reproduced copy."""
    gen = repo / "data/generate" / DATASET
    manifest = read_json(gen / "manifest.json")
    n_objects = np.concatenate(
        [load_npz(gen / s, ["n_objects"])["n_objects"] for s in manifest["shards"]]
    ).astype(float)
    rejected = {k: int(v) for k, v in manifest["rejected"].items()}
    return {
        "dataset": {
            "n_scenes": int(manifest["n_scenes"]),
            "families": {k: int(v) for k, v in manifest["families"].items()},
            "rejected": rejected,
            "attempts": int(manifest["n_scenes"]) + sum(rejected.values()),
            "n_objects": {
                "mean": float(n_objects.mean()),
                "sd": float(n_objects.std(ddof=1)),
                "n": len(n_objects),
            },
        },
        "trials": {c: _trial_success(repo, c) for c in CONDITIONS},
        "digests": {p: digest(repo / p) for p in DIGESTED},
    }


def _git_revision(root: Path) -> str | None:
    try:
        out = subprocess.run(
            ["git", "describe", "--always", "--dirty"], cwd=root, capture_output=True, text=True
        )
    except OSError:
        return None
    return out.stdout.strip() or None


def run_copy(root: Path, workdir: Path | None, keep: bool) -> dict[str, Any]:
    """Prepare, reproduce and measure one copy; the measurement plus where and how."""
    tmp = Path(tempfile.mkdtemp(prefix="crosscheck-", dir=workdir))
    try:
        repo = prepare_copy(root, tmp / "repo", SCENES, EPISODES)
        stage_targets = targets(repo)
        seconds = repro(repo)
        got = measure(repo)
    finally:
        if keep:
            print(f"crosscheck: copy kept in {tmp / 'repo'}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    got["run"] = {
        "environment": environment(),
        "settings": {
            "scale": "tiny",
            "scenes": SCENES,
            "episodes": EPISODES,
            "targets": stage_targets,
            "torch_threads_param": _torch_threads_param(root),
        },
        "code": _git_revision(root),
        "repro_seconds": round(seconds, 1),
    }
    return got


def _torch_threads_param(root: Path) -> Any:
    return yaml.safe_load((root / "params.yaml").read_text())["base"].get("torch_threads")


# --- report -----------------------------------------------------------------------------


def byte_identity(expected: dict, got: dict) -> dict[str, Any]:
    same = [p for p in DIGESTED if expected["digests"].get(p) == got["digests"].get(p)]
    differ = [p for p in DIGESTED if p not in same]
    e_env, g_env = expected["run"]["environment"], got["run"]["environment"]
    # Bits match only on the same CPU model, instruction set (torch's kernel level and the
    # flags that pick the precision) and thread count; an older record without the
    # instruction set counts as another machine.
    same_machine = all(e_env.get(k) == g_env.get(k) for k in SAME_MACHINE_KEYS)
    return {
        "byte_identical": not differ,
        "differing_outputs": differ,
        "same_cpu_model_and_threads": same_machine,
    }


def table(rows: list[Row], alpha: float = ALPHA) -> str:
    head = ("compared", "expected", "got", "p", "result")
    body = [(r.name, r.expected, r.got, f"{r.p:.3g}", "pass" if r.passed else "FAIL") for r in rows]
    widths = [max(len(x[i]) for x in (head, *body)) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(x, widths, strict=True)) for x in (head, *body)]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append(
        f"(two-sided two-proportion / two-mean z-tests; a row fails when p < {alpha:g} / "
        f"{len(rows)} = {alpha / len(rows):.2g}; intervals are Wilson 95% / mean +- 1.96 SE)"
    )
    return "\n".join(lines)


SAME_MACHINE_KEYS = ("cpu_model", "torch_cpu_capability", "cpu_flags", "torch_threads")


def _machine(env: dict) -> str:
    isa = f" ({instruction_set(env)})" if "torch_cpu_capability" in env else ""
    return (
        f"{env['cpu_model']}{isa}, {env['logical_cpus']} logical CPUs, torch threads "
        f"{env['torch_threads']}, torch {env['torch']}, sapien {env['sapien']}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m clutterbench.crosscheck")
    parser.add_argument(
        "--record", action="store_true", help=f"run and write the expectations to {EXPECTED}"
    )
    parser.add_argument("--root", type=Path, default=Path("."), help="repository root")
    parser.add_argument("--workdir", type=Path, help="where the temporary copy goes")
    parser.add_argument("--keep", action="store_true", help="keep the temporary copy")
    args = parser.parse_args(argv)
    root = args.root.resolve()
    expected_path = root / EXPECTED
    if not args.record and not expected_path.exists():
        print(f"crosscheck: {EXPECTED} missing; record it with --record", file=sys.stderr)
        return 2
    got = run_copy(root, args.workdir, args.keep)
    if args.record:
        got["method"] = __doc__.split("Test: ")[1].split("\n\n")[0].replace("\n", " ")
        write_json(expected_path, got)
        print(f"crosscheck: expectations written to {EXPECTED} ({got['run']['repro_seconds']} s)")
        print(f"  machine: {_machine(got['run']['environment'])}")
        for cond, t in got["trials"].items():
            print(f"  {cond}: {t['k']}/{t['n']}")
        print(f"  {DATASET}: {got['dataset']}")
        return 0
    expected = read_json(expected_path)
    rows = compare(expected, got)
    ident = byte_identity(expected, got)
    ok = all(r.passed for r in rows)
    print(f"expected on: {_machine(expected['run']['environment'])} ({expected['run']['code']})")
    print(f"this run on: {_machine(got['run']['environment'])} ({got['run']['code']})")
    if expected["run"]["settings"] != got["run"]["settings"]:
        print(f"note: settings differ: {expected['run']['settings']} vs {got['run']['settings']}")
    print()
    print(table(rows))
    print()
    if ident["byte_identical"]:
        print(f"byte-identical to the expectations: yes (all {len(DIGESTED)} outputs)")
    else:
        print(
            f"byte-identical to the expectations: no ({len(ident['differing_outputs'])} of "
            f"{len(DIGESTED)} outputs differ: {', '.join(ident['differing_outputs'])})"
        )
    if ident["same_cpu_model_and_threads"]:
        print(
            "same CPU model, instruction set and torch threads as the expectations: "
            "byte-identity expected"
        )
        if not ident["byte_identical"]:
            print("  (it was not: other code or package versions, or a determinism bug)")
    else:
        print(
            "other CPU model, instruction set or thread count: only statistical agreement "
            "is expected"
        )
    print(f"crosscheck: {'PASS' if ok else 'FAIL'} ({got['run']['repro_seconds']} s)")
    write_json(
        root / RESULT,
        {
            "passed": ok,
            "rows": [asdict(r) for r in rows],
            **ident,
            "expected_run": expected["run"],
            "this_run": got["run"],
            "got": {k: got[k] for k in ("dataset", "trials", "digests")},
        },
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

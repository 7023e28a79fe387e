"""`make bench`, dvc part: what dvc itself costs around the stages -> reports/bench/dvc.{json,md}.

Every stage that `dvc repro` runs is checked against its params and its lock entry (dvc reads
params.yaml and dvc.lock) and then written into dvc.lock (dvc reads the whole lock again for
update and writes it). Both files are YAML, and this pipeline's lock is long (every stage
records the values of the params it lists). The part times, on this repository's own files:
- a safe load of params.yaml, dvc.yaml and dvc.lock with ruamel.yaml's pure-Python reader and
  with its C reader (ruamel.yaml.clib, what dvc uses when it is installed), and the
  round-trip load and dump of dvc.lock that every stage's lock update makes (pure Python
  either way);
- one `dvc status` of the whole pipeline (every stage's params read), wall time.
The median of REPEATS runs each. Nothing is written but the results.
"""

from __future__ import annotations

import io
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from clutterbench.bench import header, write_result
from clutterbench.platform_info import cpu_description

FILES = ("params.yaml", "dvc.yaml", "dvc.lock")
REPEATS = 3


def _median_s(fn: Callable[[], object], repeats: int = REPEATS) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def yaml_costs(path: Path) -> dict[str, float]:
    """Seconds to load `path` safely with the pure and (where installed) the C reader, and,
    for dvc.lock, to load it round-trip and dump it (a stage's lock update)."""
    from ruamel.yaml import YAML

    text = path.read_text()
    out = {"lines": float(text.count("\n"))}
    out["safe_pure_s"] = _median_s(lambda: YAML(typ="safe", pure=True).load(text))
    out["safe_c_s"] = _median_s(lambda: YAML(typ="safe").load(text)) if _libyaml() else float("nan")
    if path.name == "dvc.lock":
        data = YAML().load(text)
        out["roundtrip_load_s"] = _median_s(lambda: YAML().load(text))
        out["dump_s"] = _median_s(lambda: YAML().dump(data, io.StringIO()))
    return out


def _libyaml() -> bool:
    import ruamel.yaml

    return bool(getattr(ruamel.yaml, "__with_libyaml__", False))


def dvc_status_s(root: Path) -> float:
    """Wall seconds of one `dvc status` at `root` (its exit status is not the point)."""
    env = {**os.environ, "DVC_NO_ANALYTICS": "1"}
    dvc = Path(sys.executable).parent / "dvc"
    t0 = time.perf_counter()
    subprocess.run([str(dvc), "status", "-q"], cwd=root, env=env, capture_output=True)
    return time.perf_counter() - t0


def bench_dvc(root: Path = Path("."), out_dir: Path = Path("reports/bench")) -> dict[str, Any]:
    import yaml

    missing = [f for f in FILES if not (root / f).is_file()]
    if missing:
        raise SystemExit(f"error: bench dvc: {', '.join(missing)} missing under {root}")
    files = {f: yaml_costs(root / f) for f in FILES}
    stages = yaml.safe_load((root / "dvc.lock").read_text()).get("stages", {})
    result: dict[str, Any] = {
        **cpu_description(),
        "torch_threads": 1,
        "libyaml": _libyaml(),
        "repeats": REPEATS,
        "locked_stages": len(stages),
        "files": files,
        "dvc_status_s": dvc_status_s(root),
    }
    lock, params = files["dvc.lock"], files["params.yaml"]
    update = lock["roundtrip_load_s"] + lock["dump_s"]
    pure = params["safe_pure_s"] + lock["safe_pure_s"] + update
    reads = ("safe_c_s" if result["libyaml"] else "safe_pure_s",)
    fast = params[reads[0]] + lock[reads[0]] + update
    result["per_stage_yaml_s"] = {"pure": pure, "installed": fast}
    md = header("What dvc costs around the stages (YAML of params and lock)", result)
    md += [
        f"This repository's files; the median of {REPEATS} runs. ruamel.yaml's C reader "
        f"(ruamel.yaml.clib) installed: {'yes' if result['libyaml'] else 'no'}. Per stage "
        "that `dvc repro` runs, dvc reads params.yaml and dvc.lock (safe: the C reader where "
        "installed), then reads dvc.lock round-trip and writes it again (pure Python either "
        "way).",
        "",
        "| file | lines | safe load, pure (s) | safe load, C (s) | round-trip load (s) | "
        "dump (s) |",
        "|---|---|---|---|---|---|",
    ]
    for name, v in files.items():
        rt = f"{v['roundtrip_load_s']:.3f}" if "roundtrip_load_s" in v else "—"
        dump = f"{v['dump_s']:.3f}" if "dump_s" in v else "—"
        md.append(
            f"| {name} | {int(v['lines'])} | {v['safe_pure_s']:.3f} | {v['safe_c_s']:.3f} | "
            f"{rt} | {dump} |"
        )
    md += [
        "",
        f"- YAML per stage run (params and lock read, lock read round-trip and written): "
        f"{pure:.2f} s with the pure "
        f"reader, {fast:.2f} s as installed.",
        f"- `dvc status` of the whole pipeline ({len(stages)} locked stages, each stage's "
        f"params read): {result['dvc_status_s']:.2f} s.",
    ]
    write_result(out_dir, "dvc", result, md)
    print("\n".join(md[4:]))
    return result

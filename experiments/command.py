"""What every dev-stream recheck does at its start and end: its configs read and checked, its
result saved as JSON and Markdown under experiments/reports/, and its command line (params.yaml,
seeding and one-line errors as a stage)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from clutterbench.io import write_json, write_text

OUT = Path("experiments/reports")


def open_recheck(params: Mapping[str, Any], section: str) -> tuple[Any, Any, Any, Any]:
    """A trials recheck's configs -> (base, dev, trials, dev.<section>): the dev streams
    checked against the tables' (check_dev_streams); one line when the recheck names no dev
    stream to run on."""
    from clutterbench.config import BaseConfig, load_section
    from clutterbench.errors import ClutterbenchError
    from clutterbench.trials.config import TrialsConfig
    from experiments.config import check_dev_streams, load_dev

    base = load_section(BaseConfig, "base", params)
    dev = load_dev(params)
    trials = load_section(TrialsConfig, "trials", params)
    check_dev_streams(dev, trials)
    cfg = getattr(dev, section)
    if not cfg.streams:
        raise ClutterbenchError(f"dev.{section}.streams: no dev stream to run on")
    return base, dev, trials, cfg


def save(
    result: dict[str, Any],
    started: float,
    out_dir: Path,
    name: str,
    markdown: Callable[[Mapping[str, Any]], str],
) -> dict[str, Any]:
    """`result` with its wall time since `started` -> out_dir/<name>.{json,md}; returns it."""
    result["seconds"] = time.perf_counter() - started
    write_json(out_dir / f"{name}.json", result)
    write_text(out_dir / f"{name}.md", markdown(result))
    return result


def run_command(recheck: Callable[[Mapping[str, Any]], dict[str, Any]], name: str) -> None:
    """Run `recheck(params)` as a stage runs (params.yaml, seeding, torch threads; errors: one
    line), then print its finding and where its report went."""
    from clutterbench.config import BaseConfig
    from clutterbench.stage import run_stage

    def run(params: dict[str, Any], base: BaseConfig) -> None:
        result = recheck(params)
        print(result["shows"])
        print(f"-> {OUT / f'{name}.md'} ({result['seconds'] / 60:.1f} min)")

    run_stage(run)

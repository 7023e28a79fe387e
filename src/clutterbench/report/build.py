"""The report stage's work: every table, in order, from the records and metrics the other
stages wrote. A table is one builder in BUILDERS, a function of the shared `Report` inputs;
a new table is one more line there."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.config import BaseConfig, load_section, resolve_scale
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json
from clutterbench.platform_info import environment
from clutterbench.report.arm_table import arm_table
from clutterbench.report.box_estimation import estimation_table
from clutterbench.report.config import ReportConfig
from clutterbench.report.datasets import dataset_stats, datasets_table
from clutterbench.report.decomposition import decomposition_table
from clutterbench.report.fig_3_15 import fig_3_15_table
from clutterbench.report.paired import paired_table
from clutterbench.report.summary import summary_table
from clutterbench.report.table_4_1 import table_4_1, table_4_1_target
from clutterbench.report.table_4_2 import table_4_2
from clutterbench.report.table_5_2 import table_5_2
from clutterbench.report.table_6_1_boxes import box_table
from clutterbench.report.table_6_2 import support_table
from clutterbench.report.table_6_3 import (
    extraction_families_table,
    extraction_table,
    rule_note,
    trial_params_note,
)
from clutterbench.report.table_6_3_noise import noise_table
from clutterbench.report.tables import load_thesis_figures
from clutterbench.report.tables_5_1_6_1 import RunSources, collapse_table
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.records import read_records
from clutterbench.trials.core.stats import aggregate_games

TABLES = Path("reports/tables")
SUPPORT = Path("reports/support")
NOISE = Path("reports/noise")


def json_key(path: Path, key: str) -> Any:
    """`key` of the JSON object in `path`, or one line naming the file and the stage to
    rerun (the one that writes reports/<stage>/)."""
    data = read_json(path)
    if not isinstance(data, dict) or key not in data:
        raise ClutterbenchError(f"{path}: no '{key}' in it; rerun the {path.parent.name} stage")
    return data[key]


def by_condition(records: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for r in records:
        out.setdefault(r["condition"], []).append(r)
    return out


@dataclasses.dataclass
class Report:
    """What every table builder reads: the params' sections, the thesis figures, and the
    records of each trials stage, each read once."""

    params: dict
    base: BaseConfig

    @functools.cached_property
    def cfg(self) -> ReportConfig:
        return load_section(ReportConfig, "report", self.params)

    @functools.cached_property
    def generate(self) -> GenerateConfig:
        return load_section(GenerateConfig, "generate", self.params)

    @functools.cached_property
    def evaluate(self) -> EvaluateConfig:
        return load_section(EvaluateConfig, "evaluate", self.params)

    @functools.cached_property
    def trials(self) -> TrialsConfig:
        return load_section(TrialsConfig, "trials", self.params)

    @functools.cached_property
    def figures(self) -> Any:
        return load_thesis_figures(Path(self.cfg.thesis_figures))

    @functools.cached_property
    def sources(self) -> RunSources:
        return RunSources(Path("reports/evaluate"), Path("models"), Path("reports/train"))

    @functools.cached_property
    def run_models(self) -> dict[str, str]:
        return {name: run.model for name, run in self.evaluate.runs.items()}

    @functools.cached_property
    def table_6_3_rows(self) -> dict[str, str]:
        """report.table_6_3, and for each of its conditions run again under a sensor
        (trials.sensed), the row '<method>/<objects>/<sensing>' of that condition."""
        return self.trials.sensed.table_rows(self.cfg.table_6_3)

    @functools.cached_property
    def ch6_records(self) -> dict[str, list[dict]]:
        """The records of every Table 6.3 row's condition the trials ran (not of an opt-in
        one this run left out: trials.opt_in)."""
        return {
            cond: read_records(Path(f"reports/trials/{cond}/records.jsonl"))
            for cond in self.table_6_3_rows.values()
            if cond not in self.trials.opt_in.skipped
        }

    @functools.cached_property
    def noise(self) -> dict[str, Any]:
        """The noise stage's summary (reports/noise/summary.json)."""
        return {
            "noise": json_key(NOISE / "summary.json", "noise"),
            "conditions": json_key(NOISE / "summary.json", "conditions"),
        }

    @functools.cached_property
    def robust_records(self) -> dict[str, list[dict]]:
        """The robust search oracles' records (noise stage)."""
        return {
            cond: read_records(NOISE / "robust" / cond / "records.jsonl")
            for cond, row in self.noise["conditions"].items()
            if row.get("robust_of")
        }

    @functools.cached_property
    def ch4_records(self) -> dict[str, list[dict]]:
        return by_condition(read_records(Path("reports/trials_ch4/records.jsonl")))

    @functools.cached_property
    def chosen(self) -> Any:
        return json_key(SUPPORT / "thresholds.json", "chosen")


def datasets(r: Report) -> None:
    stats = {
        name: dataset_stats(
            Path("data/generate"), Path("data/split"), name, ds.moved_threshold_m, ds.pulls, ds
        )
        for name, ds in r.generate.datasets.items()
    }
    # The report's metrics file also names the machine (CPU model, threads, versions): tables
    # are byte-identical only on the same CPU model and thread count (docs/determinism.md).
    # Not among the outputs the smoke test compares byte for byte.
    write_json(
        Path("reports/metrics/datasets.json"),
        {"scale": r.base.scale, "datasets": stats, "environment": environment()},
    )
    datasets_table(stats, r.figures, TABLES)


def tables_5_1_6_1(r: Report) -> None:
    for table, rows in (("table_5_1", r.cfg.table_5_1), ("table_6_1", r.cfg.table_6_1)):
        collapse_table(
            table,
            rows,
            r.run_models,
            r.evaluate.threshold,
            r.figures,
            r.sources,
            TABLES,
            r.base.scale,
        )


def table_4_2_pixels(r: Report) -> None:
    table_4_2(
        r.cfg.table_4_2,
        r.run_models,
        {name: r.evaluate.for_run(name).threshold for name in r.evaluate.runs},
        r.figures,
        r.sources,
        TABLES,
        r.base.scale,
        {name: tuple(ds.n_objects) for name, ds in r.generate.datasets.items()},
    )


def support_thresholds(path: Path, fusion: Path | None = None) -> dict[str, Any]:
    """Each Table 6.2 method's thresholds: the rules' (`chosen`), the box head's per pull
    head (`box_head`, as method `<head>_box`) and, from `fusion` where given, the box head
    fused with physics from depth (as method `<head>_box_fused`) and physics from depth's
    pulls alone (`<head>_physics_pull`); then, for each sensor the support stage chose on
    (`sensed`), the same chosen on its depth, as methods `<method>@<sensor>`."""
    data = read_json(path)
    json_key(path, "chosen")  # one line if either file has no choice
    fused = read_json(fusion) if fusion is not None else {}
    if fusion is not None:
        json_key(fusion, "chosen")
    out = _choice_thresholds(data, fused)
    for sensor, choice in data.get("sensed", {}).items():
        mine = _choice_thresholds(choice, fused.get("sensed", {}).get(sensor, {}))
        out |= {f"{method}@{sensor}": t for method, t in mine.items()}
    return out


def _choice_thresholds(choice: dict[str, Any], fusion: dict[str, Any]) -> dict[str, Any]:
    """One choice's thresholds per method (support_thresholds)."""
    box = choice.get("box_head", {})
    fused = fusion.get("chosen", {})
    return (
        dict(choice["chosen"])
        | {f"{head}_box": t for head, t in box.items()}
        | {
            f"{head}_box_fused": {k: v for k, v in t.items() if k != "physics_edge"}
            for head, t in fused.items()
        }
        | {f"{head}_physics_pull": {"edge": t["physics_edge"]} for head, t in fused.items()}
    )


def table_6_1_per_box(r: Report) -> None:
    scores = Path("reports/box_head/scores.csv")
    if not scores.exists():
        raise ClutterbenchError(f"{scores} missing; run the box_head stage")
    box_table(pd.read_csv(scores), TABLES, r.base.scale)


def table_6_2_support(r: Report) -> None:
    if not (SUPPORT / "scenes.csv").exists():
        raise ClutterbenchError(f"{SUPPORT / 'scenes.csv'} missing; run the support stage")
    support_table(
        pd.read_csv(SUPPORT / "scenes.csv"),
        r.cfg.table_6_2_methods,
        support_thresholds(SUPPORT / "thresholds.json", SUPPORT / "box_fusion.json"),
        r.figures,
        TABLES,
        r.base.scale,
        json_key(Path("data/support/truth.json"), "edges"),
    )


def table_6_3_extraction(r: Report) -> None:
    records, scale, rows = r.ch6_records, r.base.scale, r.table_6_3_rows
    trial_note = trial_params_note(r.trials.ch6.pull, r.trials.ch6.max_steps)
    rules = rule_note(records, r.chosen, r.cfg.table_6_2_methods)
    noise = r.noise["conditions"]
    not_run = r.trials.opt_in.skipped  # opt-in conditions this run left out
    extraction_table(records, rows, r.figures, TABLES, scale, [trial_note, *rules], noise, not_run)
    extraction_families_table(records, rows, TABLES, scale, [trial_note], not_run)
    meaning = r.trials.ch6.pull_map_meaning
    decomposition_table(records | r.robust_records, TABLES, scale, meaning, not_run)
    noise_table(r.noise, r.table_6_3_rows, TABLES, scale)
    paired_table(records, TABLES, scale)
    estimation_table(records, TABLES, scale)


def table_4_1_pull_with_support(r: Report) -> None:
    sensed = r.trials.ch4_sensed
    rows = sensed.table_rows(r.cfg.table_4_1)
    table_4_1(r.ch4_records, rows, r.figures, TABLES, r.base.scale, sensed.models)
    table_4_1_target(r.ch4_records, r.cfg.table_4_1_target, r.figures, TABLES, r.base.scale)


def table_5_2_replenishment(r: Report) -> None:
    """Table 5.2: report.table_5_2's rows, and for each of their conditions run again under a
    sensor (trials.ch5_sensed), the row '<method>/<scene type>/<sensing>' of that condition."""
    ch5 = by_condition(read_records(Path("reports/trials_ch5/records.jsonl")))
    rows = r.trials.ch5_sensed.table_rows(r.cfg.table_5_2)
    table_5_2(ch5, rows, r.figures, TABLES, r.base.scale)


def arm_level(r: Report) -> None:
    if not r.trials.arm_conditions:
        return
    of = {name: arm.of for name, arm in r.trials.arm_conditions.items()}
    arm_records = {
        name: read_records(Path(f"reports/trials_arm/{name}/records.jsonl")) for name in of
    }
    kinematic = {
        o: read_records(Path(f"reports/trials/{o}/records.jsonl"))
        if o in r.trials.conditions
        else r.ch4_records.get(o, [])
        for o in of.values()
    }
    arm_table(arm_records, kinematic, of, TABLES, r.base.scale)


def fig_3_15_yamakuzushi(r: Report) -> None:
    games = read_records(Path("reports/trials_ch3/records.jsonl"))
    ch3 = resolve_scale(r.params.get("yamakuzushi", {}), r.base.scale, "yamakuzushi")
    select, pomdp = ch3.get("select", {}), ch3.get("pomdp", {})
    fig_3_15_table(
        aggregate_games(games),
        games,
        r.figures,
        json_key(Path("reports/train_slide/metrics.json"), "val"),
        TABLES,
        TABLES / "fig_3_15.png",
        r.base.scale,
        [
            f"targets: pieces whose ConvNet probability is at least "
            f"{select.get('min_probability')}, best first; the POMDP observes at most "
            f"{pomdp.get('max_observations')} times per piece; a piece no state fits (belief "
            f"mass below {pomdp.get('min_mass')}) is: {pomdp.get('when_no_state_fits')} "
            "(yamakuzushi.pomdp.when_no_state_fits, chosen on validation piles)"
        ],
    )


def summary(r: Report) -> None:
    summary_table(TABLES, r.figures, r.cfg.table_6_2_methods, r.base.scale)


BUILDERS: list[tuple[str, Callable[[Report], None]]] = [
    ("datasets", datasets),
    ("Tables 5.1 and 6.1", tables_5_1_6_1),
    ("Table 6.1 per box", table_6_1_per_box),
    ("Table 4.2", table_4_2_pixels),
    ("Table 6.2", table_6_2_support),
    (
        "Table 6.3 (with its families, decomposition, task noise, paired and box estimation "
        "tables)",
        table_6_3_extraction,
    ),
    ("Table 4.1", table_4_1_pull_with_support),
    ("Table 5.2", table_5_2_replenishment),
    ("arm-level table", arm_level),
    ("Fig. 3.15", fig_3_15_yamakuzushi),
    ("summary", summary),  # last: it reads the tables above from their CSVs
]
"""Every table of the report, in the order they are written."""


def build_report(params: dict, base: BaseConfig) -> None:
    """Every builder of BUILDERS on the same inputs, in order."""
    r = Report(params, base)
    # a bad section or a missing thesis figures file fails before any table is written
    _ = (r.cfg, r.generate, r.evaluate, r.figures)
    for _, build in BUILDERS:
        build(r)

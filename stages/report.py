"""Stage report: metrics -> Markdown + CSV tables with the thesis column beside ours."""

from pathlib import Path

import pandas as pd

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.config import BaseConfig, load_section, resolve_scale
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json
from clutterbench.platform_info import environment
from clutterbench.report.arm_table import arm_table
from clutterbench.report.box_estimation import estimation_table
from clutterbench.report.collapse import RunSources, collapse_table
from clutterbench.report.config import ReportConfig
from clutterbench.report.datasets import dataset_stats, datasets_table
from clutterbench.report.decomposition import decomposition_table
from clutterbench.report.extraction import (
    extraction_families_table,
    extraction_table,
    rule_note,
    trial_params_note,
)
from clutterbench.report.fig_3_15 import fig_3_15_table
from clutterbench.report.paired import paired_table
from clutterbench.report.summary import summary_table
from clutterbench.report.support import support_table
from clutterbench.report.table_4_1 import table_4_1, table_4_1_target
from clutterbench.report.table_4_2 import table_4_2
from clutterbench.report.table_5_2 import table_5_2
from clutterbench.report.tables import load_thesis_figures
from clutterbench.stage import run_stage
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.records import read_records
from clutterbench.trials.core.stats import aggregate_games


def _json_key(path: Path, key: str):
    """`key` of the JSON object in `path`, or one line naming the file and the stage to
    rerun (the one that writes reports/<stage>/)."""
    data = read_json(path)
    if not isinstance(data, dict) or key not in data:
        raise ClutterbenchError(f"{path}: no '{key}' in it; rerun the {path.parent.name} stage")
    return data[key]


def report(params: dict, base: BaseConfig) -> None:
    cfg = load_section(ReportConfig, "report", params)
    gen = load_section(GenerateConfig, "generate", params)
    evaluate = load_section(EvaluateConfig, "evaluate", params)
    figures = load_thesis_figures(Path(cfg.thesis_figures))
    stats = {
        name: dataset_stats(
            Path("data/generate"), Path("data/split"), name, ds.moved_threshold_m, ds.pulls, ds
        )
        for name, ds in gen.datasets.items()
    }
    # The report's metrics file also names the machine (CPU model, threads, versions): tables
    # are byte-identical only on the same CPU model and thread count (docs/determinism.md).
    # Not among the outputs the smoke test compares byte for byte.
    write_json(
        Path("reports/metrics/datasets.json"),
        {"scale": base.scale, "datasets": stats, "environment": environment()},
    )
    datasets_table(stats, figures, Path("reports/tables"))
    sources = RunSources(Path("reports/evaluate"), Path("models"), Path("reports/train"))
    run_models = {name: run.model for name, run in evaluate.runs.items()}
    for table, rows in (("table_5_1", cfg.table_5_1), ("table_6_1", cfg.table_6_1)):
        collapse_table(
            table,
            rows,
            run_models,
            evaluate.threshold,
            figures,
            sources,
            Path("reports/tables"),
            base.scale,
        )
    table_4_2(
        cfg.table_4_2,
        run_models,
        {name: evaluate.for_run(name).threshold for name in evaluate.runs},
        figures,
        sources,
        Path("reports/tables"),
        base.scale,
        {name: tuple(ds.n_objects) for name, ds in gen.datasets.items()},
    )

    support = Path("reports/support")
    if not (support / "scenes.csv").exists():
        raise ClutterbenchError(f"{support / 'scenes.csv'} missing; run the support stage")
    support_table(
        pd.read_csv(support / "scenes.csv"),
        cfg.table_6_2_methods,
        _json_key(support / "thresholds.json", "chosen"),
        figures,
        Path("reports/tables"),
        base.scale,
        _json_key(Path("data/support/truth.json"), "edges"),
    )
    records = {
        cond: read_records(Path(f"reports/trials/{cond}/records.jsonl"))
        for cond in cfg.table_6_3.values()
    }
    ch6 = load_section(TrialsConfig, "trials", params).ch6
    trial_note = trial_params_note(ch6)
    chosen = _json_key(support / "thresholds.json", "chosen")
    rules = rule_note(records, chosen, cfg.table_6_2_methods)
    extraction_table(
        records, cfg.table_6_3, figures, Path("reports/tables"), base.scale, [trial_note, *rules]
    )
    extraction_families_table(
        records, cfg.table_6_3, Path("reports/tables"), base.scale, [trial_note]
    )
    decomposition_table(records, Path("reports/tables"), base.scale, ch6.pull_map_meaning)
    paired_table(records, Path("reports/tables"), base.scale)
    estimation_table(records, Path("reports/tables"), base.scale)

    by_condition: dict[str, list[dict]] = {}
    for r in read_records(Path("reports/trials_ch4/records.jsonl")):
        by_condition.setdefault(r["condition"], []).append(r)
    table_4_1(by_condition, cfg.table_4_1, figures, Path("reports/tables"), base.scale)
    table_4_1_target(
        by_condition, cfg.table_4_1_target, figures, Path("reports/tables"), base.scale
    )

    ch5: dict[str, list[dict]] = {}
    for r in read_records(Path("reports/trials_ch5/records.jsonl")):
        ch5.setdefault(r["condition"], []).append(r)
    table_5_2(ch5, cfg.table_5_2, figures, Path("reports/tables"), base.scale)

    trials_cfg = load_section(TrialsConfig, "trials", params)
    if trials_cfg.arm_conditions:
        of = {name: arm.of for name, arm in trials_cfg.arm_conditions.items()}
        arm_records = {
            name: read_records(Path(f"reports/trials_arm/{name}/records.jsonl")) for name in of
        }
        kinematic = {
            o: read_records(Path(f"reports/trials/{o}/records.jsonl"))
            if o in trials_cfg.conditions
            else by_condition.get(o, [])
            for o in of.values()
        }
        arm_table(arm_records, kinematic, of, Path("reports/tables"), base.scale)

    games = read_records(Path("reports/trials_ch3/records.jsonl"))
    ch3 = resolve_scale(params.get("yamakuzushi", {}), base.scale, "yamakuzushi")
    select, pomdp = ch3.get("select", {}), ch3.get("pomdp", {})
    fig_3_15_table(
        aggregate_games(games),
        games,
        figures,
        _json_key(Path("reports/train_slide/metrics.json"), "val"),
        Path("reports/tables"),
        Path("reports/tables/fig_3_15.png"),
        base.scale,
        [
            f"targets: pieces whose ConvNet probability is at least "
            f"{select.get('min_probability')}, best first; the POMDP observes at most "
            f"{pomdp.get('max_observations')} times per piece; a piece no state fits (belief "
            f"mass below {pomdp.get('min_mass')}) is: {pomdp.get('when_no_state_fits')} "
            "(yamakuzushi.pomdp.when_no_state_fits, chosen on validation piles)"
        ],
    )
    # last: the summary reads the tables above from their CSVs
    summary_table(Path("reports/tables"), figures, cfg.table_6_2_methods, base.scale)


if __name__ == "__main__":
    run_stage(report)

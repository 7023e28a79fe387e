"""Stage report: metrics -> Markdown + CSV tables with the thesis column beside ours."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.data.generate import GenerateConfig
from clutterbench.io import write_json
from clutterbench.report.collapse import collapse_table
from clutterbench.report.config import ReportConfig
from clutterbench.report.datasets import dataset_stats, datasets_table
from clutterbench.report.tables import load_thesis_figures
from clutterbench.stage import run_stage


def report(params: dict, base: BaseConfig) -> None:
    cfg = load_section(ReportConfig, "report", params)
    gen = load_section(GenerateConfig, "generate", params)
    figures = load_thesis_figures(Path(cfg.thesis_figures))
    stats = {
        name: dataset_stats(
            Path("data/generate"), Path("data/split"), name, ds.moved_threshold_m, ds.pulls
        )
        for name, ds in gen.datasets.items()
    }
    write_json(Path("reports/metrics/datasets.json"), {"scale": base.scale, "datasets": stats})
    datasets_table(stats, figures, Path("reports/tables"))
    evaluated = Path("reports/evaluate")
    collapse_table(
        "table_5_1",
        cfg.table_5_1,
        figures,
        evaluated,
        Path("reports/tables"),
        notes=[
            f"{base.scale} scale; ch. 5 test split (thesis: 1,000 simulated images).",
            "pixel counted as collapse when its probability > 0.5; counts summed over all "
            "test pixels.",
            "figures: reports/evaluate/<run>/figure.png; sweep: reports/evaluate/<run>/sweep.csv.",
            "best IoU in sweep: the highest IoU over thresholds 0.00-0.99 on the test set itself "
            "(optimistic; shows how calibrated each loss leaves the probabilities).",
        ],
    )
    collapse_table(
        "table_6_1",
        cfg.table_6_1,
        figures,
        evaluated,
        Path("reports/tables"),
        notes=[
            f"{base.scale} scale; ch6_test: separate random-scene test set (thesis: 1,000).",
            "previous work = the ch. 5 network (BCE, trained on ch. 5 scenes) on this test set.",
            "threshold 0.5 as in Table 5.1 (the thesis does not state one for Table 6.1).",
        ],
    )


if __name__ == "__main__":
    run_stage(report)

"""Stage report: metrics and trial records -> Markdown + CSV tables with the thesis column
beside ours (the tables and their order: clutterbench.report.build.BUILDERS)."""

from clutterbench.config import BaseConfig
from clutterbench.report.build import build_report
from clutterbench.stage import run_stage


def report(params: dict, base: BaseConfig) -> None:
    build_report(params, base)


if __name__ == "__main__":
    run_stage(report)

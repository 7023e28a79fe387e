"""Stage testset: the pull-consequence test set as a standalone artifact (data/testset), and
the leaderboard's baseline rows scored on it (the work: clutterbench.data.testset,
clutterbench.support.scorecard and baselines)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.testset import export_testset
from clutterbench.data.testset_load import load
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.support.baselines import baselines
from clutterbench.support.config import SupportEvalConfig
from clutterbench.support.scorecard import leaderboard, score, write_row

OUT = Path("data/testset")
BOARD = Path("reports/leaderboard")


def testset(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SupportEvalConfig, "support", params)
    sim = load_section(SimConfig, "sim", params)
    gen = load_section(GenerateConfig, "generate", params)
    dataset = cfg.box_head.test_dataset
    if dataset not in gen.datasets:
        raise ClutterbenchError(f"support.box_head.test_dataset: unknown dataset '{dataset}'")
    drop_m, tilt_deg = label_thresholds(params)
    thresholds = {"moved_m": cfg.moved_threshold_m, "drop_m": drop_m, "tilt_deg": tilt_deg}
    export_testset(Path("data/generate"), dataset, sim.camera, thresholds, cfg.min_pixels, OUT)
    ts = load(OUT)
    model = Path(f"models/{cfg.model}/best.pt")
    for name, (make, about) in baselines(
        ts, model, Path("models/box_head/best.pt"), sim.camera
    ).items():
        card = score(ts, make(), name, about)
        write_row(card, BOARD / "baselines")
        print(f"{name}: pull_collapse AUROC {card['pull_collapse']['auroc']}")
    leaderboard(BOARD, BOARD, ts["manifest"]["sha256"])


if __name__ == "__main__":
    run_stage(testset)

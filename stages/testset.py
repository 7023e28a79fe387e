"""Stage testset: the pull-consequence test set as a standalone artifact (data/testset: the
ch6_test dataset and the ch. 6 table streams' benchmark starts), and
the leaderboard's baseline rows scored on it (the work: clutterbench.data.testset,
clutterbench.support.scorecard and baselines)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.testset import dataset_arrays, export_testset, labelled_arrays
from clutterbench.data.testset_load import load
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.support.baselines import baselines
from clutterbench.support.config import SupportEvalConfig
from clutterbench.support.scorecard import leaderboard, score, write_row
from clutterbench.support.testset_starts import benchmark_starts
from clutterbench.trials.config import TrialsConfig

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
    trials = load_section(TrialsConfig, "trials", params)
    streams = ch6_streams(trials)
    starts = benchmark_starts(trials, sim, base.seed, streams)
    parts = [dataset_arrays(Path("data/generate"), dataset), labelled_arrays(starts)]
    export_testset(parts, sim.camera, thresholds, cfg.min_pixels, OUT, sim.physics)
    ts = load(OUT)
    model = Path(f"models/{cfg.model}/best.pt")
    physics = (trials.ch6, cfg.test.catalogue, cfg.min_pixels)
    for name, (make, about) in baselines(
        ts, model, Path("models/box_head/best.pt"), sim, physics
    ).items():
        card = score(ts, make(), name, about)
        write_row(card, BOARD / "baselines")
        print(f"{name}: pull_collapse AUROC {card['pull_collapse']['auroc']}")
    leaderboard(BOARD, BOARD, ts["manifest"]["sha256"])


def ch6_streams(trials: TrialsConfig) -> dict[str, int]:
    """Each stream of the ch. 6 conditions (Table 6.3) -> the most episodes one runs on it."""
    out: dict[str, int] = {}
    for cond in trials.conditions.values():
        out[cond.stream] = max(out.get(cond.stream, 0), cond.episodes)
    return out


if __name__ == "__main__":
    run_stage(testset)

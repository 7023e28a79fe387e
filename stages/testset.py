"""Stage testset: the pull-consequence test set as a standalone artifact (data/testset: the
ch6_test dataset and the ch. 6 table streams' benchmark starts; its sensed track, the same
scenes through support.sensing's first sensor, beside it as data/testset_sensed/<preset>), and
the leaderboard's baseline rows scored on each track (the work: clutterbench.data.testset and
testset_sensed, clutterbench.support.scorecard and baselines)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.testset import dataset_arrays, export_testset, labelled_arrays
from clutterbench.data.testset_load import load
from clutterbench.data.testset_sensed import IDEAL, export_sensed, sensed_root, track_dir
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
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
    ideal = export_testset(parts, sim.camera, thresholds, cfg.min_pixels, OUT, sim.physics)
    sensed = {name: export_sensed(OUT, name, sim.camera)["sha256"] for name in cfg.sensing[:1]}
    write_json(sensed_root(OUT) / "tracks.json", sensed)  # the out exists with no track too
    physics = (trials.ch6, cfg.test.catalogue, cfg.min_pixels)
    for track in (IDEAL, *sensed):
        score_baselines(load(track_dir(OUT, track)), track, cfg.model, sim, physics)
    leaderboard(BOARD, BOARD, ideal["sha256"], sensed)


def score_baselines(ts: dict, track: str, model: str, sim: SimConfig, physics: tuple) -> None:
    """Every baseline's row on one track of the test set: baselines/<name>.json on the ideal
    track, baselines/<name>@<preset>.json on a sensed one."""
    for name, (make, about) in baselines(
        ts, Path(f"models/{model}/best.pt"), Path("models/box_head/best.pt"), sim, physics
    ).items():
        card = score(ts, make(), name, about)
        write_row(card, BOARD / "baselines", name if track == IDEAL else f"{name}@{track}")
        print(f"{name} ({track}): pull_collapse AUROC {card['pull_collapse']['auroc']}")


def ch6_streams(trials: TrialsConfig) -> dict[str, int]:
    """Each stream of the ch. 6 conditions (Table 6.3) -> the most episodes one runs on it."""
    out: dict[str, int] = {}
    for cond in trials.conditions.values():
        out[cond.stream] = max(out.get(cond.stream, 0), cond.episodes)
    return out


if __name__ == "__main__":
    run_stage(testset)

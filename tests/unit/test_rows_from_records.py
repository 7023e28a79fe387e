"""Every committed row that quotes a trial or test-set figure is recomputed here from the
committed records, so a row can never go stale quietly: the leaderboard (predictor rows from
their scorecards and the published test set, planner rows from the episodes they won and the
trials records), each trials summary.json from its records.jsonl, and the README's Table 6.3
rows from the records. A failure names the row and how to regenerate it."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from clutterbench.config import load_base, load_params, load_section
from clutterbench.data.testset_load import load, visible
from clutterbench.data.testset_pins import pin_problems
from clutterbench.data.testset_sensed import sensed_tracks
from clutterbench.envs.board import CRITERIA, repaired
from clutterbench.io import read_json
from clutterbench.report.config import ReportConfig
from clutterbench.report.tables import load_thesis_figures
from clutterbench.support.scorecard import is_fresh, leaderboard
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.records import read_records
from clutterbench.trials.core.stats import aggregate, aggregate_games

ROOT = Path(__file__).resolve().parents[2]
BOARD = ROOT / "reports/leaderboard"
TRIALS = ROOT / "reports/trials"
PUBLISHED = ROOT / "data/published/testset"


def _cards(kind: str | None = None) -> list[tuple[Path, dict]]:
    cards = [(p, read_json(p)) for p in sorted(BOARD.glob("*/*.json"))]
    if kind == "agent":
        return [(p, c) for p, c in cards if c.get("kind") == "agent"]
    return [(p, c) for p, c in cards if c.get("kind") != "agent"]


def test_the_published_manifest_pins_every_file_of_the_set_its_loader_included():
    manifest = read_json(PUBLISHED / "manifest.json")
    assert pin_problems(PUBLISHED) == []
    files = manifest["files"]
    assert {"scenes.npz", "load_testset.py"} <= set(files)
    assert files["scenes.npz"] == manifest["sha256"]


def test_the_leaderboard_is_its_rows_rewritten_by_the_writer(tmp_path):
    """leaderboard.md and .csv are exactly what the writer makes of the committed rows and the
    published set (`python -m clutterbench.envs.board` rewrites them)."""
    for path, _ in [*_cards(), *_cards("agent")]:
        dst = tmp_path / path.parent.name / path.name
        dst.parent.mkdir(exist_ok=True)
        shutil.copyfile(path, dst)
    sha = read_json(PUBLISHED / "manifest.json")["sha256"]
    leaderboard(tmp_path, tmp_path, sha, sensed_tracks(PUBLISHED))
    for name in ("leaderboard.md", "leaderboard.csv"):
        assert (tmp_path / name).read_text() == (BOARD / name).read_text(), (
            f"reports/leaderboard/{name} is stale: python -m clutterbench.envs.board"
        )


def test_every_published_predictor_row_quotes_the_published_set():
    """Each predictor row not scored on fresh scenes names the published set's hash (a sensed
    track's row: that track's, published beside it) and its scene and pair counts, recounted
    from the set itself (a sensed track has the ideal one's scenes and masks)."""
    ts = load(PUBLISHED)
    scenes = pairs = 0
    for s in range(len(ts["n_objects"])):
        k = len(visible(ts, s))
        if k >= 2:
            scenes, pairs = scenes + 1, pairs + k * (k - 1)
    rows = [(p, c) for p, c in _cards() if not is_fresh(c)]
    assert rows
    tracks = {None: ts["manifest"]["sha256"], **sensed_tracks(PUBLISHED)}
    for path, card in rows:
        got = (card["testset_sha256"], card["scenes"], card["pairs"])
        assert got == (tracks.get(card.get("sensing")), scenes, pairs), path.name


def test_every_agent_row_pairs_with_what_the_trials_records_say_each_planner_won():
    """Each pairing's planner count is the planner's wins over the agent's episodes in the
    committed trials records (needs nothing of the agent's but its row)."""
    rows = _cards("agent")
    assert rows
    stale = []
    for path, card in rows:
        episodes = range(card["first_episode"], card["first_episode"] + card["episodes"])
        for key in CRITERIA:
            for cond, pair in card[f"{key}_paired"].items():
                recs = read_records(TRIALS / cond / "records.jsonl")
                won = sum(bool(r[key]) for r in recs if int(r["episode"]) in episodes)
                if pair["baseline_k"] != won:
                    stale.append(f"{path.name} {key} {cond}: {pair['baseline_k']}, records {won}")
                elif pair["only_agent"] - pair["only_baseline"] != card[key]["k"] - won:
                    stale.append(f"{path.name} {key} {cond}: only-agent/only-planner counts")
    assert not stale, f"stale agent rows (python -m clutterbench.envs.board): {stale}"


def test_every_agent_row_is_its_episodes_paired_with_the_trials_records():
    """An agent row's rates and every pairing, recomputed from the episodes it won and the
    committed trials records (reports/trials/*/records.jsonl)."""
    rows = _cards("agent")
    assert rows
    for path, card in rows:
        assert "episodes_won" in card, f"{path.name}: keeps no episodes_won to recompute from"
        for key in CRITERIA:
            assert card[key]["k"] == len(card["episodes_won"][key]), path.name
        again = repaired(card, TRIALS)
        stale = sorted(
            cond
            for key in CRITERIA
            for cond in set(card[f"{key}_paired"]) | set(again[f"{key}_paired"])
            if card[f"{key}_paired"].get(cond) != again[f"{key}_paired"].get(cond)
        )
        assert again == card, (
            f"{path.relative_to(ROOT)}: stale against the trials records ({', '.join(stale)}): "
            "python -m clutterbench.envs.board"
        )


def _trials_conditions() -> list[str]:
    return sorted(
        p.name
        for p in TRIALS.iterdir()
        if (p / "records.jsonl").is_file() and (p / "summary.json").is_file()
    )


@pytest.mark.parametrize("condition", _trials_conditions())
def test_every_trials_summary_is_its_records(condition):
    """Every figure of a trials summary.json that its records determine is recomputed from
    them (the rates, per step and per episode, their intervals, the means)."""
    records = read_records(TRIALS / condition / "records.jsonl")
    summary = read_json(TRIALS / condition / "summary.json")
    again = aggregate(records).iloc[0].to_dict()
    for key, value in again.items():
        assert key in summary, f"{condition}: summary.json lacks {key}"
        if isinstance(value, float | np.floating) and not isinstance(summary[key], str):
            assert summary[key] == pytest.approx(float(value), nan_ok=True), (condition, key)
        else:
            assert summary[key] == value, (condition, key)


README_TRIAL_FIGURES = ("Fig. 3.15", "Table 4.1", "4.3.3 (text)", "Table 5.2", "Table 6.3")
"""The README's results rows that quote trials (chapters 3 to 6: reports/trials_ch3,
trials_ch4, trials_ch5 and reports/trials)."""


def _tables_from_records(out: Path) -> dict[str, pd.DataFrame]:
    """Fig. 3.15 and Tables 4.1 (and its predetermined-target row), 5.2 and 6.3 rebuilt by the
    report's own builders from the committed trials records, read back as the summary reads
    them."""
    from clutterbench.report.build import by_condition
    from clutterbench.report.fig_3_15 import fig_3_15_table
    from clutterbench.report.table_4_1 import table_4_1, table_4_1_target
    from clutterbench.report.table_5_2 import table_5_2
    from clutterbench.report.table_6_3 import extraction_table

    params = load_params(ROOT / "params.yaml")
    cfg, scale = load_section(ReportConfig, "report", params), load_base(params).scale
    figures = load_thesis_figures(ROOT / cfg.thesis_figures)
    ch4 = by_condition(read_records(ROOT / "reports/trials_ch4/records.jsonl"))
    ch5 = by_condition(read_records(ROOT / "reports/trials_ch5/records.jsonl"))
    not_run = load_section(TrialsConfig, "trials", params).opt_in.skipped
    ch6 = {
        c: read_records(TRIALS / c / "records.jsonl")
        for c in cfg.table_6_3.values()
        if c not in not_run
    }
    games = read_records(ROOT / "reports/trials_ch3/records.jsonl")
    val = read_json(ROOT / "reports/train_slide/metrics.json")["val"]
    fig_3_15_table(aggregate_games(games), games, figures, val, out, out / "f.png", scale)
    table_4_1(ch4, cfg.table_4_1, figures, out, scale)
    table_4_1_target(ch4, cfg.table_4_1_target, figures, out, scale)
    table_5_2(ch5, cfg.table_5_2, figures, out, scale)
    extraction_table(ch6, cfg.table_6_3, figures, out, scale, not_run=not_run)
    names = ("fig_3_15", "table_4_1", "table_4_1_target", "table_5_2", "table_6_3")
    return {name: pd.read_csv(out / f"{name}.csv") for name in names} | {"figures": figures}


def test_the_readme_trial_rows_are_the_trials_records(tmp_path):
    """The README's results rows of Fig. 3.15 and Tables 4.1, 5.2 and 6.3, recomputed by the
    report's own builders and summary code from the committed trials records: none stale,
    none missing, none extra."""
    from clutterbench.report import summary

    frames = _tables_from_records(tmp_path)
    figures = frames.pop("figures")
    rows = [
        *summary._fig_3_15(frames, figures),
        *summary._table_4_1(frames, figures),
        *summary._table_5_2(frames, figures),
        *summary._table_6_3(frames, figures),
    ]
    quoted = tuple(f"| [{f}]" for f in README_TRIAL_FIGURES)
    want = [x for x in summary.summary_markdown(rows, [], "").splitlines() if x.startswith(quoted)]
    readme = (ROOT / "README.md").read_text().splitlines()
    got = [line for line in readme if line.startswith(quoted)]
    stale = sorted(set(got) ^ set(want))
    assert want and got == want, f"README trial rows differ from the records: {stale[:4]}"

"""Tables 6.2 and 6.3 (and 6.3 by scene family) and the support figure, from hand-made
records into a tmp dir."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.report.table_6_2 import mutual_support_note, support_table, thresholds_text
from clutterbench.report.table_6_3 import (
    _gap_text,
    extraction_families_table,
    extraction_table,
    oracle_gaps,
    trial_params_note,
)
from clutterbench.report.tables import load_thesis_figures, thesis_row
from clutterbench.support.figure import SupportPanel, support_figure
from clutterbench.trials.config import Ch6TrialParams
from clutterbench.trials.core.stats import cluster_bootstrap_interval


@pytest.fixture(scope="module")
def figures(root):
    return load_thesis_figures(root / "reports/thesis_figures.yaml")


def trial(
    condition: str,
    planner: str,
    n_objects: int,
    steps_ok: list[bool],
    out: bool,
    family: str = "random",
) -> dict:
    steps = [{"success": ok, "extracted": True, "others_still": ok} for ok in steps_ok]
    return {
        "condition": condition,
        "planner": planner,
        "n_objects": n_objects,
        "stream": "ch6_3_10",
        "family": family,
        "perception": "instance",
        "steps": steps,
        "target_out": out,
        "success": out and all(steps_ok),
        "n_disturbed": 0 if all(steps_ok) else 1,
        "disturbance_m": 0.004,
    }


RECORDS = {
    "ss": [trial("ss", "single_step", n, [ok], ok) for n, ok in ((3, True), (5, False))],
    "ms": [
        trial("ms", "multi_step", 3, [True, True], True),
        trial("ms", "multi_step", 10, [True, False, True], True),
        trial("ms", "multi_step", 7, [True], False),
    ],
    "rnd": [trial("rnd", "random", 4, [False], False)],
}
ROWS = {"single_step/3-5": "ss", "multi_step/3-10": "ms", "random/3-10": "rnd"}


def line_of(md: str, start: str) -> str:
    (line,) = [ln for ln in md.splitlines() if ln.startswith(start)]
    return line


def test_extraction_table_puts_the_thesis_rates_beside_ours(tmp_path, figures):
    raw = extraction_table(RECORDS, ROWS, figures, tmp_path, "tiny", ["extra note"])
    md = (tmp_path / "table_6_3.md").read_text()
    thesis_step = thesis_row(figures, "table_6_3", "multi_step/3-10")
    thesis_episode = thesis_row(figures, "table_6_3", "multi_step_single_arm/per_target")
    multi = line_of(md, "| multi-step extraction")
    # ours: 5 of 6 steps (interval: bootstrap over the 3 episodes), 1 of 3 episodes (Wilson),
    # 2 steps on average; the thesis as printed
    lo, hi = cluster_bootstrap_interval([(2, 2), (2, 3), (1, 1)])
    assert f"5/6 = 83.3% [{100 * lo:.1f}, {100 * hi:.1f}]" in multi
    assert "1/3 = 33.3% [6.1, 79.2]" in multi
    assert f"{thesis_step['success']}/{thesis_step['trials']} = 91.2%" in multi
    assert f"{thesis_episode['success']}/{thesis_episode['trials']} = 80.0%" in multi
    assert "| 2 | 2.3 |" in multi  # mean steps: ours, thesis
    assert "| 3-10 | 3-10 |" in multi  # objects: ours (from the records), thesis
    single = line_of(md, "| single-step:")
    assert "1/2 = 50.0%" in single and "= 85.0%" in single and "80.0%" not in single
    assert "| 4 | — |" in line_of(md, "| random (floor)")  # no thesis row
    assert "- extra note" in md and "tiny scale" in md and "real-robot" in md
    assert list(raw["row"]) == list(ROWS)
    assert raw.iloc[1]["step_success_k"] == 5 and raw.iloc[1]["thesis_mean_steps"] == 2.3
    csv = pd.read_csv(tmp_path / "table_6_3.csv")  # the raw numbers, not the formatted text
    assert csv.loc[1, "success_rate"] == pytest.approx(1 / 3)
    assert csv.loc[1, "mean_disturbance_m"] == pytest.approx(0.004)


def test_extraction_table_names_a_missing_condition_or_a_wrong_planner(tmp_path, figures):
    with pytest.raises(ClutterbenchError, match="condition 'bimanual_3_10'"):
        extraction_table(RECORDS, {"bimanual/3-10": "bimanual_3_10"}, figures, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran planner single_step, not multi_step"):
        extraction_table(RECORDS, {"multi_step/3-10": "ss"}, figures, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="'<method>/<objects>"):
        extraction_table(RECORDS, {"teleport": "ss"}, figures, tmp_path, "t")


FAMILY_RECORDS = {
    "ms": [
        trial("ms", "multi_step", 5, [True, True], True, "stacked"),
        trial("ms", "multi_step", 5, [False, True], True, "stacked"),
        trial("ms", "multi_step", 3, [True], True, "shelved"),
        trial("ms", "multi_step", 4, [False], False, "shelved"),
    ],
    "rnd": [
        trial("rnd", "random", 6, [False, False, False], False, "shelved"),
        trial("rnd", "random", 3, [True], True, "stacked"),
    ],
}
FAMILY_ROWS = {"multi_step/3-10": "ms", "random/3-10": "rnd"}


def test_extraction_families_table_splits_each_row_by_scene_family(tmp_path):
    raw = extraction_families_table(FAMILY_RECORDS, FAMILY_ROWS, tmp_path, "tiny", ["a note"])
    csv = pd.read_csv(tmp_path / "table_6_3_families.csv")
    assert len(raw) == len(csv) == 4
    got = {
        (r.condition, r.family): (
            r.step_success_k,
            r.step_success_n,
            r.success_k,
            r.success_n,
            r.mean_steps,
            r.episodes,
        )
        for r in csv.itertuples()
    }
    # pooled, ms would read 4/6 steps and 2/4 episodes: each family has its own counts
    assert got == {
        ("ms", "shelved"): (1, 2, 1, 2, 1.0, 2),
        ("ms", "stacked"): (3, 4, 1, 2, 2.0, 2),
        ("rnd", "shelved"): (0, 3, 0, 1, 3.0, 1),
        ("rnd", "stacked"): (1, 1, 1, 1, 1.0, 1),
    }
    # rows in the table's order, families sorted within each
    assert list(zip(csv["row"], csv["family"], strict=True)) == [
        ("multi_step/3-10", "shelved"),
        ("multi_step/3-10", "stacked"),
        ("random/3-10", "shelved"),
        ("random/3-10", "stacked"),
    ]
    md = (tmp_path / "table_6_3_families.md").read_text()
    stacked = line_of(md, "| multi-step extraction (CPG order, one arm) [ms] | stacked |")
    lo, hi = cluster_bootstrap_interval([(2, 2), (1, 2)])
    assert (
        f"| 3/4 = 75.0% [{100 * lo:.1f}, {100 * hi:.1f}] | 1/2 = 50.0% [9.5, 90.5] | 2 | 2 |"
        in stacked
    )
    assert "(thesis)" not in md and "- a note" in md and "tiny scale" in md


def test_extraction_families_table_names_a_missing_condition_or_family(tmp_path):
    with pytest.raises(ClutterbenchError, match="condition 'bimanual_3_10'"):
        extraction_families_table(FAMILY_RECORDS, {"bimanual/3-10": "bimanual_3_10"}, tmp_path, "t")
    no_family = {"ms": [{k: v for k, v in r.items() if k != "family"} for r in RECORDS["ms"]]}
    with pytest.raises(ClutterbenchError, match="has no 'family'"):
        extraction_families_table(no_family, {"multi_step/3-10": "ms"}, tmp_path, "t")


def test_trial_params_note_reads_the_ch6_params_in_mm():
    ch6 = Ch6TrialParams(
        moved_threshold_m=0.005, grasp_lift_m=0.003, pull_increment_m=0.02, max_steps=14
    )
    assert trial_params_note(ch6.pull, ch6.max_steps) == (
        "a box moved: its centre moved more than 5.0 mm; the gripper raises the grasped box "
        "by 3.0 mm before pulling it out in 20.0 mm increments; an episode gives up after 14 "
        "attempts."
    )
    flat = Ch6TrialParams(grasp_lift_m=0.0, pull_increment_m=0.0125, max_steps=1)
    assert "without raising it in 12.5 mm increments" in trial_params_note(flat.pull, 1)
    assert trial_params_note(flat.pull, flat.max_steps).endswith("after 1 attempt.")


def _episode(condition: str, planner: str, episode: int, ok: bool) -> dict:
    return trial(condition, planner, 5, [ok], ok) | {"episode": episode}


def test_oracle_gaps_match_each_planner_to_its_ceiling_on_the_same_scenes():
    recs = {
        "or": [_episode("or", "oracle", e, ok) for e, ok in enumerate([True, True, False, True])],
        "oh": [_episode("oh", "oracle_hold", e, True) for e in range(4)],
        "ms": [
            _episode("ms", "multi_step", e, ok) for e, ok in enumerate([True, False, True, False])
        ],
        "bi": [_episode("bi", "bimanual", e, ok) for e, ok in enumerate([True, True, True, False])],
    }
    gaps = oracle_gaps(recs)
    # multi-step: 2/4 against the one-arm oracle's 3/4, and it won episode 2 the oracle lost
    assert gaps["ms"]["oracle"] == "or" and gaps["ms"]["points"] == pytest.approx(25.0)
    assert gaps["ms"]["beat"] == [2]
    # bimanual holds a box: its ceiling is the holding oracle
    assert gaps["bi"]["oracle"] == "oh" and gaps["bi"]["points"] == pytest.approx(25.0)
    assert gaps["bi"]["beat"] == []
    other_stream = {"ms": [r | {"stream": "elsewhere"} for r in recs["ms"]], "or": recs["or"]}
    assert "ms" not in oracle_gaps(other_stream)


def test_an_episode_won_by_holding_during_another_pull_is_named_beside_the_oracle():
    """oracle_hold holds a box only while pulling the target: a bimanual episode that beat it
    holding a box while pulling another box is outside its action set, and the row says so;
    one that held only during the target's pull is not."""
    oracle = [_episode("oh", "oracle_hold", e, False) for e in range(2)]
    planner = [_episode("bi", "bimanual_pull", e, True) | {"target": 0} for e in range(2)]
    planner[0]["steps"] = [{"box": 3, "hold": 1, "success": True}, {"box": 0, "hold": None}]
    planner[1]["steps"] = [{"box": 3, "hold": None, "success": True}, {"box": 0, "hold": 1}]
    gap = oracle_gaps({"oh": oracle, "bi": planner})["bi"]
    assert gap["beat"] == [0, 1] and gap["beat_held_aside"] == [0]
    assert _gap_text(gap, "bi") == (
        "-100.0 (oh; beat it in 2, 1 holding a box during another box's pull)"
    )


def scenes_frame() -> pd.DataFrame:
    nan = math.nan
    rows = [
        # scene, family, n_objects, method, n_true, n_pred, tp, precision, recall
        (0, "stacked", 4, "iou", 2, 1, 1, 1.0, 0.5),
        (1, "stacked", 5, "iou", 4, 4, 2, 0.5, 0.5),
        (2, "random", 6, "iou", 1, 0, 0, nan, 0.0),
        (0, "stacked", 4, "coverage", 2, 3, 2, 2 / 3, 1.0),
        (1, "stacked", 5, "coverage", 4, 2, 2, 1.0, 0.5),
        (2, "random", 6, "coverage", 0, 1, 0, 0.0, nan),
    ]
    cols = ["scene", "family", "n_objects", "method", "n_true", "n_pred", "tp"]
    return pd.DataFrame(rows, columns=[*cols, "precision", "recall"])


def test_support_table_means_over_defined_scenes_and_pools_counts(tmp_path, figures):
    methods = {"iou": "CP + IoU rule (thesis)", "coverage": "CP + coverage rule (eq. 6.2)"}
    params = {"prob_threshold": 0.35, "score_threshold": 0.2, "bbox_margin_px": 3}
    thresholds = {"iou": params | {"adjacency_iou": 0.0, "rule": "iou"}}
    stats = support_table(scenes_frame(), methods, thresholds, figures, tmp_path, "tiny")
    iou, cov = stats.iloc[0], stats.iloc[1]
    # iou: precision over scenes 0, 1 only (scene 2 inferred nothing): (1 + 0.5) / 2
    assert iou["precision"] == pytest.approx(0.75)
    assert iou["recall"] == pytest.approx((0.5 + 0.5 + 0.0) / 3)
    assert iou["pooled_precision"] == pytest.approx(3 / 5)  # sum tp / sum n_pred
    assert iou["pooled_recall"] == pytest.approx(3 / 7)  # sum tp / sum n_true
    assert (iou["scenes"], iou["scenes_precision"], iou["scenes_recall"]) == (3, 2, 3)
    assert cov["precision"] == pytest.approx((2 / 3 + 1.0 + 0.0) / 3)
    assert cov["recall"] == pytest.approx(0.75)
    assert (cov["pooled_precision"], cov["pooled_recall"]) == pytest.approx((4 / 6, 4 / 6))
    md = (tmp_path / "table_6_2.md").read_text()
    mean = thesis_row(figures, "table_6_2", "mean")
    iou_line = line_of(md, "| CP + IoU rule (thesis)")
    assert f"| 0.750 | {mean['precision']:.3f} |" in iou_line
    assert "p>0.35, score>0.20, margin 3 px, adj IoU>0.00" in iou_line
    assert f"{mean['precision']:.3f}" not in line_of(md, "| CP + coverage rule")
    assert "validation scenes" in md and "3 simulated test scenes (random 1, stacked 2)" in md
    fam = (tmp_path / "table_6_2_families.md").read_text()
    assert "| CP + IoU rule (thesis) | stacked | 0.750 | 0.500 |" in fam
    assert "| CP + IoU rule (thesis) | random | — | 0.000 |" in fam


def test_mutual_support_note_counts_pairs_once_per_scene_and_caps_recall(tmp_path, figures):
    # scene 0: 0 <-> 1 mutual, 1 -> 2 not; scene 1: 1 -> 0 alone (no pair across scenes)
    truth = {"0": [[0, 1], [1, 0], [1, 2]], "1": [[1, 0]], "2": []}
    note = mutual_support_note(truth)
    assert note.startswith("mutual support: 2 of the 4 true edges (50.0%) come in mutual pairs")
    assert "pooled recall is at most 0.750," in note
    methods = {"iou": "CP + IoU rule (thesis)"}
    support_table(scenes_frame(), methods, {}, figures, tmp_path, "t", truth)
    assert note in (tmp_path / "table_6_2.md").read_text()
    assert "at most undefined" in mutual_support_note({"0": []})


def test_support_table_names_a_method_without_rows(tmp_path, figures):
    with pytest.raises(ClutterbenchError, match="no rows for method 'oracle_iou'"):
        support_table(scenes_frame(), {"oracle_iou": "oracle"}, {}, figures, tmp_path, "t")
    assert thresholds_text(None) == "—"


def test_thresholds_text_reads_the_gap_test():
    base = {"rule": "iou", "prob_threshold": 0.4, "bbox_margin_px": 2}
    assert thresholds_text(base | {"max_gap_m": 0.05}) == "p>0.40, margin 2 px, surface gap<50 mm"
    assert thresholds_text(base | {"max_gap_m": None}).endswith("no gap test")


def panel(k: int) -> SupportPanel:
    depth = np.full((32, 40), 0.6, dtype=np.float32)
    masks = np.zeros((3, 32, 40), dtype=bool)
    masks[0, 20:30, 4:36] = True
    masks[1, 8:20, 6:18] = True
    masks[2, 8:20, 22:34] = True
    depth[masks.any(axis=0)] = 0.5
    return SupportPanel(depth, masks, [3, 5, 8], {(3, 5), (5, 8)}, {(3, 5), (3, 8)}, f"s{k}")


def test_support_figure_is_byte_identical_across_calls(tmp_path):
    panels = [panel(k) for k in range(4)]
    support_figure(panels, tmp_path / "a.png", "support relations")
    support_figure(panels, tmp_path / "b.png", "support relations")
    a = (tmp_path / "a.png").read_bytes()
    assert a[:8] == b"\x89PNG\r\n\x1a\n" and a == (tmp_path / "b.png").read_bytes()
    support_figure(panels[:1], tmp_path / "c.png", "support relations")
    assert (tmp_path / "c.png").read_bytes() != a
    with pytest.raises(ClutterbenchError, match="1 to 6 panels"):
        support_figure([panel(k) for k in range(7)], tmp_path / "d.png", "too many")


def test_rule_note_names_the_trials_rule_and_its_val_thresholds():
    from clutterbench.report.table_6_3 import rule_note

    used = {"ms": [{"rule": "coverage_gap"}], "or": [{"rule": None}]}
    chosen = {
        "coverage_gap": {
            "rule": "coverage",
            "prob_threshold": 0.3,
            "score_threshold": 0.5,
            "bbox_margin_px": 4,
            "adjacency_iou": 0.05,
            "max_gap_m": 0.05,
        }
    }
    (note,) = rule_note(used, chosen, {"coverage_gap": "CP + coverage rule + gap"})
    assert "coverage_gap (Table 6.2 row 'CP + coverage rule + gap'; p>0.30" in note
    assert "surface gap<50 mm" in note
    assert rule_note({"or": used["or"]}, chosen, {}) == []


def test_support_table_adds_each_method_s_sensed_rows_after_the_exact_ones(tmp_path, figures):
    sensed = scenes_frame()
    sensed["method"] = sensed["method"] + "@d415"
    sensed.loc[sensed["method"] == "iou@d415", "tp"] = 0
    sensed.loc[sensed["method"] == "iou@d415", "precision"] = 0.0
    frame = pd.concat([scenes_frame(), sensed], ignore_index=True)
    methods = {"iou": "CP + IoU rule (thesis)", "coverage": "CP + coverage rule (eq. 6.2)"}
    stats = support_table(frame, methods, {}, figures, tmp_path, "tiny")
    assert list(stats["method"]) == ["iou", "coverage", "iou@d415", "coverage@d415"]
    assert stats.iloc[0]["precision"] == pytest.approx(0.75)  # the exact rows as before
    assert stats.iloc[2]["precision"] == pytest.approx(0.0)
    assert "| CP + IoU rule (thesis), on d415 depth" in (tmp_path / "table_6_2.md").read_text()
    alone = support_table(scenes_frame(), methods, {}, figures, tmp_path, "tiny")
    assert list(alone["method"]) == ["iou", "coverage"]

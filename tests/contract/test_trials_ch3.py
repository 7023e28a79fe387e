"""Chapter 3 games: the episode protocol (a game ends at its first failed slide), the oracle
(it never makes a failing slide), and the record's counts agree with its slides."""

import dataclasses

import pytest

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.data.slides import pile_seed
from clutterbench.parallel import worker_init
from clutterbench.trials.ch3.config import Ch3Config
from clutterbench.trials.ch3.games import ch3_jobs, run_ch3_game


@pytest.fixture(scope="module")
def cfg():
    worker_init(1)
    base = Ch3Config()
    games = dataclasses.replace(
        base.games, n_games=2, variants=("oracle", "random", "no_convnet"), max_slides=3
    )
    return dataclasses.replace(base, games=games)


@pytest.fixture(scope="module")
def games(cfg):
    jobs = ch3_jobs(cfg=cfg, seed_of=lambda g: pile_seed(0, "ch3_test", g), model=None)
    return [run_ch3_game(job).record for job in jobs]


def test_oracle_never_makes_a_failing_slide(games):
    oracle = [g for g in games if g["condition"] == "oracle"]
    assert oracle and all(s["success"] for g in oracle for s in g["steps"])
    assert all(g["pieces_removed"] >= 1 for g in oracle)


def test_a_game_ends_at_its_first_failed_slide_and_counts_its_successes(games, cfg):
    for g in games:
        assert all(s["success"] for s in g["steps"][:-1])
        assert g["pieces_removed"] == sum(s["success"] for s in g["steps"])
        assert len(g["steps"]) <= cfg.games.max_slides
        if g["steps"] and not g["steps"][-1]["success"]:
            assert g["end"] == "slide_failed"
        assert g["end"] in ("slide_failed", "nothing_worth_sliding", "max_slides", "cleared")


def test_variants_play_the_same_piles(games):
    seeds = {}
    for g in games:
        seeds.setdefault(g["game"], set()).add((g["seed"], g["n_pieces"]))
    assert all(len(s) == 1 for s in seeds.values())


def test_every_slide_carries_the_named_fields_and_per_piece_motion(games, cfg, tmp_path):
    """Every slide record has the named outcome every chapter carries and, for every other
    piece on the board, its motion; re-judged from those alone at the game's threshold,
    each game's outcome is the record's."""
    from clutterbench.criteria import MOTION_FIELDS
    from clutterbench.trials import rejudge
    from clutterbench.trials.core.protocol import STEP_FIELDS
    from clutterbench.trials.core.records import read_records, write_records

    named = set(STEP_FIELDS) - {"others_still_held", "success_held"}
    slides = [s for g in games for s in g["steps"]]
    assert slides
    for s in slides:
        assert named <= set(s)
        assert s["executed"] and s["judged"] and s["counted"] and not s["aborted_before_motion"]
        assert s["extracted"] == s["target_out"]
        assert s["success"] == s["strict_success"] == (s["target_out"] and s["others_still"])
        assert s["piece"] not in {e["box"] for e in s["box_motion"]}
        assert all(set(e) == set(MOTION_FIELDS) for e in s["box_motion"])
        thr = cfg.slide.moved_threshold_m
        moved = {e["box"] for e in s["box_motion"] if e["displacement_m"] > thr or e["left_shelf"]}
        assert s["others_still"] == (not moved)
    path = tmp_path / "records.jsonl"
    write_records(path, games)
    for g in read_records(path):
        (row,) = rejudge.rejudge([g], g["moved_threshold_m"], CollapseFreeConfig())
        assert row["success"] == row["strict_success"] == g["success"]


def test_a_convnet_variant_alone_still_needs_the_slide_convnet(root, tmp_path):
    """convnet_no_pomdp reads the ConvNet as convnet does: listed alone, a missing network is
    one line naming it before any game starts (it once reached the workers as None)."""
    import shutil
    import subprocess
    import sys

    import yaml

    params = yaml.safe_load((root / "params.yaml").read_text())
    params["base"]["scale"] = "tiny"
    params["yamakuzushi"]["games"]["variants"] = ["convnet_no_pomdp"]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    shutil.copytree(root / "stages", tmp_path / "stages")
    out = subprocess.run(
        [sys.executable, "stages/trials_ch3.py"], cwd=tmp_path, capture_output=True, text=True
    )
    assert out.returncode != 0
    assert "slide_convnet" in out.stderr.strip().splitlines()[-1]

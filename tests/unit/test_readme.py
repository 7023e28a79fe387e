"""The generated blocks of the README and docs/run-times.md (clutterbench.readme): each is its
committed source, so a hand edit of a block, or a source rewritten without `make readme`,
fails here."""

from __future__ import annotations

from pathlib import Path

import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.readme import (
    BLOCKS,
    RUN_TIMES_DOC,
    leaderboard_body,
    stale_blocks,
    synced,
    with_block,
)

ROOT = Path(__file__).resolve().parents[2]

BOARD = """# Pull-consequence leaderboard

Test set sha256 abc: 3 scenes, 9 (pulled, other) pairs.

| predictor | pull_collapse AUROC |
|---|---|
| truth | 1.000 |
| constant | 0.500 |

## Planners on the benchmark streams

| agent | stream |
|---|---|
| mine | ch6_3_10 |

### mine against each planner on the same episodes (collapse-free)

| condition | both |
|---|---|
| oracle | 3 |
"""


def test_every_generated_block_of_the_readme_is_its_source():
    text = (ROOT / "README.md").read_text()
    assert stale_blocks(text, ROOT) == []
    assert synced(text, ROOT) == text


def test_the_run_times_page_lists_every_committed_record_and_no_time_by_hand():
    text = (ROOT / RUN_TIMES_DOC).read_text()
    assert stale_blocks(text, ROOT, RUN_TIMES_DOC) == []
    assert synced(text, ROOT, RUN_TIMES_DOC) == text
    records = next(b for b in BLOCKS if b.path == RUN_TIMES_DOC)
    edited = with_block(text, records, "- **99.0 min**, whole run\n", RUN_TIMES_DOC)
    assert stale_blocks(edited, ROOT, RUN_TIMES_DOC) == ["run-time records"]


def test_a_hand_edit_of_a_block_is_stale(tmp_path):
    text = (ROOT / "README.md").read_text()
    board = next(b for b in BLOCKS if b.name == "leaderboard")
    edited = with_block(text, board, "| predictor |\n|---|\n| mine | 0.99 |\n")
    assert stale_blocks(edited, ROOT) == ["leaderboard"]
    assert synced(edited, ROOT) == text


def test_the_leaderboard_block_ranks_predictors_and_lists_planners_without_pairings(tmp_path):
    path = tmp_path / "reports/leaderboard/leaderboard.md"
    path.parent.mkdir(parents=True)
    path.write_text(BOARD)
    body = leaderboard_body(tmp_path)
    assert body.index("| truth | 1.000 |") < body.index("| constant | 0.500 |")
    assert "**Planners on the benchmark streams**" in body and "| mine | ch6_3_10 |" in body
    assert "# Pull-consequence" not in body and "against each planner" not in body
    assert "No leaderboard" in leaderboard_body(tmp_path / "elsewhere")


def test_a_readme_without_a_block_is_one_line():
    with pytest.raises(ClutterbenchError, match="no leaderboard block"):
        with_block("# README\n", BLOCKS[1], "x")

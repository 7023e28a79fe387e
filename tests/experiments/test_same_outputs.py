"""experiments/same_outputs: OLD's trial outputs and table cells found byte for byte in
NEW, which may hold more (conditions and columns added since); any changed byte is named."""

from __future__ import annotations

import json
import shutil

from experiments.same_outputs import compare, main


def _checkout(root):
    (root / "reports/trials/a").mkdir(parents=True)
    (root / "data/trials/a").mkdir(parents=True)
    (root / "reports/tables").mkdir(parents=True)
    (root / "reports/trials/records.jsonl").write_text('{"c": "a", "ok": 1}\n')
    (root / "reports/trials/summary.json").write_text(json.dumps({"a": {"k": 1}}))
    (root / "reports/trials/a/episodes.csv").write_text("e,ok\n0,1\n")
    (root / "data/trials/a/ep0.mcap").write_bytes(b"\x00\x01")
    (root / "reports/tables/t.csv").write_text("row,rate\na,0.5\nb,0.25\n")
    return root


def test_new_may_hold_more_but_every_old_byte_and_cell(tmp_path):
    old, new = _checkout(tmp_path / "old"), _checkout(tmp_path / "new")
    with (new / "reports/trials/records.jsonl").open("a") as f:
        f.write('{"c": "b", "ok": 0}\n')
    (new / "reports/trials/summary.json").write_text(json.dumps({"a": {"k": 1}, "b": {}}))
    (new / "reports/tables/t.csv").write_text("row,rate,noise\nb,0.25,x\na,0.5,y\nc,1,z\n")
    assert main([str(old), str(new)]) == 0
    table = compare(old, new)["tables"][0]
    assert table["differ"] == [] and table["added"] == "1 rows, 1 columns"


def test_a_changed_record_episode_or_cell_is_named(tmp_path):
    old = _checkout(tmp_path / "old")
    for broken, change in (
        ("reports/trials/records.jsonl", '{"c": "a", "ok": 0}\n'),
        ("data/trials/a/ep0.mcap", "\x00\x02"),
        ("reports/tables/t.csv", "row,rate\na,0.5\nb,0.26\n"),
    ):
        new = tmp_path / "new"
        shutil.rmtree(new, ignore_errors=True)
        _checkout(new)
        (new / broken).write_text(change)
        result = compare(old, new)
        named = [d for s in result["stages"] for p in ("reports", "data") for d in s[p]["differ"]]
        named += [d for t in result["tables"] for d in t["differ"]]
        assert len(named) == 1 and (broken.split("/")[-1] in named[0] or "b / rate" in named[0])
        assert main([str(old), str(new)]) == 1


def test_rows_named_by_several_leading_cells(tmp_path):
    """A table whose rows are (method, family) pairs, as the per-family tables are."""
    old, new = _checkout(tmp_path / "old"), _checkout(tmp_path / "new")
    body = "method,family,rate\ncp,random,0.5\ncp,shelved,0.25\nbox,random,0.75\n"
    (old / "reports/tables/f.csv").write_text(body)
    (new / "reports/tables/f.csv").write_text(
        "method,family,rate\nbox,random,0.75\ncp,shelved,0.25\ncp,random,0.5\nnew,random,1\n"
    )
    assert main([str(old), str(new)]) == 0
    (new / "reports/tables/f.csv").write_text(body.replace("shelved,0.25", "shelved,0.26"))
    table = [t for t in compare(old, new)["tables"] if t["table"] == "f"][0]
    assert table["differ"] == ["cp / shelved / rate: 0.25 -> 0.26"]

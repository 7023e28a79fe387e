"""The bench's dvc part: dvc's own YAML work, timed on a repository's files."""

from __future__ import annotations

import json

import pytest

from clutterbench.bench.dvc_overhead import bench_dvc


def test_ruamel_reads_yaml_with_its_c_reader_here():
    """dvc reads params.yaml and dvc.lock for every stage; without ruamel.yaml.clib (a
    dependency for that) each read is pure Python, several times slower."""
    import ruamel.yaml

    assert ruamel.yaml.__with_libyaml__


def test_the_dvc_part_times_each_file_and_writes_its_report(tmp_path):
    (tmp_path / "params.yaml").write_text("a:\n  b: 1\n  c: [1, 2]\n")
    (tmp_path / "dvc.yaml").write_text("stages:\n  s:\n    cmd: echo\n")
    lock = "schema: '2.0'\nstages:\n" + "".join(
        f"  s{i}:\n    cmd: echo {i}\n    params:\n      params.yaml:\n        a.b: {i}\n"
        for i in range(3)
    )
    (tmp_path / "dvc.lock").write_text(lock)
    out = tmp_path / "out"
    result = bench_dvc(root=tmp_path, out_dir=out)
    assert result["locked_stages"] == 3
    lock_costs = result["files"]["dvc.lock"]
    assert lock_costs["lines"] == lock.count("\n")
    assert lock_costs["safe_c_s"] >= 0 and lock_costs["roundtrip_load_s"] > 0
    assert "roundtrip_load_s" not in result["files"]["params.yaml"]
    saved = json.loads((out / "dvc.json").read_text())
    assert saved["files"].keys() == {"params.yaml", "dvc.yaml", "dvc.lock"}
    assert "| dvc.lock | " in (out / "dvc.md").read_text()


def test_a_missing_file_is_one_line(tmp_path):
    (tmp_path / "params.yaml").write_text("a: 1\n")
    with pytest.raises(SystemExit, match="dvc.yaml, dvc.lock missing"):
        bench_dvc(root=tmp_path, out_dir=tmp_path / "out")

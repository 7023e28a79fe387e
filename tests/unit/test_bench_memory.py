"""The memory benchmark's measurement: VmHWM tracks allocations; one tiny epoch runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clutterbench.bench.memory import epoch_peak_rss, memory_markdown, peak_rss_mb
from clutterbench.collapse.config import TrainConfig
from clutterbench.config import load_params, load_section
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.data.synthetic import write_synthetic_dataset


def rss_mb() -> float:
    status = Path("/proc/self/status").read_text()
    return int(next(x for x in status.splitlines() if x.startswith("VmRSS:")).split()[1]) / 1024


def test_peak_rss_sees_a_large_allocation():
    before = peak_rss_mb()
    # Rise 64 MiB above the earlier peak, whatever this test process did before.
    block = np.ones(int((before - rss_mb() + 64) * 2**20) // 8)
    assert peak_rss_mb() - before >= 60
    del block
    assert peak_rss_mb() - before >= 60  # a peak, not the current size


def test_tiny_epoch_reports_its_peak(root, tmp_path):
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = "tiny"
    cfg = load_section(TrainConfig, "train", params)
    mcfg = cfg.models["cp_focal"]
    # cp_focal also learns pull labels (labels: [deletion, pull]): the data has pull outcomes
    write_synthetic_dataset(
        tmp_path / "gen", "toy", 8, 4, mcfg.net.input_size, (2, 4), pull_outcomes=True
    )
    split_dataset("toy", Fractions(0.75, 0.25, 0.0), 0, tmp_path / "gen", tmp_path / "split")
    run = epoch_peak_rss(
        tmp_path / "gen", tmp_path / "split/toy.json", cfg, mcfg, 0.005, 2, 1, (0.01, 15.0)
    )
    assert run["train_pairs"] > 0 and run["val_pairs"] > 0
    assert run["peak_rss_mb"] >= 100  # at least torch and the network
    row = {
        "dataset": "toy",
        "scenes": 8,
        "image_size": 64,
        "shard_size": 4,
        "model": "cp_focal",
        "batch_size": mcfg.batch_size,
        "train_batches": 2,
        "decompressed_dataset_mb": 0.1,
        **run,
    }
    assert f"| toy | 8 | {run['train_pairs']} |" in "\n".join(memory_markdown([row]))


def test_the_memory_part_writes_the_labels_its_model_learns(root):
    """bench_train_memory's synthetic ch6 carries what the generate stage writes for ch6 (the
    pull head's pullout_* arrays), so the measured epoch runs (it raised once they were missing)."""
    from clutterbench.bench.memory import bench_train_memory

    params = load_params(root / "params.yaml")
    (row,) = bench_train_memory(params, scale="tiny", factors=(1,), train_batches=1)
    assert (
        row["model"] == "cp_focal"
        and row["scenes"] == params["generate"]["datasets"]["ch6"]["n_scenes"]["tiny"]
    )
    assert row["train_pairs"] > 0 and row["peak_rss_mb"] >= 100

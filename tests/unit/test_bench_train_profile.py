"""The train_profile benchmark's pure pieces: each operator's group from its ancestors, the
groups' self times and shares, the validation batches of a slice, and the markdown."""

from __future__ import annotations

import dataclasses

import pytest

from clutterbench.bench.train_profile import (
    CONV,
    DATA,
    ELEMENTWISE,
    GROUPS,
    OPTIMISER,
    OVERHEAD,
    VALIDATION,
    group_times,
    markdown,
    op_group,
    shares,
    val_batches_per_slice,
)


@pytest.mark.parametrize(
    "names, group",
    [
        (["aten::mkldnn_convolution", "aten::_convolution", "aten::conv2d"], CONV),
        (["aten::copy_", "aten::_to_copy", "aten::to", "aten::conv2d"], CONV),  # its bf16 cast
        (["aten::convolution_backward", "ConvolutionBackward0"], CONV),
        (["aten::native_batch_norm", "aten::batch_norm"], ELEMENTWISE),
        (["aten::copy_", "aten::_to_copy"], ELEMENTWISE),
        (["aten::sqrt", "Optimizer.step#Adam.step"], OPTIMISER),
        (["aten::fill_", "aten::zero_", "Optimizer.zero_grad#Adam.zero_grad"], OPTIMISER),
        (["aten::mkldnn_convolution", "aten::conv2d", "validation"], VALIDATION),
        (["aten::stack", "data_loading"], DATA),
    ],
)
def test_op_group(names, group):
    assert op_group(names) == group


@dataclasses.dataclass
class Event:
    name: str
    self_cpu_time_total: float  # us
    cpu_parent: Event | None = None


def test_group_times_sums_self_time_by_group_and_op():
    conv = Event("aten::conv2d", 100.0)
    step = Event("Optimizer.step#Adam.step", 50.0)
    events = [
        conv,
        Event("aten::mkldnn_convolution", 2_000_000.0, conv),
        Event("aten::native_batch_norm", 1_000_000.0),
        step,
        Event("aten::sqrt", 250_000.0, step),
        Event("aten::sqrt", 250_000.0, step),
        Event("data_loading", 400_000.0),
    ]
    groups, ops = group_times(events)
    assert list(groups) == list(GROUPS)
    assert groups[CONV] == pytest.approx(2.0001)
    assert groups[ELEMENTWISE] == pytest.approx(1.0)
    assert groups[OPTIMISER] == pytest.approx(0.50005)
    assert groups[DATA] == pytest.approx(0.4)
    assert groups[VALIDATION] == 0.0
    assert ops[(OPTIMISER, "aten::sqrt")] == [pytest.approx(0.5), 2]
    table = shares(groups, 5.0)
    assert table[OVERHEAD]["seconds"] == pytest.approx(5.0 - 3.90015)
    assert table[CONV]["share"] == pytest.approx(2.0001 / 5.0)
    assert sum(v["share"] for v in table.values()) == pytest.approx(1.0)
    assert shares(groups, 3.0)[OVERHEAD]["seconds"] == 0.0  # never below 0


def test_val_batches_per_slice():
    # ch6: 90 / 10 split, batch 24, validation batch 32: 48 steps -> 48 * (1/9) * 0.75 = 4
    assert val_batches_per_slice(48, 0.9, 0.1, 24, 32) == 4
    assert val_batches_per_slice(30, 0.8, 0.1, 32, 32) == 4  # 3.75
    assert val_batches_per_slice(2, 0.9, 0.1, 24, 32) == 1  # at least one


def test_markdown_rows():
    groups = shares({g: 1.0 for g in GROUPS if g != OVERHEAD}, 10.0)
    result = {
        "model": "cp_focal",
        "steps": 48,
        "warmup_steps": 5,
        "batch_size": 24,
        "image_size": 128,
        "precision": "bf16",
        "channels_last": True,
        "synthetic_scenes": 400,
        "val_batches": 4,
        "val_batch_size": 32,
        "profiled_seconds": 10.0,
        "profiled_train_seconds": 9.0,
        "unprofiled_train_seconds": 8.0,
        "others_cpu": 0.01,
        "groups": groups,
        "top_ops": [
            {"group": CONV, "op": "aten::convolution_backward", "calls": 96, "seconds": 2.5}
            | {"share": 0.25}
        ],
        "data_loading_alone": {"batches": 60, "ms_per_batch": 12.04, "pairs_per_s": 1992.4},
        "cpu_model": "Some CPU",
        "logical_cpus": 2,
        "torch_threads": 2,
        "machine": "x86_64",
    }
    text = "\n".join(markdown(result))
    assert f"| {CONV} | 1.00 | 10.0 % |" in text
    assert f"| {OVERHEAD} | 5.00 | 50.0 % |" in text
    assert f"| {CONV} | aten::convolution_backward | 96 | 2.50 | 25.0 % |" in text
    assert "12.0 ms per batch, 1992 pairs/s" in text
    assert "used 1.0 % of the CPUs" in text

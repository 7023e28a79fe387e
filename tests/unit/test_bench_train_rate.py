"""The train_rate benchmark's pure pieces: FLOP-rate arithmetic, the shared-core gate, the
conv shapes it records from a training forward, the FLOPs of its conv cases, and the markdown
it writes."""

from __future__ import annotations

import pytest
import torch

from clutterbench.bench import cpu_rates
from clutterbench.bench.cpu_rates import (
    ConvShape,
    Gate,
    combined_rate,
    conv_case,
    gflops_per_s,
    matmul_flops,
    others_share,
    rate_row,
    shares_of,
    step_convs,
    timed,
)
from clutterbench.bench.train_rate_md import markdown, step_table
from clutterbench.bench.train_steps import build_training, step_row
from clutterbench.collapse.config import TrainConfig
from clutterbench.config import load_params, load_section

PEAKS = {"bf16": 400.0, "fp32": 100.0}


def test_matmul_flops_are_two_per_multiply_add():
    assert matmul_flops(4) == 128
    assert matmul_flops(4096) == 2 * 4096**3


def test_gflops_per_s():
    assert gflops_per_s(3e9, 0.5) == pytest.approx(6.0)
    assert gflops_per_s(2 * 4096**3, 0.35) == pytest.approx(392.7, abs=0.1)
    with pytest.raises(ValueError):
        gflops_per_s(1.0, 0.0)


def test_rate_row_is_a_share_of_each_peak():
    row = rate_row(20.0, 0.5, PEAKS)  # 40 GFLOP/s
    assert row == pytest.approx({"gflop_per_s": 40.0, "of_bf16": 0.1, "of_fp32": 0.4})


def test_combined_rate_weights_by_time_not_by_layer():
    rows = [
        {"gflop": 1.0, "count": 2, "seconds": 0.1},  # 10 GFLOP/s, twice per step
        {"gflop": 3.0, "count": 1, "seconds": 0.5},  # 6 GFLOP/s
    ]
    # 5 GFLOP in 0.7 s, not the mean of the layers' rates (8)
    assert combined_rate(rows) == pytest.approx(5.0 / 0.7)


def test_shares_of_recomputes_every_share():
    result = {
        "models": [{"gflop_per_s": 40.0, "of_bf16": 0.0}],
        "variants": [{"variant": "torch.compile", "error": "boom"}],
        "convs": {"total": {"nchw": {"gflop_per_s": 20.0}}},
    }
    shares_of(result, {"bf16": 80.0, "fp32": 10.0})
    assert result["models"][0] == {"gflop_per_s": 40.0, "of_bf16": 0.5, "of_fp32": 4.0}
    assert result["variants"][0] == {"variant": "torch.compile", "error": "boom"}
    assert result["convs"]["total"]["nchw"]["of_bf16"] == 0.25


def _batch(pairs: int, scenes: int, size: int = 32) -> dict[str, torch.Tensor]:
    return {
        "depth_m": torch.zeros(scenes, 1, size, size),
        "target": torch.zeros(pairs, 1, size, size),
    }


def test_others_share_of_the_cpus():
    # 3 CPU s busy in all, 1 of them this process's, over 2 s on 2 CPUs: others used 1 of 4
    assert others_share(3.0, 1.0, 2.0, 2) == pytest.approx(0.5)
    assert others_share(1.0, 1.2, 2.0, 2) == 0.0  # tick rounding: never below 0
    assert others_share(1.0, 0.0, 0.0, 2) == 0.0


class _FakeContention:
    """Contention with the shares of a script, one per `with` block."""

    script: list[float] = []

    def __enter__(self):
        self.others = None
        return self

    def __exit__(self, *exc):
        self.others = _FakeContention.script.pop(0)


def test_gate_repeats_disturbed_runs_and_keeps_the_fastest(monkeypatch):
    monkeypatch.setattr(cpu_rates, "Contention", _FakeContention)
    gate = Gate(idle_wait_s=0.0, attempts=3, clean=0.05)
    runs = iter([[0.5, 0.4], [0.3, 0.35], [0.6]])
    _FakeContention.script = [0.4, 0.2, 0.01]  # disturbed, disturbed, clean
    times, others, attempts = gate.run(lambda attempt: next(runs))
    assert (times, others, attempts) == ([0.3, 0.35], 0.2, 3)
    _FakeContention.script = [0.0]  # clean at once: one run
    times, others, attempts = gate.run(lambda attempt: [float(attempt)])
    assert (times, others, attempts) == ([1.0], 0.0, 1)
    late = Gate(idle_wait_s=0.0, attempts=3, deadline=0.0)
    _FakeContention.script = [0.9]  # past the deadline: no repeat
    assert late.run(lambda attempt: [1.0])[2] == 1


def test_step_row_rates_from_best_and_median_step():
    row = step_row("net", "as is", _batch(24, 4, 128), 16.0, [0.5, 0.4, 0.8], PEAKS)
    assert (row["batch_size"], row["scenes_per_batch"], row["image_size"]) == (24, 4, 128)
    assert row["best_step_s"] == 0.4 and row["median_step_s"] == 0.5
    assert row["gflop_per_s"] == pytest.approx(40.0)
    assert row["median_gflop_per_s"] == pytest.approx(32.0)
    assert row["of_bf16"] == pytest.approx(0.1) and row["of_fp32"] == pytest.approx(0.4)


def test_timed_reps_between_min_and_max():
    calls = []
    assert len(timed(lambda: calls.append(1), 0.0, warmup=2, min_reps=3, max_reps=9)) == 3
    assert len(calls) == 5  # the warm-up calls are not timed
    assert len(timed(lambda: None, 1e9, warmup=0, min_reps=1, max_reps=4)) == 4


def test_step_table_cells():
    row = step_row("cp_focal", "as is", _batch(24, 4, 128), 15.75, [0.4, 0.5, 0.6], PEAKS)
    compiled = {**row, "variant": "torch.compile", "compile_s": 118.4}
    failed = {"model": "cp_focal", "variant": "torch.compile", "error": "boom"}
    row["others_cpu"] = 0.031
    lines = step_table([row, compiled, failed], "variant")
    assert lines[2] == (
        "| as is | 24 (4) | 15.75 | 0.400 / 0.500 | 39.4 / 31.5 | 9.8 % | 39.4 % | 3.1 % |"
    )
    assert lines[3].startswith(
        "| torch.compile (compile 118 s, others' CPU ? meanwhile) | 24 (4) |"
    )
    assert lines[4] == "| torch.compile | | | | failed: boom | | | |"


def test_markdown_states_the_matmul_rates_and_conv_totals():
    row = step_row("cp_focal", "as is", _batch(24, 4, 128), 15.75, [0.4], PEAKS)
    conv = {"conv": "24x16x64x64 -> 32 3x3 /2", "count": 2, "gflop": 0.5}
    conv |= {"nchw_gflop_per_s": 50.0, "channels_last_gflop_per_s": 100.0}
    conv |= {"nchw_others_cpu": 0.02, "channels_last_others_cpu": 0.3}
    total = {"gflop_per_s": 80.0, "of_bf16": 0.2, "of_fp32": 0.8, "seconds_per_step": 0.0125}
    result = {
        "matmul": {
            "bf16": {"n": 4096, "gflop_per_s": 400.0},
            "fp32": {"n": 4096, "gflop_per_s": 100.0},
        },
        "precision": "bf16",
        "channels_last": True,
        "models": [row],
        "variants": [row],
        "convs": {
            "model": "cp_focal",
            "layers": [conv],
            "total": {"nchw": total, "channels_last": total},
        },
        "seconds": 300.0,
        "cpu_model": "Some CPU",
        "logical_cpus": 2,
        "torch_threads": 2,
        "machine": "x86_64",
    }
    text = "\n".join(markdown(result))
    assert "**bf16 400.0 GFLOP/s**, **fp32 100.0 GFLOP/s**" in text
    assert "| 24x16x64x64 -> 32 3x3 /2 | 2 | 0.500 | 50.0 | 100.0 | 30.0 % |" in text
    assert "All of them, channels-last: 0.013 s per step, 80.0 GFLOP/s = 20.0 % of" in text


@pytest.fixture(scope="module")
def tiny_cp(root):
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = "tiny"
    cfg = load_section(TrainConfig, "train", params)
    return cfg, cfg.models["cp_focal"]


def test_step_convs_records_every_conv_of_a_training_forward(tiny_cp):
    cfg, mcfg = tiny_cp
    model, _, _ = build_training(cfg, mcfg, cfg.channels_last)
    size = mcfg.net.input_size
    batch = _batch(5, 2, size) | {"scene_of": torch.tensor([0, 0, 0, 1, 1])}
    batch["depth_m"] += 0.6
    convs = step_convs(model, batch, cfg)
    modules = [m for m in model.modules() if isinstance(m, torch.nn.Conv2d)]
    # the grouped decoder runs each conv fed VGG maps as one conv per input part: the first
    # as three (VGG head, mask code, skip), the next ones as two (upsampled code, skip)
    split = sum(2 if i == 0 else 1 for i in range(len(model.decoder)) if i < 4)
    assert sum(n for _, n in convs) == len(modules) + split
    first = convs[0][0]
    assert first.input == (2, 1, size, size) and not first.input_grad  # the depth encoder
    mask_first = next(c for c, _ in convs if c.input == (5, 1, size, size))
    assert not mask_first.input_grad and mask_first.stride == (2, 2)
    assert all(c.input_grad for c, _ in convs if c.input[1] > 1)


@pytest.mark.parametrize("input_grad, passes", [(False, 2), (True, 3)])
def test_conv_case_flops_forward_and_backward(input_grad, passes):
    from torch.utils.flop_counter import FlopCounterMode

    shape = ConvShape((2, 4, 8, 8), (6, 4, 3, 3), (1, 1), (1, 1), 1, input_grad)
    step, forward = conv_case(shape, channels_last=True)
    forward_flops = 2 * 2 * 6 * 8 * 8 * 4 * 3 * 3  # 2 per MAC, each output sums C*kh*kw
    with FlopCounterMode(display=False) as counter:
        forward()
    assert counter.get_total_flops() == forward_flops
    with FlopCounterMode(display=False) as counter:
        step()
    assert counter.get_total_flops() == passes * forward_flops  # + weight (and input) grad
    assert shape.label() == "2x4x8x8 -> 6 3x3"

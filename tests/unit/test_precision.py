"""Precision per CPU: `auto` never picks emulated bf16 (an AVX2-only CPU gets fp32)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import clutterbench.precision as precision
from clutterbench.bench import machine_line
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.detector import DetectorParams
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.errors import ClutterbenchError
from clutterbench.models import build_model
from clutterbench.platform_info import FLAGS, cpu_flags, instruction_set
from clutterbench.precision import (
    InferenceConfig,
    native_bf16,
    resolve_precision,
    use_for_inference,
)
from tests.contract.test_models import tiny_config

ALL_FLAGS = dict.fromkeys(FLAGS, True)


@pytest.fixture
def cpu(monkeypatch):
    """Pretend to run on a CPU with this torch capability and these flags."""

    def pretend(capability: str, flags: dict[str, bool]) -> None:
        monkeypatch.setattr(precision, "torch_cpu_capability", lambda: capability)
        monkeypatch.setattr(precision, "cpu_flags", lambda: flags)
        precision._native_here.cache_clear()

    monkeypatch.setattr(precision, "_WARNED", set())
    monkeypatch.delenv(precision.INFERENCE_ENV, raising=False)
    yield pretend
    precision._native_here.cache_clear()


def test_auto_is_fp32_where_torch_runs_avx2_kernels_even_if_the_cpu_has_bf16(cpu):
    # ATEN_CPU_CAPABILITY=avx2 on an AVX-512 BF16 CPU: torch's kernels emulate bf16 there
    cpu("AVX2", ALL_FLAGS)
    assert not native_bf16()
    assert resolve_precision("auto") == "fp32"


def test_auto_is_bf16_only_with_avx512_kernels_and_a_bf16_instruction(cpu):
    cpu("AVX512", {"avx2": True, "avx512f": True, "avx512_bf16": True, "amx_bf16": False})
    assert resolve_precision("auto") == "bf16"
    cpu("AVX512", {"avx2": True, "avx512f": True, "avx512_bf16": False, "amx_bf16": True})
    assert resolve_precision("auto") == "bf16"
    cpu("AVX512", {"avx2": True, "avx512f": True, "avx512_bf16": False, "amx_bf16": False})
    assert resolve_precision("auto") == "fp32"


def test_forced_precisions_are_kept_and_emulated_bf16_warns_once(cpu, capsys):
    cpu("AVX2", {"avx2": True})
    assert resolve_precision("fp32") == "fp32"
    assert capsys.readouterr().err == ""
    assert resolve_precision("bf16") == "bf16"
    assert resolve_precision("bf16") == "bf16"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "emulated" in err[0] and "AVX2" in err[0]
    cpu("AVX512", ALL_FLAGS)
    assert resolve_precision("fp32") == "fp32"


def test_bad_precision_values_name_their_key():
    with pytest.raises(ClutterbenchError, match="train.precision"):
        TrainConfig(precision="fp16")
    with pytest.raises(ClutterbenchError, match="inference.precision"):
        InferenceConfig(precision="half")
    with pytest.raises(ClutterbenchError, match="detector.precision"):
        DetectorParams(precision="bfloat16")


def test_train_config_and_predictor_follow_the_cpu(cpu):
    model = torch.nn.Conv2d(1, 1, 1)
    cpu("AVX2", ALL_FLAGS)
    assert not TrainConfig().bf16
    assert CollapsePredictor(model, channels_last=False).precision == "fp32"
    cpu("AVX512", ALL_FLAGS)
    assert TrainConfig().bf16 and not TrainConfig(precision="fp32").bf16
    assert CollapsePredictor(model, channels_last=False).precision == "bf16"
    # the stage's inference.precision reaches predictors built without an explicit one
    assert use_for_inference("fp32") == "fp32"
    assert CollapsePredictor(model, channels_last=False).precision == "fp32"
    assert CollapsePredictor(model, precision="bf16", channels_last=False).bf16


def test_cpu_flags_read_from_cpuinfo(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nmodel name\t: AMD EPYC\nflags\t\t: fpu sse2 avx2 fma\n")
    assert cpu_flags(info) == {
        "avx2": True,
        "avx512f": False,
        "avx512_bf16": False,
        "amx_bf16": False,
    }
    assert cpu_flags(tmp_path / "missing") == dict.fromkeys(FLAGS, False)


def test_machine_line_names_the_instruction_set_and_bf16():
    desc = {
        "cpu_model": "AMD EPYC",
        "torch_cpu_capability": "AVX2",
        "cpu_flags": {"avx2": True, "avx512f": False, "avx512_bf16": False, "amx_bf16": False},
        "logical_cpus": 2,
        "torch_threads": 2,
        "machine": "x86_64",
    }
    assert instruction_set(desc) == "torch AVX2; avx2"
    line = machine_line(desc)
    assert "AMD EPYC (torch AVX2; avx2; bf16 emulated)" in line
    desc |= {"torch_cpu_capability": "AVX512", "cpu_flags": ALL_FLAGS}
    assert "bf16 native" in machine_line(desc)


def test_bf16_predictor_runs_autocast_and_stays_close_to_fp32():
    """`bf16` really changes the arithmetic (bits differ) and only slightly (probabilities)."""
    torch.manual_seed(0)
    model = build_model("collapse_map", tiny_config("collapse_map"))
    size = model.cfg.input_size
    rng = np.random.default_rng(0)
    depth = (0.5 + 0.3 * rng.random((size, size))).astype(np.float32)
    masks = (rng.random((3, size, size)) > 0.9).astype(np.float32)
    fp32 = CollapsePredictor(model, precision="fp32", channels_last=False)(depth, masks)
    bf16 = CollapsePredictor(model, precision="bf16", channels_last=False)(depth, masks)
    assert not np.array_equal(fp32, bf16)
    assert np.abs(fp32 - bf16).max() < 0.05

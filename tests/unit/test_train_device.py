"""Where training runs: $CLUTTERBENCH_TRAIN_DEVICE (cpu, cuda, auto), one-line errors."""

import pytest
import torch

from clutterbench.collapse.train import DEVICE_ENV, to_device, train_device
from clutterbench.errors import ClutterbenchError


def test_default_is_cpu(monkeypatch):
    monkeypatch.delenv(DEVICE_ENV, raising=False)
    assert train_device() == torch.device("cpu")


def test_env_names_the_device(monkeypatch):
    monkeypatch.setenv(DEVICE_ENV, " CPU ")
    assert train_device() == torch.device("cpu")


def test_auto_takes_the_gpu_only_when_there_is_one(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert train_device("auto") == torch.device("cpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert train_device("auto") == torch.device("cuda")


def test_cuda_without_a_gpu_is_one_line(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ClutterbenchError, match="sees no GPU") as err:
        train_device("cuda")
    assert "\n" not in str(err.value)


def test_unknown_device_is_refused():
    with pytest.raises(ClutterbenchError, match="use cpu, cuda or auto"):
        train_device("tpu")


def test_batches_follow_the_model():
    batch = {"depth_m": torch.zeros(2, 1, 4, 4), "classes": torch.zeros(2, 4, 4, dtype=torch.long)}
    moved = to_device(batch, torch.device("meta"))
    assert {t.device.type for t in moved.values()} == {"meta"}
    assert moved["classes"].dtype == torch.long

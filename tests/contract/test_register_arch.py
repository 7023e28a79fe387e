"""The network registry as an extension point: a toy network registered as a user would
(docs/extending.md) goes through the params parser, the training step, the checkpoint API
and the predictor like the built-in ones."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path

import pytest
import torch
from torch import nn

from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.collapse.train import loss_fn, train_step
from clutterbench.config import bounded, parse
from clutterbench.errors import ClutterbenchError
from clutterbench.models import ARCHS, build_model, register_arch
from clutterbench.models.checkpoint import load_checkpoint, save_checkpoint
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.common import check_input, normalise_depth

SIZE = 32
EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "plain_cnn.py"


@dataclasses.dataclass(frozen=True)
class ToyConfig:
    input_size: int = bounded(128, ge=8)
    n_masks: int = bounded(1, ge=1)
    n_classes: int = bounded(1, ge=1)
    width: int = bounded(8, ge=1)
    depth_range_m: tuple[float, float] = (0.3, 1.0)


class ToyNet(nn.Module):
    """Two 3x3 convolutions over the depth and the masks stacked as channels."""

    def __init__(self, cfg: ToyConfig):
        super().__init__()
        self.cfg = cfg
        self.body = nn.Sequential(
            nn.Conv2d(1 + cfg.n_masks, cfg.width, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(cfg.width, cfg.n_classes, 3, padding=1),
        )

    def forward(self, depth_m: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        check_input(depth_m, masks, self.cfg.input_size, self.cfg.n_masks)
        x = normalise_depth(depth_m, *self.cfg.depth_range_m)
        return self.body(torch.cat([x, masks.to(x.dtype)], dim=1))


@pytest.fixture
def toy():
    register_arch("toy", ToyConfig, ToyNet)
    yield "toy"
    ARCHS.pop("toy")


def _params(arch: str, **net) -> dict:
    model = {"arch": arch, "dataset": "d", "batch_size": 2, "lr": 1e-2, "epochs": 1, "net": net}
    return {"models": {"m": model}, "precision": "fp32", "channels_last": False}


def test_builtin_archs_keep_their_names_and_order():
    assert list(ARCHS)[:2] == ["collapse_map", "fcn8s"]
    assert ARCHS["collapse_map"] == (CollapseMapConfig, CollapseMapNet)


def test_unknown_arch_is_a_one_line_error_naming_the_key(toy):
    with pytest.raises(ClutterbenchError) as err:
        parse(TrainConfig, _params("unet"), "train")
    assert str(err.value) == "train.models.m.arch: 'unet' is not one of collapse_map, fcn8s, toy"


def test_a_name_cannot_be_taken_twice(toy):
    register_arch("toy", ToyConfig, ToyNet)  # the same pair again: a no-op
    with pytest.raises(ValueError, match="already registered"):
        register_arch("toy", CollapseMapConfig, CollapseMapNet)
    with pytest.raises(TypeError, match="must be a dataclass"):
        register_arch("other", dict, ToyNet)


def test_a_registered_network_trains_saves_and_loads(toy, tmp_path):
    cfg = parse(TrainConfig, _params(toy, input_size=SIZE, width=4), "train")
    mcfg = cfg.models["m"]
    assert mcfg.net == ToyConfig(input_size=SIZE, width=4)  # parsed from the params mapping
    with pytest.raises(ClutterbenchError, match=r"train\.models\.m\.net\.width: 0 is out"):
        parse(TrainConfig, _params(toy, input_size=SIZE, width=0), "train")
    torch.manual_seed(0)
    model = build_model(mcfg.arch, mcfg.net).train()
    opt = torch.optim.Adam(model.parameters(), lr=mcfg.lr)
    depth = 0.5 + 0.3 * torch.rand(2, 1, SIZE, SIZE)
    target = torch.zeros(2, 1, SIZE, SIZE)
    target[:, :, 8:16, 8:24] = 1
    batch = {"depth_m": depth, "target": target, "collapse": target.clone()}
    loss = loss_fn(cfg, mcfg)
    first = float(train_step(model, batch, opt, loss, cfg))
    assert float(train_step(model, batch, opt, loss, cfg)) < first

    path = tmp_path / "best.pt"
    save_checkpoint(path, mcfg.arch, model, {"epoch": 1})
    ckpt = load_checkpoint(path)
    assert ckpt.arch == "toy" and ckpt.net == mcfg.net and ckpt.meta == {"epoch": 1}
    model.eval()
    with torch.no_grad():
        assert torch.equal(ckpt.model()(depth, target), model(depth, target))
    predictor = CollapsePredictor.from_checkpoint(path, image_size=SIZE, precision="fp32")
    heat = predictor(depth[0, 0].numpy(), target[:, 0].numpy())
    assert heat.shape == (2, SIZE, SIZE) and 0.0 <= heat.min() <= heat.max() <= 1.0


def test_a_checkpoint_of_an_unregistered_network_is_a_one_line_error(toy, tmp_path):
    path = tmp_path / "best.pt"
    save_checkpoint(path, "toy", build_model("toy", ToyConfig(input_size=SIZE)), {})
    ARCHS.pop("toy")
    try:
        with pytest.raises(ClutterbenchError, match="unknown arch 'toy'"):
            load_checkpoint(path)
    finally:
        register_arch("toy", ToyConfig, ToyNet)


def test_the_documented_example_network_trains_and_round_trips(tmp_path):
    """docs/extending.md's example module, loaded as the package would import it."""
    spec = importlib.util.spec_from_file_location("plain_cnn_example", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    try:
        spec.loader.exec_module(module)
        assert ARCHS["plain_cnn"] == (module.PlainCNNConfig, module.PlainCNN)
        cfg = parse(TrainConfig, _params("plain_cnn", input_size=SIZE, width=4, layers=2), "train")
        mcfg = cfg.models["m"]
        torch.manual_seed(0)
        model = build_model(mcfg.arch, mcfg.net).train()
        opt = torch.optim.Adam(model.parameters(), lr=mcfg.lr)
        depth = 0.5 + 0.3 * torch.rand(2, 1, SIZE, SIZE)
        target = torch.zeros(2, 1, SIZE, SIZE)
        target[:, :, 8:16, 8:24] = 1
        batch = {"depth_m": depth, "target": target, "collapse": target.clone()}
        assert torch.isfinite(train_step(model, batch, opt, loss_fn(cfg, mcfg), cfg))
        path = tmp_path / "best.pt"
        save_checkpoint(path, mcfg.arch, model, {})
        assert load_checkpoint(path).net == mcfg.net
    finally:
        ARCHS.pop("plain_cnn", None)
        del sys.modules[spec.name]

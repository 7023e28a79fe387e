"""Every collapse network: shapes, checkpoint round trip, one-batch overfit, bad checkpoints."""

import dataclasses

import numpy as np
import pytest
import torch

from clutterbench.collapse.losses import bce_loss
from clutterbench.collapse.predict import CollapsePredictor, predict_collapse
from clutterbench.errors import ClutterbenchError
from clutterbench.models import ARCHS, build_model
from clutterbench.models.checkpoint import load_checkpoint, save_checkpoint
from clutterbench.models.vgg import VGG16Encoder, VGGConfig

SIZE = 64


def tiny_config(arch: str):
    cfg_cls = ARCHS[arch][0]
    fields = {f.name for f in dataclasses.fields(cfg_cls)}
    kw = {"input_size": SIZE, "encoder": VGGConfig(width=0.125)}
    if "decoder_channels" in fields:
        kw["decoder_channels"] = (32, 16, 16, 8, 8)
    if "fc_channels" in fields:
        kw["fc_channels"] = 32
    return cfg_cls(**kw)


def scene_batch(n: int = 4, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    depth = 0.5 + 0.3 * torch.rand(n, 1, SIZE, SIZE, generator=g)
    target = torch.zeros(n, 1, SIZE, SIZE)
    truth = torch.zeros(n, 1, SIZE, SIZE)
    for i in range(n):
        target[i, :, 10 + 8 * i : 20 + 8 * i, 10:30] = 1
        truth[i, :, 20:40, 30 + 4 * i : 50] = 1
    return depth, target, truth


@pytest.fixture(params=sorted(ARCHS))
def arch(request):
    return request.param


def test_vgg16_is_configuration_d():
    enc = VGG16Encoder(VGGConfig(width=1.0, batch_norm=False))
    assert [c.out_channels for c in enc.convs()] == [64, 64, 128, 128] + [256] * 3 + [512] * 6
    feats = enc(torch.zeros(1, 1, 64, 64))
    assert [f.shape[-1] for f in feats] == [32, 16, 8, 4, 2]


def test_output_shape_and_dtype(arch):
    torch.manual_seed(0)
    model = build_model(arch, tiny_config(arch)).eval()
    depth, target, _ = scene_batch()
    out = model(depth, target)
    assert out.shape == (4, 1, SIZE, SIZE) and out.dtype == torch.float32
    with pytest.raises(ValueError, match="64x64"):
        model(torch.zeros(1, 1, 32, 32), torch.zeros(1, 1, 32, 32))


def test_checkpoint_round_trip(arch, tmp_path):
    torch.manual_seed(0)
    model = build_model(arch, tiny_config(arch)).eval()
    path = tmp_path / "best.pt"
    save_checkpoint(path, arch, model, {"dataset": "x", "epoch": 3})
    ckpt = load_checkpoint(path)
    assert ckpt.arch == arch and ckpt.net == model.cfg and ckpt.meta["epoch"] == 3
    depth, target, _ = scene_batch()
    with torch.no_grad():
        assert torch.equal(ckpt.model()(depth, target), model(depth, target))
    first = path.read_bytes()
    save_checkpoint(path, arch, model, {"dataset": "x", "epoch": 3})
    assert path.read_bytes() == first  # same weights -> same bytes


def test_one_batch_overfit_drives_loss_down(arch):
    torch.manual_seed(0)
    model = build_model(arch, tiny_config(arch)).train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    depth, target, truth = scene_batch()
    losses = []
    for _ in range(100):
        loss = bce_loss(model(depth, target), truth)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.25 * losses[0], losses[::10]
    model.eval()
    with torch.no_grad():
        pred = torch.sigmoid(model(depth, target)) > 0.5
    iou = (pred & (truth > 0)).sum() / (pred | (truth > 0)).sum()
    assert iou > 0.8


def test_predict_collapse_batches_over_targets(arch):
    torch.manual_seed(0)
    model = build_model(arch, tiny_config(arch))
    depth, target, _ = scene_batch()
    predictor = CollapsePredictor(model, batch_size=3, bf16=False)
    masks = target[:, 0].numpy()
    heat = predict_collapse(predictor, depth[0, 0].numpy(), masks)
    assert heat.shape == (4, SIZE, SIZE) and heat.dtype == np.float32
    assert 0.0 <= heat.min() and heat.max() <= 1.0
    one = predict_collapse(predictor, depth[0, 0].numpy(), masks[2:3])
    np.testing.assert_allclose(heat[2], one[0], atol=1e-5)


def test_checkpoint_errors_are_one_line(arch, tmp_path):
    with pytest.raises(ClutterbenchError, match="not found"):
        load_checkpoint(tmp_path / "missing.pt")
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ClutterbenchError, match="unreadable"):
        load_checkpoint(bad)
    path = tmp_path / "best.pt"
    save_checkpoint(path, arch, build_model(arch, tiny_config(arch)), {})
    with pytest.raises(ClutterbenchError, match="takes 64x64 images but the data are 128x128"):
        CollapsePredictor.from_checkpoint(path, image_size=128)

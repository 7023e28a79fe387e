"""The grouped benchmark's FLOP ceiling: the parts add up to the per-pair network, one target
per scene buys nothing, and the ceiling rises towards (encoder + decoder) / decoder."""

from __future__ import annotations

import pytest

from clutterbench.bench.grouped import flop_ceiling
from clutterbench.collapse.config import TrainConfig
from clutterbench.config import load_params, load_section
from clutterbench.models import build_model


@pytest.fixture(scope="module")
def tiny_nets(root):
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = "tiny"
    cfg = load_section(TrainConfig, "train", params)
    return {
        name: build_model(cfg.models[name].arch, cfg.models[name].net)
        for name in ("cp_focal", "ch4_various")
    }


@pytest.mark.parametrize("name", ["cp_focal", "ch4_various"])
def test_parts_add_up_to_the_per_pair_network(tiny_nets, name):
    f = flop_ceiling(tiny_nets[name], 1.0)
    parts = f["encoder_gflop"] + f["decoder_scene_gflop"] + f["decoder_target_gflop"]
    assert f["encoder_gflop"] > 0 and f["decoder_scene_gflop"] > 0 and f["decoder_target_gflop"] > 0
    assert parts == pytest.approx(f["pair_gflop"], rel=1e-9)
    assert f["ceiling"] == pytest.approx(1.0, rel=1e-9)  # one target: nothing shared


def test_ceiling_rises_with_targets_per_scene_below_its_limit(tiny_nets):
    net = tiny_nets["cp_focal"]
    ceilings = [flop_ceiling(net, n)["ceiling"] for n in (2.0, 4.0, 8.0)]
    assert ceilings[0] < ceilings[1] < ceilings[2]
    f = flop_ceiling(net, 1e9)
    limit = f["pair_gflop"] / f["decoder_target_gflop"]
    assert f["ceiling"] == pytest.approx(limit, rel=1e-6)

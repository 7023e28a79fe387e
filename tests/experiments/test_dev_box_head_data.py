"""experiments/box_head_data: each variant trains on the scenes it names, every one is scored on the
stage's val scenes, and the unseen-val variant never reads those."""

from __future__ import annotations

import numpy as np
import pandas as pd

from clutterbench.collapse.box_head import OUTPUTS, feature_names
from clutterbench.support.box_train import Pairs
from clutterbench.support.config import BoxHeadConfig
from experiments.box_head_data import markdown, score, variants


def _pairs(scenes, seed):
    rng = np.random.default_rng(seed)
    n_feat = len(feature_names(("pull", "pull_collapse")))
    rows = pd.DataFrame({"scene": np.repeat(scenes, 6)})
    x = rng.normal(size=(len(rows), n_feat)).astype(np.float32)
    y = (x[:, : len(OUTPUTS)] + 0.3 * rng.normal(size=(len(rows), len(OUTPUTS))) > 0).astype(
        np.float32
    )
    return Pairs(x, y, rows)


def test_each_variant_reads_the_scenes_it_names():
    cfg = BoxHeadConfig(train_scenes=3, val_scenes=2, hidden=8, epochs=2)
    train, val = _pairs([7, 3, 9, 1, 5], 0), _pairs([4, 8, 6, 2], 1)
    named, scored = variants(train, val, cfg)
    scenes = {k: set(p.rows["scene"]) for k, (p, _) in named.items()}
    assert set(scored.rows["scene"]) == {4, 8}  # the stage's val: the first val_scenes
    assert scenes["stage"] == {7, 3, 9} and scenes["all_train"] == {7, 3, 9, 1, 5}
    assert scenes["unseen_val"] == {6, 2} and scenes["stage_and_unseen_val"] == {7, 3, 9, 6, 2}
    assert [c.hidden for k, (_, c) in named.items() if k.startswith("stage, hidden")] == [16, 32]


def test_a_variant_is_scored_on_the_val_pairs_and_reported():
    cfg = BoxHeadConfig(train_scenes=40, val_scenes=10, hidden=8, epochs=20, batch_size=16, lr=0.01)
    train, val = _pairs(list(range(40)), 0), _pairs(list(range(50, 60)), 1)
    row = score(train, val, cfg, seed=0)
    assert row["train_scenes"] == 40 and row["train_pairs"] == 240 and 1 <= row["best_epoch"] <= 20
    assert all(0.5 < row[f"{o}_auroc"] <= 1 for o in OUTPUTS)  # the labels follow the features
    text = markdown(
        {"val_pairs": 60, "val_scenes": 10, "seconds": 6, "rows": {"stage": row}, "shows": "x"}
    )
    assert "| stage | 40 | 240 | 8 |" in text


def test_decoder_features_average_each_box_then_the_pulled_one():
    import torch

    from experiments.box_head_data import decoder_pair_features

    masks = np.zeros((3, 8, 8), bool)
    masks[0, :4, :4], masks[1, 4:, 4:], masks[2, :2, 4:] = True, True, True
    feats = torch.zeros(3, 2, 4, 4)  # pooled 2x: boxes 0 and 1 cover a quadrant, box 2 half one
    for x in range(3):
        feats[x, 0, :2, :2] = 10 * x
        feats[x, 0, 2:, 2:] = 10 * x + 1
        feats[x, 0, :2, 2:] = 10 * x + 2
        feats[x, 1] = -x
    out = decoder_pair_features(feats, masks)
    assert out.shape == (6, 4)
    # rows (x, y) off the diagonal, row-major: (0,1) (0,2) (1,0) (1,2) (2,0) (2,1)
    np.testing.assert_allclose(out[:, 0], [1, 2, 10, 12, 20, 21])  # channel 0 over box y
    np.testing.assert_allclose(out[:, 1], [0, 0, -1, -1, -2, -2])
    np.testing.assert_allclose(out[:, 2], [0, 0, 11, 11, 22, 22])  # over box x itself


def test_decoder_variants_widen_the_stage_pairs():
    from experiments.box_head_data import with_decoder

    cfg = BoxHeadConfig(train_scenes=3, val_scenes=2, hidden=8, epochs=2)
    train, val = _pairs([7, 3, 9, 1, 5], 0), _pairs([4, 8, 6, 2], 1)
    dec_train = np.ones((len(train), 6), np.float32)
    dec_val = np.ones((len(val), 6), np.float32)
    named = with_decoder(train, val, dec_train, dec_val, cfg)
    n = train.x.shape[1]
    for (tr, va, _), extra in zip(named.values(), (3, 6)):
        assert set(tr.rows["scene"]) == {7, 3, 9} and set(va.rows["scene"]) == {4, 8}
        assert tr.x.shape[1] == va.x.shape[1] == n + extra
        np.testing.assert_array_equal(tr.x[:, :n], train.x[train.rows["scene"].isin([7, 3, 9])])

"""The params of a toy collapse_map training run on synthetic scenes (seconds on one core),
shared by the tests that train a real network end to end."""

from __future__ import annotations

from typing import Any


def toy_train_params(n_scenes: int) -> dict[str, Any]:
    """Params for model `m` (collapse_map at 32 px, one epoch, fp32) on dataset `toy`."""
    return {
        "base": {"seed": 0, "torch_threads": 1, "scale": "tiny"},
        "generate": {
            "datasets": {
                "toy": {"n_scenes": n_scenes, "families": {"random": 1}, "n_objects": [2, 4]}
            }
        },
        "split": {"datasets": {"toy": {"train": 0.75, "val": 0.25, "test": 0.0}}},
        "sim": {"camera": {"fovy_deg": 42.0}},  # a sensor model's focal length in our pixels
        "trials": {"collapse_free": {"drop_m": 0.01, "tilt_deg": 15.0}},  # pull_collapse labels
        "train": {
            "models": {
                "m": {
                    "arch": "collapse_map",
                    "dataset": "toy",
                    "net": {
                        "input_size": 32,
                        "encoder": {"width": 0.0625},
                        "decoder_channels": [8, 8, 8, 8, 8],
                        "mask_channels": [4, 4, 4, 4, 4],
                    },
                    "batch_size": 5,  # no trailing batch of one (BatchNorm)
                    "lr": 0.001,
                    "epochs": 1,
                }
            },
            "precision": "fp32",
            "channels_last": False,
        },
    }

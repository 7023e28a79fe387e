"""PyTorch Dataset over (scene, target) pairs; masks and labels derived at load time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from clutterbench.data.labels import collapse_mask, moved_matrix, target_mask
from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, read_json
from clutterbench.sim.noise import DepthNoiseConfig, add_depth_noise


def load_scenes(
    gen_dir: Path, dataset: str, indices: list[int] | None = None
) -> dict[str, np.ndarray]:
    """Concatenate the shards of `dataset`, keeping only scene `indices` (all if None)."""
    manifest = read_json(Path(gen_dir) / dataset / "manifest.json")
    assert isinstance(manifest, dict)
    parts = [load_npz(Path(gen_dir) / dataset / name) for name in manifest["shards"]]
    for part in parts:
        if str(part["config_hash"]) != manifest["config_hash"]:
            raise ClutterbenchError(
                f"dataset '{dataset}': shard from another config; rerun generate"
            )
    keys = [k for k in parts[0] if k != "config_hash"]
    data = {k: np.concatenate([p[k] for p in parts]) for k in keys}
    if indices is not None:
        pos = {int(s): i for i, s in enumerate(data["scene_index"])}
        missing = [i for i in indices if i not in pos]
        if missing:
            raise ClutterbenchError(
                f"dataset '{dataset}': split names scene {missing[0]} "
                "that the shards do not hold; rerun split"
            )
        rows = np.array([pos[i] for i in indices], dtype=np.int64)
        data = {k: v[rows] for k, v in data.items()}
    return data


class CollapseDataset(Dataset):
    """Items are dicts of float32 tensors (1, H, W): depth_m, target, collapse.

    One item per (scene, target box) pair: thesis 5.2.2 / 6.2.1 sample a target per
    simulation; we use every visible box of every scene, since the removal matrix labels
    them all.
    """

    def __init__(
        self,
        gen_dir: Path,
        split_file: Path,
        split: str,
        threshold_m: float,
        noise: DepthNoiseConfig | None = None,
        flip: bool = False,
        seed: int = 0,
        min_target_pixels: int = 10,
    ):
        record = read_json(split_file)
        if not isinstance(record, dict) or split not in record:
            raise ClutterbenchError(f"{split_file}: no '{split}' split")
        self.scenes = load_scenes(gen_dir, record["dataset"], record[split])
        # A box hidden behind others cannot be chosen as a target from the camera's view.
        visible = [np.bincount(inst.ravel(), minlength=256) for inst in self.scenes["instance"]]
        self.pairs = [
            (s, x)
            for s, n in enumerate(self.scenes["n_objects"])
            for x in range(n)
            if visible[s][x + 1] >= min_target_pixels
        ]
        self.threshold_m, self.noise, self.flip = threshold_m, noise, flip
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        s, x = self.pairs[i]
        n = int(self.scenes["n_objects"][s])
        depth = self.scenes["depth_m"][s]
        instance = self.scenes["instance"][s]
        moved = moved_matrix(self.scenes["removal_m"][s, :n, :n], self.threshold_m)[x]
        if self.noise is not None:
            depth = add_depth_noise(depth, self.noise, self.rng)
        arrays = [depth, target_mask(instance, x), collapse_mask(instance, moved)]
        if self.flip and self.rng.random() < 0.5:
            arrays = [a[:, ::-1] for a in arrays]
        names = ("depth_m", "target", "collapse")
        return {
            k: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))[None]
            for k, a in zip(names, arrays)
        }

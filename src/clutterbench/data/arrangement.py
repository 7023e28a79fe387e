"""One split of a dataset's arrangement clusters (thesis 5.2.1): the depth images and every
visible cluster's class and image box, as the detector trains and is evaluated on them."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from clutterbench.data.shards import ShardStore, load_split
from clutterbench.errors import ClutterbenchError

KEYS = ("scene_index", "family", "depth_m", "cluster_class", "cluster_bbox_px")


@dataclasses.dataclass(frozen=True)
class ArrangementSet:
    """Scenes of one split, in scene-index order."""

    scene_index: np.ndarray
    """(S,) int64 scene indices in the dataset."""
    family: np.ndarray
    """(S,) str scene family of each scene."""
    depth_m: np.ndarray
    """(S, H, W) float32 depth, metres."""
    classes: list[np.ndarray]
    """Per scene (K,) int64 class indices (perception.boxes.ARRANGEMENT_CLASSES)."""
    boxes_px: list[np.ndarray]
    """Per scene (K, 4) float32 (x, y, w, h) boxes; only clusters with visible pixels."""

    def __len__(self) -> int:
        return len(self.scene_index)

    def class_counts(self, n_classes: int) -> np.ndarray:
        """(n_classes,) clusters per class over the split."""
        return np.bincount(
            np.concatenate([np.zeros(0, np.int64), *self.classes]), minlength=n_classes
        )


def visible_clusters(classes: np.ndarray, boxes_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(classes, boxes) of one scene's recorded clusters without the padding (-1) and the
    clusters that no pixel shows (zero-size box)."""
    keep = (classes >= 0) & (boxes_px[:, 2] > 0) & (boxes_px[:, 3] > 0)
    return classes[keep].astype(np.int64), boxes_px[keep].astype(np.float32)


def load_arrangement_split(gen_dir: Path, split_file: Path, which: str) -> ArrangementSet:
    """The `which` ("train" / "val" / "test") scenes of the dataset `split_file` names."""
    record = load_split(split_file, gen_dir)
    wanted = set(int(i) for i in record[which])
    store = ShardStore(gen_dir, record["dataset"], cache_shards=1)
    index, family, depth, classes, boxes = [], [], [], [], []
    for shard in range(store.n_shards):
        a = store.load(shard, KEYS)
        for r, s in enumerate(a["scene_index"]):
            if int(s) not in wanted:
                continue
            c, b = visible_clusters(a["cluster_class"][r], a["cluster_bbox_px"][r])
            index.append(int(s))
            family.append(str(a["family"][r]))
            depth.append(a["depth_m"][r].astype(np.float32))
            classes.append(c)
            boxes.append(b)
    if len(index) != len(wanted):
        raise ClutterbenchError(
            f"{split_file}: {len(wanted) - len(index)} {which} scenes are in no shard; "
            "rerun generate and split"
        )
    order = np.argsort(index, kind="stable")
    h, w = depth[0].shape if depth else (0, 0)
    return ArrangementSet(
        scene_index=np.array(index, dtype=np.int64)[order],
        family=np.array(family, dtype=str)[order],
        depth_m=np.stack(depth)[order] if depth else np.zeros((0, h, w), np.float32),
        classes=[classes[i] for i in order],
        boxes_px=[boxes[i] for i in order],
    )

"""Table 6.2: support relations inferred from one depth image, against physics truth.

Thresholds are chosen on the validation split of the CP's training data (thesis 6.2.1 mixes
shelved, stacked and random scenes); the test scenes come from a trials seed stream of their
own, generated (with every removal simulated from the canonical start) by the same code as
the datasets, and their truth is stored beside them (data/support/truth.json).

Truth: SUPP(X, Y) when removing X moves Y beyond the threshold AND X and Y touch in the
settled scene (PhysX contacts). Objects are the boxes a robot sees (>= min_pixels visible);
as the thesis, we "ignore the case where O_HYP does not correspond to O_GT", so a relation
with a hidden box is in neither graph.

Pull truth (a collapse predictor with pull heads): the same with "removing X" read
as "the trials' executor pulling X out", under the head's label kind (data.labels.label_matrix:
`pull`, Y moves beyond the threshold or leaves the shelf; `pull_collapse`, Y collapses by
trials.collapse_free), from the pullout_* arrays of datasets generated with pull_outcomes:
true; a head's methods are named `<head>_<method>` (`pull_coverage`, `pull_collapse_coverage`)
and are chosen and scored on that head's truth only.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.data.labels import LABEL_ARRAYS, label_matrix
from clutterbench.data.shards import ShardStore, iter_shards, load_split
from clutterbench.data.trial_params import PULL_MAP_HEADS
from clutterbench.errors import ClutterbenchError
from clutterbench.perception.gaps import camera_points  # noqa: F401  (re-exported)
from clutterbench.planning.ch6.support import (
    RULES,
    SceneEvidence,
    SupportParams,
    choose_support_params,
    edge_precision_recall,
    infer_support,
    oracle_heatmaps,
    support_contact,
    surface_gaps,
    sweep_support,
)
from clutterbench.sim.config import CameraConfig

SCENE_KEYS = ("scene_index", "n_objects", "family", "depth_m", "instance", "removal_m", "contact")
PULL_HEADS = tuple(PULL_MAP_HEADS.values())
"""The collapse predictor's heads of the trials' pull (data.labels.LABEL_KINDS; one per
trials.ch6.pull_map_meaning); each gets its own methods, chosen and scored against its own
truth."""


def head_prefix(head: str) -> str:
    """The prefix of head `head`'s method names ('' for the deletion head)."""
    return "" if head == "deletion" else f"{head}_"


def method_head(method: str) -> tuple[str, str]:
    """(head, rule) of a method name: 'pull_collapse_coverage_gap' -> ('pull_collapse',
    'coverage_gap'); 'oracle_coverage' -> ('deletion', 'oracle_coverage')."""
    for head in sorted(PULL_HEADS, key=len, reverse=True):
        if method.startswith(head_prefix(head)):
            return head, method.removeprefix(head_prefix(head))
    return "deletion", method


PredictFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclasses.dataclass
class Scene:
    """One scene as the support evaluation needs it (from a dataset shard)."""

    index: int
    family: str
    depth_m: np.ndarray
    ids: list[int]
    """Visible boxes (>= min_pixels)."""
    masks: np.ndarray
    """(K, H, W) bool."""
    moved: np.ndarray
    """(K, K) bool: ids[b] moved beyond the threshold when ids[a] was removed."""
    contact: np.ndarray
    """(K, K) bool: they touch in the settled scene."""
    n_objects: int
    gaps_m: np.ndarray | None = None
    """(K, K) `surface_gaps` of the visible objects (None: not computed)."""
    moved_by: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    """Pull head -> (K, K) bool: the trials' pull of ids[a] marks ids[b] under that head's
    label kind (PULL_HEADS; only the heads read)."""

    def view(self, head: str) -> Scene:
        """This scene with head `head`'s truth in place of the deletion's, so its
        `true_edges` are that head's truth (the deletion head: the scene itself)."""
        if head == "deletion":
            return self
        assert head in self.moved_by, f"scene read without its {head} truth"
        return dataclasses.replace(self, moved=self.moved_by[head], moved_by={})

    @property
    def true_edges(self) -> set[tuple[int, int]]:
        a, b = np.nonzero(self.moved & self.contact)
        return {(self.ids[i], self.ids[j]) for i, j in zip(a, b) if i != j}


def scene_from_arrays(
    arrays: dict[str, np.ndarray],
    row: int,
    threshold_m: float,
    min_pixels: int,
    camera: CameraConfig | None = None,
    heads: Sequence[str] = (),
    collapse_free: tuple[float, float] | None = None,
) -> Scene:
    """One scene of a shard's arrays, with the truth of each pull head of `heads` too
    (pullout_* arrays; `collapse_free` (drop_m, tilt_deg) for pull_collapse)."""
    n = int(arrays["n_objects"][row])
    instance = arrays["instance"][row]
    counts = np.bincount(instance.ravel(), minlength=256)[1 : n + 1]
    ids = [int(k) for k in np.flatnonzero(counts >= min_pixels)]
    masks = (
        np.stack([instance == k + 1 for k in ids]) if ids else np.zeros((0, *instance.shape), bool)
    )
    removal = arrays["removal_m"][row][np.ix_(ids, ids)]
    moved = np.nan_to_num(removal, nan=0.0) > threshold_m
    np.fill_diagonal(moved, False)
    depth_m = arrays["depth_m"][row].astype(np.float32)
    moved_by = {
        head: label_matrix(head, lambda k: arrays[k][row], n, threshold_m, collapse_free)[
            np.ix_(ids, ids)
        ]
        for head in heads
    }
    return Scene(
        index=int(arrays["scene_index"][row]),
        family=str(arrays["family"][row]),
        depth_m=depth_m,
        ids=ids,
        masks=masks,
        moved=moved,
        contact=arrays["contact"][row][np.ix_(ids, ids)],
        n_objects=n,
        gaps_m=None if camera is None else surface_gaps(camera_points(depth_m, camera), masks),
        moved_by=moved_by,
    )


def scene_keys(store: ShardStore, heads: Sequence[str] = ()) -> tuple[str, ...]:
    """The arrays a scene is read from, with the truth of pull heads `heads`; one line when
    the dataset lacks them."""
    extra = tuple(dict.fromkeys(a for h in heads for a in LABEL_ARRAYS[h]))
    if not set(extra) <= set(store.array_names()):
        raise ClutterbenchError(
            f"dataset '{store.dataset}' holds no pull outcomes (pullout_*), which the pull "
            f"head's support thresholds need; generate it with generate.datasets."
            f"{store.dataset}.pull_outcomes: true"
        )
    return SCENE_KEYS + extra


def split_scenes(
    gen_dir: Path,
    split_file: Path,
    which: str,
    limit: int,
    threshold_m: float,
    min_pixels: int,
    camera: CameraConfig | None = None,
    heads: Sequence[str] = (),
    collapse_free: tuple[float, float] | None = None,
) -> list[Scene]:
    """The first `limit` scenes of a split, in split order (with the truth of pull heads
    `heads`, as scene_from_arrays)."""
    record = load_split(split_file, gen_dir)
    wanted = [int(i) for i in record[which]][:limit]
    order = {s: i for i, s in enumerate(wanted)}
    store = ShardStore(gen_dir, record["dataset"], cache_shards=1)
    keys = scene_keys(store, heads)
    found: dict[int, Scene] = {}
    for shard in range(store.n_shards):
        arrays = store.load(shard, keys)
        for row, s in enumerate(arrays["scene_index"]):
            if int(s) in order:
                found[int(s)] = scene_from_arrays(
                    arrays, row, threshold_m, min_pixels, camera, heads, collapse_free
                )
    return [found[s] for s in wanted if s in found]


def all_scenes(
    gen_dir: Path,
    dataset: str,
    threshold_m: float,
    min_pixels: int,
    camera: CameraConfig | None = None,
    heads: Sequence[str] = (),
    collapse_free: tuple[float, float] | None = None,
) -> Iterator[Scene]:
    """Every scene of a generated dataset (with the truth of pull heads `heads`)."""
    keys = scene_keys(ShardStore(gen_dir, dataset, cache_shards=1), heads)
    for arrays in iter_shards(gen_dir, dataset, keys):
        for row in range(len(arrays["scene_index"])):
            yield scene_from_arrays(
                arrays, row, threshold_m, min_pixels, camera, heads, collapse_free
            )


def sensed_scene(
    scene: Scene, sensing: str, camera: CameraConfig, spread: float = 0.0, seed: int = 0
) -> Scene:
    """`scene` as the sensor `sensing` (sim/sensor.py) would have returned its depth image,
    seeded by `seed` and the picture as every observation is (sim/render.py observe), its
    surface gaps measured on that depth; masks and truth unchanged. `spread` > 0: the preset's
    noise randomised around it first (sim.sensor.randomized, a training augmentation)."""
    from clutterbench.perception.gaps import surface_gaps
    from clutterbench.sim.sensor import (
        focal_px,
        observation_rng,
        pinhole,
        preset,
        randomized,
        sense,
    )

    model = pinhole(focal_px(scene.depth_m.shape[0], camera.fovy_deg), scene.depth_m.shape)
    rng = observation_rng(seed, scene.depth_m)
    sensor = preset(sensing)
    if spread > 0.0:
        sensor = randomized(sensor, rng, spread)
    depth_m = sense(scene.depth_m, model, sensor, rng)
    gaps = scene.gaps_m
    if gaps is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            gaps = surface_gaps(camera_points(depth_m, camera), scene.masks)
    return dataclasses.replace(scene, depth_m=depth_m, gaps_m=gaps)


def segmented_scene(scene: Scene, camera: CameraConfig, min_pixels: int) -> Scene:
    """`scene` with its masks as a robot without ground truth has them, as the trials' rows of
    `perception: depth` see theirs (perception/seen.py): its depth image (sensed, if it was)
    segmented by region growing, each segment named by the box its grasp takes. A segment
    under `min_pixels` or whose grasp takes no visible box is left out; each pair's truth is
    that of the boxes their grasps take, none between two segments of one box; surface gaps
    measured again on the new masks (if the scene had them)."""
    from clutterbench.observation import Observation
    from clutterbench.perception.depth_segmentation import shelf_roi
    from clutterbench.perception.seen import see_segments
    from clutterbench.sim.shelf import Shelf

    shelf = Shelf()  # every chapter 6 scene's
    instance = np.zeros(scene.depth_m.shape, dtype=np.uint8)
    for box, mask in zip(scene.ids, scene.masks):
        instance[mask] = box + 1
    obs = Observation(scene.depth_m, instance, camera.model(shelf.height_m))
    seen = see_segments(obs, shelf_roi(shelf), scene.n_objects, min_pixels)
    counts = np.bincount(seen.obs.instance.ravel(), minlength=256)
    kept = [
        i
        for i, box in sorted(seen.grasps.items())
        if box in scene.ids and counts[i + 1] >= min_pixels
    ]
    rows = np.array([scene.ids.index(seen.grasps[i]) for i in kept], dtype=np.int64)
    other = rows[:, None] != rows[None, :]  # two segments of one box: no truth between them

    def pairs(m: np.ndarray) -> np.ndarray:
        return m[np.ix_(rows, rows)] & other

    masks = (
        np.stack([seen.obs.instance == i + 1 for i in kept])
        if kept
        else np.zeros((0, *instance.shape), bool)
    )
    gaps = None
    if scene.gaps_m is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            gaps = surface_gaps(camera_points(scene.depth_m, camera), masks)
    return dataclasses.replace(
        scene,
        ids=kept,
        masks=masks,
        moved=pairs(scene.moved),
        contact=pairs(scene.contact),
        gaps_m=gaps,
        moved_by={head: pairs(m) for head, m in scene.moved_by.items()},
    )


def evidence(scene: Scene, heatmaps: np.ndarray) -> SceneEvidence:
    return SceneEvidence(heatmaps, scene.masks, scene.ids, scene.true_edges, scene.gaps_m)


def predicted_heatmaps(scene: Scene, predict: PredictFn) -> np.ndarray:
    if not scene.ids:
        return np.zeros((0, *scene.depth_m.shape), np.float32)
    return predict(scene.depth_m, scene.masks.astype(np.uint8))


def sweep_all(
    cp_evidence: Sequence[SceneEvidence],
    oracle_evidence: Sequence[SceneEvidence],
    grid: Any,
    prefix: str = "",
) -> pd.DataFrame:
    """Every rule on the CP's heatmaps and on the oracle collapse map, one frame; methods
    named `prefix` + rule (head_prefix(head): a pull head's, on its truth)."""
    frames = []
    for source, scenes in (("cp", cp_evidence), ("oracle", oracle_evidence)):
        for rule in RULES:
            df = sweep_support(
                scenes,
                rule,
                grid.prob_thresholds if source == "cp" else (0.5,),
                grid.score_thresholds,
                grid.bbox_margins_px,
                grid.adjacency_ious,
                grid.max_gaps_m,
            )
            df.insert(0, "method", prefix + (rule if source == "cp" else f"oracle_{rule}"))
            frames.append(df)
    return pd.concat(frames, ignore_index=True)


def choose_all(sweep: pd.DataFrame) -> dict[str, SupportParams]:
    """Each method's thresholds: the best f1 of mean precision and recall on val scenes, once
    without the surface-gap test (the thesis' rule exactly) and once with it (`_gap`).
    Where no grid point has both means defined (a few val scenes without any true or any
    predicted edge), the pooled f1 decides, ranked below every defined one."""
    denom = 2 * sweep["tp"] + sweep["fp"] + sweep["fn"]
    pooled = np.where(denom > 0, 2 * sweep["tp"] / denom.where(denom > 0, 1), 1.0)
    ranked = sweep.assign(f1=sweep["f1"].fillna(pd.Series(pooled - 2.0, index=sweep.index)))
    no_gap = ranked["max_gap_m"].isna()
    chosen: dict[str, SupportParams] = {}
    for method in dict.fromkeys(sweep["method"]):
        rows = ranked["method"] == method
        rule = method_head(method)[1].removeprefix("oracle_")
        # `method`: exactly the thesis' rule (no surface-gap test); `<method>_gap`: the same
        # rule with the surface-gap test on pseudo-direct contact (ours), where swept.
        if (rows & no_gap).any():
            chosen[method] = choose_support_params(ranked[rows & no_gap], rule)
        if (rows & ~no_gap).any():
            chosen[f"{method}_gap"] = choose_support_params(ranked[rows & ~no_gap], rule)
    return chosen


def val_metrics_at(sweep: pd.DataFrame, method: str, params: SupportParams) -> dict[str, float]:
    """Validation precision / recall / f1 of `method` at its chosen thresholds."""
    rows = sweep[
        (sweep["method"] == method.removesuffix("_gap"))
        & np.isclose(sweep["prob_threshold"], params.prob_threshold)
        & np.isclose(sweep["score_threshold"], params.score_threshold)
        & (sweep["bbox_margin_px"] == params.bbox_margin_px)
        & np.isclose(sweep["adjacency_iou"], params.adjacency_iou)
        & np.isclose(sweep["max_gap_m"].fillna(np.inf), params.max_gap_m or np.inf)
    ]
    r = rows.iloc[0]
    return {k: float(r[k]) for k in ("precision", "recall", "f1")}


def random_edges(
    scene: Scene, params: SupportParams, p_edge: float, rng: np.random.Generator
) -> set[tuple[int, int]]:
    """The floor: each pseudo-contact pair is an edge with probability `p_edge`, in a random
    direction."""
    contact = support_contact(scene.masks, params, scene.gaps_m)
    out = set()
    for a, b in zip(*np.nonzero(np.triu(contact, 1))):
        if rng.random() < p_edge:
            x, y = (a, b) if rng.random() < 0.5 else (b, a)
            out.add((scene.ids[x], scene.ids[y]))
    return out


def contact_edge_rate(scenes: Sequence[Scene], params: SupportParams) -> float:
    """Share of pseudo-contact pairs that hold a true edge (either way) on validation scenes."""
    pairs = edges = 0
    for sc in scenes:
        contact = np.triu(support_contact(sc.masks, params, sc.gaps_m), 1)
        truth = sc.moved & sc.contact
        pairs += int(contact.sum())
        edges += int((contact & (truth | truth.T)).sum())
    return edges / pairs if pairs else 0.0


def evaluate_scene(
    scene: Scene,
    heatmaps: np.ndarray,
    chosen: dict[str, SupportParams],
    p_edge: float | None,
    rng: np.random.Generator,
) -> tuple[list[dict[str, Any]], dict[str, set[tuple[int, int]]]]:
    """Rows of scenes.csv for one test scene (one per method) and each method's edges;
    `p_edge` None: no random row (and no draw from `rng`)."""
    truth = scene.true_edges
    oracle = oracle_heatmaps(scene.moved, scene.masks) if scene.ids else heatmaps
    edges: dict[str, set[tuple[int, int]]] = {}
    for method, params in chosen.items():
        is_oracle = method_head(method)[1].startswith("oracle_")
        maps = oracle if is_oracle else heatmaps
        found = (
            infer_support(maps, scene.masks, scene.ids, params, scene.gaps_m)
            if len(scene.ids) > 1
            else []
        )
        edges[method] = {(e.supporter, e.supported) for e in found}
    if p_edge is not None:
        edges["random"] = (
            random_edges(scene, chosen["coverage"], p_edge, rng) if scene.ids else set()
        )
    rows = []
    for method, pred in edges.items():
        precision, recall = edge_precision_recall(pred, truth)
        rows.append(
            {
                "scene": scene.index,
                "family": scene.family,
                "n_objects": scene.n_objects,
                "visible": len(scene.ids),
                "method": method,
                "n_true": len(truth),
                "n_pred": len(pred),
                "tp": len(pred & truth),
                "precision": precision,
                "recall": recall,
            }
        )
    return rows, edges

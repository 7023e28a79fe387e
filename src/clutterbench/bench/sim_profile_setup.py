"""The sim_profile part's set-up (bench/sim_profile.py): the project directory its samples
run in, their configs at default scale, the randomly initialised networks that stand in for
the trained ones (this machine trains none: the same forward-pass cost, other decisions), a
worker's first picture, and the groups a stage's sample is made of
(bench/sim_profile_stages.py)."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from clutterbench.bench.sim_profile_attribution import each

COPIED = (
    "reports/support/thresholds.json",
    "reports/support/box_fusion.json",
    "reports/box_head/metrics.json",
)
"""Committed reports the stages read (the ch. 5 evaluate metrics: make_project)."""


@dataclasses.dataclass
class Group:
    name: str
    unit: str
    units: int
    """Units the sample runs."""
    full: int
    """Units of this group in the whole stage at default scale."""
    run: Callable[[], object]
    about: str = ""
    phase: bool = False
    """Another phase of work on the units of the group before it (a stage's units count
    them once)."""


@dataclasses.dataclass
class Sample:
    groups: list[Group]
    notes: list[str] = dataclasses.field(default_factory=list)


def plural(n: int, unit: str) -> str:
    """'1 episode', '3 episodes'."""
    return f"{n} {unit}" if n == 1 else f"{n} {unit}s"


def make_project(tmp: Path, repo: Path) -> Path:
    """A project directory for the samples: params.yaml, the benchmark scenes (linked) and the
    committed reports the stages read (copied); the samples write only inside it."""
    from clutterbench.config import load_params

    (tmp / "data").mkdir()
    (tmp / "data" / "benchmark").symlink_to(repo / "data" / "benchmark")
    shutil.copy(repo / "params.yaml", tmp / "params.yaml")
    ch5 = load_params(repo / "params.yaml")["trials"]["ch5"]["model"]
    for rel in (*COPIED, f"reports/evaluate/{ch5}_ch5/metrics.json"):
        if (repo / rel).exists():
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(repo / rel, tmp / rel)
    return tmp


class Context:
    """A sample's configs (default scale) and what it may do outside the profile."""

    def __init__(self, prof: Any):
        from clutterbench.config import BaseConfig, load_params, load_section
        from clutterbench.sim.config import SimConfig
        from clutterbench.trials.config import TrialsConfig

        self.prof, self.upstream_s = prof, 0.0
        params = load_params("params.yaml")
        self.params = {**params, "base": {**params["base"], "scale": "default"}}
        self.base = load_section(BaseConfig, "base", self.params)
        self.sim = load_section(SimConfig, "sim", self.params)
        self.trials = load_section(TrialsConfig, "trials", self.params)

    def section(self, cls: type, key: str) -> Any:
        from clutterbench.config import load_section

        return load_section(cls, key, self.params)

    @contextlib.contextmanager
    def unprofiled(self) -> Iterator[None]:
        """Upstream work: outside the profile and the start-up time (`upstream_s`)."""
        self.prof.disable()
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.upstream_s += time.perf_counter() - t0
            self.prof.enable()

    def untrained(self, *names: str) -> None:
        """models/<name>/best.pt, randomly initialised (default config, seed 0), for each."""
        with self.unprofiled():
            for name in names:
                path = Path("models") / name / "best.pt"
                if not path.exists():
                    path.parent.mkdir(parents=True, exist_ok=True)
                    _save_untrained(self, name, path)


def _save_untrained(ctx: Context, name: str, path: Path) -> None:
    import torch

    from clutterbench.collapse.config import TrainConfig
    from clutterbench.support.config import SupportEvalConfig

    torch.manual_seed(0)
    train = ctx.section(TrainConfig, "train")
    if name in train.models:
        from clutterbench.models import build_model
        from clutterbench.models.checkpoint import save_checkpoint

        m = train.models[name]
        meta: dict[str, Any] = {"name": name, "dataset": m.dataset, "epoch": 0}
        if tuple(m.labels) != ("deletion",):
            meta["heads"] = list(m.labels)
        save_checkpoint(path, m.arch, build_model(m.arch, m.net), meta)
    elif name == "box_head":
        from clutterbench.collapse.box_head import (
            BoxHead,
            BoxHeadMeta,
            feature_names,
            save_box_head,
        )

        cfg = ctx.section(SupportEvalConfig, "support")
        heads = tuple(train.models[cfg.model].labels)
        size = ctx.sim.camera.image_size
        meta_b = BoxHeadMeta(cfg.model, heads, feature_names(heads), cfg.box_head.hidden, size)
        save_box_head(BoxHead(len(meta_b.features), meta_b.hidden), meta_b, path)
    elif name == "detector":
        from clutterbench.collapse.detector import DetectorParams
        from clutterbench.models.detector import ArrangementNet, save_detector

        p = ctx.section(DetectorParams, "detector")
        keep = ("score_threshold", "nms_iou", "max_detections")
        save_detector(path, ArrangementNet(p.net), {k: getattr(p, k) for k in keep})
    elif name == "slide_convnet":
        from clutterbench.collapse.slide_train import SlideTrainConfig
        from clutterbench.models.slide_convnet import SlideConvNet, save_slide_convnet

        cfg_s = ctx.section(SlideTrainConfig, "yamakuzushi.convnet")
        save_slide_convnet(path, SlideConvNet(cfg_s.net), {"seed": 0})
    else:
        raise ValueError(f"no untrained network {name!r}")


def first_picture(ctx: Context) -> None:
    """A worker's set-up (parallel.worker_init: the renderer, one torch thread) and its first
    picture (the renderer's set-up: once per worker process)."""
    from clutterbench.parallel import worker_init
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.render import observe
    from clutterbench.sim.shelf import Shelf

    worker_init(1)
    observe(BoxWorld(Shelf(), ctx.sim.physics, render=True), ctx.sim.camera)


def by_key(
    conditions: dict[str, Any],
    key: Callable[[Any], str],
    jobs_of: Callable[[str, Any], list[Any]],
    fn: Callable[[Any], Any],
    unit: str = "episode",
) -> list[Group]:
    """One group per key of the conditions (in params order): the sample's jobs of each of
    its conditions (jobs_of(name, condition)), its full units their episodes."""
    keyed: dict[str, list[str]] = {}
    for name, cond in conditions.items():
        keyed.setdefault(key(cond), []).append(name)
    groups = []
    for k, names in keyed.items():
        jobs = [j for n in names for j in jobs_of(n, conditions[n])]
        full = sum(conditions[n].episodes for n in names)
        about = ", ".join(names)
        groups.append(Group(k, unit, len(jobs), full, functools.partial(each, fn, jobs), about))
    return groups

"""Params of the train and evaluate stages."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, Literal

from clutterbench.collapse.losses import FocalConfig
from clutterbench.config import bounded
from clutterbench.data.labels import LABEL_KINDS, OUTPUT_CHANNELS
from clutterbench.errors import ClutterbenchError
from clutterbench.models import ARCHS, parse_net_config
from clutterbench.precision import check_precision, resolve_precision
from clutterbench.sim.noise import DepthAugmentation, DepthNoiseConfig, TrainSensingConfig


@dataclasses.dataclass(frozen=True)
class TrainModelConfig:
    arch: str
    """Network: a name in the registry clutterbench.models.ARCHS (built in: collapse_map,
    fcn8s; more with models.register_arch, docs/extending.md)."""
    dataset: str
    """Generated + split dataset to train on (its train / val splits)."""
    # No defaults for the settings the report compares with the thesis: params.yaml says
    # them, the thesis' values live only in reports/thesis_figures.yaml (`settings`).
    batch_size: int = bounded(ge=1)
    """Images per optimizer step."""
    lr: float = bounded(gt=0.0)
    """Adam learning rate."""
    epochs: int = bounded(ge=1)
    """Maximum epochs."""
    net: Any = dataclasses.field(default_factory=dict)
    """The arch's config (CollapseMapConfig / FCN8sConfig fields); its n_masks picks the
    samples: 1 = (scene, target) removals, 2 = (scene, extract, support) pulls (ch. 4)."""
    loss: Literal["bce", "focal", "ce"] = "bce"
    """bce (thesis ch. 5) or focal, eq. (6.1) (thesis ch. 6) on a collapse map (n_classes 1);
    ce: softmax cross-entropy over classes (n_classes > 1, thesis ch. 4)."""
    lr_schedule: Literal["constant", "cosine"] = "constant"
    """constant (thesis) or cosine decay to lr / 100 over `epochs` (short CPU runs)."""
    patience: int = bounded(5, ge=1)
    """Early stopping: stop after this many epochs without a lower validation loss."""
    noise: bool = True
    """Add simulated sensor noise to training depth (thesis 5.2.2)."""
    flip: bool = True
    """Random left-right flips (gravity is symmetric about the shelf's vertical plane;
    thesis 4.3.1 doubles its ch. 4 data this way)."""
    scene_group: int = bounded(8, ge=1)
    """A training batch takes the targets of a scene together, at most this many in a row,
    so that a network that encodes the depth image apart from the masks (collapse_map)
    encodes it once for them all; more scenes per batch with a smaller value."""
    labels: tuple[str, ...] = ("deletion",)
    """What its collapse maps mean, one sigmoid output channel (head) each, in this order,
    on one shared network (data.labels.LABEL_KINDS): deletion (the boxes that move when
    the target is lifted out: the thesis' labels), pull (the boxes that move or leave the
    shelf when the trials pull it out; the dataset needs pull_outcomes: true). More than
    deletion: the collapse_map arch with one input mask and bce or focal loss, summed over
    heads."""
    sensing: TrainSensingConfig | None = None
    """This network's own training sensor (a network for the sensed rows, trained on what they
    see: docs/sensing.md); null: train.sensing, every network's."""


HEADS_ARCH = "collapse_map"
"""The arch whose collapse maps may have several heads (train.models.<m>.labels)."""


def check_heads(m: TrainModelConfig, key: str) -> None:
    """One-line errors when `labels` names an unknown kind, one twice, or heads that the
    network, its masks or its loss cannot have."""
    unknown = [k for k in m.labels if k not in LABEL_KINDS]
    if unknown or not m.labels:
        raise ClutterbenchError(
            f"{key}.labels: {unknown[0] if unknown else 'none'} is no label kind "
            f"(known: {', '.join(LABEL_KINDS)})"
        )
    if len(set(m.labels)) < len(m.labels):
        raise ClutterbenchError(f"{key}.labels: {list(m.labels)} names a kind twice")
    if m.labels == ("deletion",):
        return
    if m.arch != HEADS_ARCH or m.net.n_masks != 1:
        raise ClutterbenchError(
            f"{key}.labels: {list(m.labels)} needs arch {HEADS_ARCH} with one input mask "
            f"(net.n_masks 1), not {m.arch} with {m.net.n_masks}"
        )
    if m.loss == "ce":
        raise ClutterbenchError(
            f"{key}.loss: ce does not fit labels {list(m.labels)} (bce or focal)"
        )
    if m.net.n_classes != len(m.labels):
        raise ClutterbenchError(
            f"{key}.net.n_classes: labels {list(m.labels)} give {len(m.labels)} sigmoid "
            f"channels, not {m.net.n_classes}"
        )


def check_labels(m: TrainModelConfig, key: str) -> None:
    """One-line errors when the network's masks, classes, label kinds and loss do not fit
    together."""
    check_heads(m, key)
    n_masks, n_classes = m.net.n_masks, m.net.n_classes
    if m.labels != ("deletion",):
        return  # one sigmoid channel per head (check_heads)
    if n_masks not in OUTPUT_CHANNELS:
        raise ClutterbenchError(
            f"{key}.net.n_masks: no samples give {n_masks} masks (known: "
            f"{', '.join(map(str, OUTPUT_CHANNELS))})"
        )
    if n_classes not in OUTPUT_CHANNELS[n_masks]:
        raise ClutterbenchError(
            f"{key}.net.n_classes: {n_masks}-mask samples label "
            f"{' or '.join(map(str, OUTPUT_CHANNELS[n_masks]))} channels, not {n_classes}"
        )
    if (m.loss == "ce") != (n_classes > 1):
        need = "ce" if n_classes > 1 else "bce or focal"
        raise ClutterbenchError(f"{key}.loss: {m.loss} does not fit n_classes {n_classes} ({need})")


def depth_augmentation(
    noise_on: bool,
    noise_model: DepthNoiseConfig,
    sensing: TrainSensingConfig,
    input_size: int,
    fovy_deg: float,
) -> DepthAugmentation | None:
    """What a network's training depth passes through (train.<model>, detector): None
    (noise off), the parametric `noise_model` (preset ideal), or the sensing preset's model,
    its noise scaled per image by the spread; the focal length is sim.camera's fovy_deg at
    the network's `input_size`."""
    if not noise_on:
        return None
    if sensing.preset == "ideal":
        return noise_model
    from clutterbench.sim.sensor import SensedAugmentation, focal_px, preset

    sensor = preset(sensing.preset)
    return SensedAugmentation(sensor, focal_px(input_size, fovy_deg), sensing.spread)


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    models: Mapping[str, TrainModelConfig] = dataclasses.field(default_factory=dict)
    """Model name -> its training run; each becomes stage train@<name>, output models/<name>/."""
    model_defaults: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    """What every train.models entry takes unless it says otherwise (its `net` key by key):
    params.yaml states the shared encoder, decoder and schedule once."""
    focal: FocalConfig = FocalConfig()
    """Focal loss parameters (thesis 6.2.1: alpha_1 0.25, alpha_0 0.75, gamma 2)."""
    noise: DepthNoiseConfig = DepthNoiseConfig()
    """Depth noise augmentation."""
    sensing: TrainSensingConfig = TrainSensingConfig()
    """A sensor model as the depth augmentation instead (ideal: the noise above)."""
    channels_last: bool = True
    """NHWC memory format (measured ~2x faster on this CPU; reports/bench/models.md)."""
    precision: str = "auto"
    """auto (bf16 autocast where the CPU runs it natively, else fp32), fp32 or bf16
    (clutterbench.precision; both timed in reports/bench/models.md)."""
    val_threshold: float = bounded(0.5, gt=0.0, le=1.0)
    """Probability above which a pixel counts as collapse in validation metrics."""

    def augmentation(self, name: str, fovy_deg: float) -> DepthAugmentation | None:
        """What model `name`'s training images pass through: None (noise: false), the
        parametric noise, or the sensor preset's model (sim.camera's fovy_deg at the
        network's input size gives our focal length)."""
        m = self.models[name]
        sensing = self.sensing_of(name)
        return depth_augmentation(m.noise, self.noise, sensing, m.net.input_size, fovy_deg)

    def sensing_of(self, name: str) -> TrainSensingConfig:
        """The sensor model `name`'s training depth passes through: its own, else train's."""
        return self.models[name].sensing or self.sensing

    @staticmethod
    def prepare_params(data: Mapping[str, Any]) -> Mapping[str, Any]:
        """The raw section with model_defaults merged under every model's own keys."""
        defaults = data.get("model_defaults")
        models = data.get("models")
        if not isinstance(defaults, Mapping) or not isinstance(models, Mapping):
            return data
        merged = {}
        for name, m in models.items():
            if not isinstance(m, Mapping):
                merged[name] = m
                continue
            m = {**defaults, **m}
            if isinstance(defaults.get("net"), Mapping) and isinstance(m.get("net"), Mapping):
                m["net"] = {**defaults["net"], **m["net"]}
            merged[name] = m
        return {**data, "models": merged}

    def __post_init__(self) -> None:
        check_precision(self.precision, "train.precision")
        for name, m in self.models.items():
            if m.arch not in ARCHS:
                raise ClutterbenchError(
                    f"train.models.{name}.arch: {m.arch!r} is not one of {', '.join(ARCHS)}"
                )
            if isinstance(m.net, Mapping):
                raw = dict(m.net)
                if len(m.labels) > 1 and "n_classes" not in raw:  # one channel per head
                    raw["n_classes"] = len(m.labels)
                net = parse_net_config(m.arch, raw, f"train.models.{name}.net")
                object.__setattr__(m, "net", net)
            check_labels(m, f"train.models.{name}")

    @property
    def bf16(self) -> bool:
        """Whether training runs under bf16 autocast on this CPU (`precision` resolved)."""
        return resolve_precision(self.precision) == "bf16"


@dataclasses.dataclass(frozen=True)
class EvalRunConfig:
    model: str
    """Model name (a key of train.models); its checkpoint is models/<model>/best.pt."""
    dataset: str
    """Dataset whose split is evaluated."""
    val_dataset: str
    """Dataset whose 'val' split chooses the threshold reported beside the params one: the
    evaluated dataset itself, or, where that has no val scenes (ch6_test), the dataset the
    model was trained on. Never the test set, so the choice does not peek at the test."""
    split: Literal["train", "val", "test"] = "test"
    """Which split of `dataset` is evaluated."""
    threshold: float | None = bounded(None, gt=0.0, le=1.0)
    """This run's pixel threshold, where its table states another than evaluate.threshold
    (thesis Table 4.2: 0.4); null: evaluate.threshold."""
    head: str = "deletion"
    """The model's head evaluated, on labels of that kind (data.labels.LABEL_KINDS) of both
    `dataset` and `val_dataset`: deletion (every network), or pull (a network trained with
    train.models.<m>.labels naming it; the datasets need pull_outcomes: true)."""

    def __post_init__(self) -> None:
        if self.head not in LABEL_KINDS:
            raise ValueError(f"head: {self.head!r} is not one of {', '.join(LABEL_KINDS)}")


@dataclasses.dataclass(frozen=True)
class EvaluateConfig:
    threshold: float = bounded(gt=0.0, le=1.0)
    """Thesis 5.3.1: a pixel is collapse when its probability is higher than this (the
    thesis' value: reports/thesis_figures.yaml, table_5_1 eval_threshold)."""
    runs: Mapping[str, EvalRunConfig] = dataclasses.field(default_factory=dict)
    """Run name -> (model, dataset, val_dataset); each becomes stage evaluate@<run>."""
    batch_size: int = bounded(32, ge=1)
    """Targets per forward pass."""
    figure_samples: int = bounded(8, ge=1)
    """Test pairs drawn in the figure (thesis Fig. 5.8 / 6.5)."""

    def for_run(self, run: str) -> EvaluateConfig:
        """This config with run `run`'s own threshold, where it has one."""
        own = self.runs[run].threshold
        return self if own is None else dataclasses.replace(self, threshold=own)

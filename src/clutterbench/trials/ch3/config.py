"""Params of chapter 3, Yamakuzushi (`yamakuzushi`): piles, slides, cameras, the ConvNet's
data and training, the planner and the games. Imports no SAPIEN and no torch."""

from __future__ import annotations

import dataclasses
from typing import Literal

from clutterbench.collapse.slide_train import SlideTrainConfig
from clutterbench.config import bounded, cores_field
from clutterbench.data.slide_crops import ScanConfig
from clutterbench.data.slides import SlideDataConfig
from clutterbench.planning.ch3.yamakuzushi import PomdpConfig, SelectConfig
from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig

VARIANTS = ("convnet", "no_convnet", "convnet_no_pomdp", "random", "oracle")
"""The games of Fig. 3.15: the thesis' method (ConvNet, then the POMDP); without the ConvNet
(the least-occluded piece, then the POMDP); the ConvNet's best piece slid at once, without
the POMDP (its share); a random candidate slid at once (floor); every candidate slide
simulated from the present state, the first success kept (ceiling)."""
CONVNET_VARIANTS = ("convnet", "convnet_no_pomdp")
"""The variants that read the slide ConvNet (models/slide_convnet)."""


@dataclasses.dataclass(frozen=True)
class GamesConfig:
    n_games: int = bounded(100, ge=1)
    """Games per variant (thesis 15); the same piles (seed stream ch3_games) for every
    variant."""
    variants: tuple[
        Literal["convnet", "no_convnet", "convnet_no_pomdp", "random", "oracle"], ...
    ] = VARIANTS
    """Variants played."""
    max_slides: int = bounded(10, ge=1)
    """A game ends after this many slides at most (a pile has at most 10 pieces)."""
    workers: int = cores_field(2)
    """Worker processes playing games; auto: base.cores."""
    mcap_images: bool = True
    """Write depth images (top and sensor views) into the variants' MCAP files."""


@dataclasses.dataclass(frozen=True)
class Ch3Config:
    pile: PileConfig = dataclasses.field(default_factory=PileConfig)
    slide: SlideConfig = dataclasses.field(default_factory=SlideConfig)
    camera: PileCameraConfig = dataclasses.field(default_factory=PileCameraConfig)
    scan: ScanConfig = dataclasses.field(default_factory=ScanConfig)
    data: SlideDataConfig = dataclasses.field(default_factory=SlideDataConfig)
    convnet: SlideTrainConfig = dataclasses.field(default_factory=SlideTrainConfig)
    select: SelectConfig = dataclasses.field(default_factory=SelectConfig)
    pomdp: PomdpConfig = dataclasses.field(default_factory=PomdpConfig)
    games: GamesConfig = dataclasses.field(default_factory=GamesConfig)

    def __post_init__(self) -> None:
        if self.convnet.net.input_size != self.scan.crop_px:
            raise ValueError(
                f"convnet.net.input_size {self.convnet.net.input_size} must equal "
                f"scan.crop_px {self.scan.crop_px}"
            )

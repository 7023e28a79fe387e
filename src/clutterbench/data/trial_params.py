"""The pieces of the trials' params that the layers below the trials read too: where a trial
stream's scenes come from (SceneStreamConfig, held by the `trials` section's streams and the
`support` section's test stream) and which head of the collapse predictor a pull map of each
meaning is (PULL_MAP_HEADS, read by the support stage's evaluation and the trials' planners).

Here, not in trials/config.py, because the support stage stands below the trials and imports
nothing of them; trials/config.py builds its section from these. Imports no SAPIEN and no torch.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Literal

from clutterbench.config import bounded
from clutterbench.data.config import DatasetConfig


@dataclasses.dataclass(frozen=True)
class SceneStreamConfig:
    """Where the scenes of trials come from: a seed stream of its own, never a dataset's."""

    families: Mapping[str, float] = dataclasses.field(default_factory=dict)
    """Scene family -> relative weight."""
    n_objects: tuple[int, int] = bounded((3, 10), ge=1, le=30)
    """Inclusive range of the number of boxes per scene."""
    catalogue: Literal["same", "various", "new"] = "various"
    """Box catalogue the sizes are drawn from."""

    def __post_init__(self) -> None:
        # A stream's scene mix obeys the rules of a dataset's: one validator for both.
        DatasetConfig(
            n_scenes=1,
            families=dict(self.families),
            catalogue=self.catalogue,
            n_objects=self.n_objects,
        )


PULL_MAP_HEADS = {"moved": "pull", "collapse": "pull_collapse"}
"""trials.ch6.pull_map_meaning -> the collapse predictor's head (data.labels.LABEL_KINDS)
whose maps mean the same: every box the pull moves, or only what it collapses."""

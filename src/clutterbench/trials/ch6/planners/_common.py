"""What several ch. 6 planner modules share: the thresholds the support stage chose on
validation scenes (a support rule's, the box head's, the fusion's) and the truth maps a
planner reads (the pull planners' levers beyond Algorithm 1: trials.ch6's `levers`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from clutterbench.data.trial_params import PULL_MAP_HEADS
from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.trials.ch6.truth_maps import TruthCollapseMaps

BOX_HEAD = Path("models/box_head/best.pt")
"""The box planners' per-box head (stage box_head)."""


def sensor_choice(data: dict[str, Any], path: Path, sensing: str) -> dict[str, Any]:
    """The part of a support-stage file (`data`, read from `path`) chosen on the validation
    scenes as `sensing` returned their depth: the file itself for ideal, its
    `sensed.<sensing>` part for a sensor (support.sensing); one line when it has none."""
    if sensing == "ideal":
        return data
    try:
        return data["sensed"][sensing]
    except (KeyError, TypeError):
        raise ClutterbenchError(
            f"{path}: nothing chosen on {sensing} depth; add {sensing} to support.sensing and "
            "rerun the support stage"
        ) from None


def chosen_support(thresholds: Path, rule: str, sensing: str = "ideal") -> SupportParams:
    """The support rule's thresholds chosen on validation scenes by the support stage, on
    their depth as `sensing` returns it."""
    from clutterbench.io import read_json
    from clutterbench.planning.ch6.support import SupportParams

    chosen = sensor_choice(read_json(thresholds), thresholds, sensing)
    try:
        return SupportParams(**chosen["chosen"][rule])
    except (KeyError, TypeError) as exc:
        # pull_<rule>, pull_collapse_<rule>: chosen only where the support model has that head
        hint = " with a support.model that has that pull head" if rule.startswith("pull_") else ""
        raise ClutterbenchError(
            f"{thresholds}: no usable thresholds for rule '{rule}' ({exc}); rerun the support "
            f"stage{hint}"
        ) from None


def box_thresholds(thresholds: Path, meaning: str, sensing: str = "ideal") -> tuple[float, float]:
    """(edge, outcome) thresholds of the box head on the head of pull_map_meaning `meaning`:
    an edge above the first, a pull rejected or aborted when some box's probability is above
    the second; both chosen on validation scenes by the support stage (the edge on their depth
    as `sensing` returns it)."""
    from clutterbench.io import read_json

    head = PULL_MAP_HEADS[meaning]
    try:
        chosen = sensor_choice(read_json(thresholds), thresholds, sensing)["box_head"][head]
        return float(chosen["edge"]), float(chosen["outcome"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ClutterbenchError(
            f"{thresholds}: no box-head thresholds for the {head} head ({exc}); rerun the support "
            "stage after box_head"
        ) from None


def box_fusion(
    thresholds: Path, meaning: str, contact: str = "head", sensing: str = "ideal"
) -> tuple[float, float, tuple[float, ...], tuple[float, ...] | None]:
    """(edge, outcome, weights, contact weights) of the box head fused with physics from
    depth on the head of pull_map_meaning `meaning`: its support-edge and outcome thresholds,
    its logistic weights and, for `contact` learned (trials.ch6.box_contact), the learned
    contact's weights (None: the head's contact), chosen on validation scenes (their depth as
    `sensing` returns it) by the support stage, which writes them beside `thresholds`
    (box_fusion.json)."""
    from clutterbench.io import read_json

    head = PULL_MAP_HEADS[meaning]
    path = thresholds.with_name("box_fusion.json")
    try:
        chosen = sensor_choice(read_json(path), path, sensing)["chosen"][head]
        weights = tuple(float(w) for w in chosen["weights"])
        learned = None
        if contact == "learned":
            learned = tuple(float(w) for w in chosen["contact_weights"])
        return float(chosen["edge"]), float(chosen["outcome"]), weights, learned
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise ClutterbenchError(
            f"{path}: no box-head fusion for the {head} head with the {contact} contact "
            f"({exc}); rerun the support stage after box_head"
        ) from None


def truth_maps_of(planner: Any) -> TruthCollapseMaps | None:
    """The physics-truth maps a planner reads instead of the collapse predictor, if any."""
    from clutterbench.trials.ch6.truth_maps import TruthCollapseMaps

    maps = getattr(planner, "predict", None)
    return maps if isinstance(maps, TruthCollapseMaps) else None

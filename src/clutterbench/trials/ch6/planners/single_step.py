"""The thesis' previous method as the single-step rows of Table 6.3 (ch. 4): pull the
target at once, holding the support of least risk."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from clutterbench.trials.ch6.planners._registry import register_planner

if TYPE_CHECKING:
    from clutterbench.observation import Observation
    from clutterbench.planning.ch6.extraction import Decision


class SupportWhilePullPlanner:
    """The thesis' previous method as the single-step rows of Table 6.3 (their counts equal
    the various-size cells of Table 4.1): pull the target at once while the second arm holds
    the support of least risk r_c chosen by the chapter 4 network (eqs. 4.1, 4.2)."""

    def __init__(self, predictor: Any, params: Any):
        self.predictor, self.params = predictor, params

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        import numpy as np

        from clutterbench.perception.masks import segment
        from clutterbench.planning.ch4.risk_planner import plan_risk
        from clutterbench.planning.ch6.extraction import Decision

        seg = segment(obs, "instance", min_pixels=self.params.min_pixels)
        if target not in seg.ids or len(seg.ids) < 2:
            return Decision(target, None, {"policy": "single_step", "support": None})
        choice, pairs, risks, _ = plan_risk(
            self.predictor, obs, seg, seg.ids.index(target), self.params.ch4_pixel_threshold
        )
        hold = seg.ids[choice.support] if choice.support is not None else None
        finite = np.isfinite(choice.risk)
        state = {
            "policy": "single_step",
            "support": hold,
            "risk": round(float(choice.risk), 4) if finite else None,
        }
        return Decision(target, hold, state)


@register_planner(
    "single_step",
    label="single-step: pull the target, holding the support of least risk (ch. 4)",
    networks=frozenset({"ch4"}),
    holds=True,
    cost="network",
)
def _single_step(job, spec):
    from clutterbench.trials.core.harness import load_predictor

    return SupportWhilePullPlanner(
        load_predictor(job.ch4_model_path, job.camera.image_size), job.params
    )

"""Recheck on dev streams: what the ch. 6 planners on maps of the pull do after an abort.

    python -m experiments.ch6_pull                       # make dev-ch6-pull
    python -m experiments.ch6_pull ch6_pull_thresholds   # make dev-ch6-pull-thresholds
    python -m experiments.ch6_pull ch6_pull_watch        # make dev-ch6-pull-watch
    python -m experiments.ch6_pull ch6_no_plan           # make dev-ch6-no-plan
    python -m experiments.ch6_pull ch6_no_plan_thresholds   # make dev-ch6-no-plan-thresholds
    python -m experiments.ch6_pull ch6_idle_hold         # make dev-ch6-idle-hold
    python -m experiments.ch6_pull ch6_clear             # make dev-ch6-clear
    python -m experiments.ch6_pull ch6_hold              # make dev-ch6-hold
    python -m experiments.ch6_pull ch6_vs_pfd            # make dev-ch6-vs-pfd
    python -m experiments.ch6_pull ch6_box               # make dev-ch6-box
    python -m experiments.ch6_pull ch6_box_physics       # make dev-ch6-box-physics
    python -m experiments.ch6_pull ch6_box_hold          # make dev-ch6-box-hold
    python -m experiments.ch6_pull ch6_release           # make dev-ch6-release
    python -m experiments.ch6_pull ch6_fit_hypotheses    # make dev-ch6-fit-hypotheses
    python -m experiments.ch6_pull ch6_box_contact       # make dev-ch6-box-contact
    python -m experiments.ch6_pull ch6_box_cp_max        # make dev-ch6-box-cp-max
    python -m experiments.ch6_pull ch6_box_edge          # make dev-ch6-box-edge

A collapse score over cp_max stops a pull (Algorithm 1, lines 7-18) or, at a decision,
rejects the box. `trials.ch6.abort_response` says what the planners on maps of the pull
(`*_pull*`) do next: `block` skips the box until a step succeeds (Algorithm 1;
an episode whose every candidate is skipped gives up), `learn` takes the box the score
feared for as carried by the box being pulled (an edge of the collapse prediction graph for
the rest of the episode), so the plan removes that box first or, bimanual, holds it
(planning/ch6/extraction.py). This recheck runs each planner of dev.<section>.planners under each
variant of dev.<section>.variants on the dev streams of dev.<section>.streams (own seeds, never
a table's scenes), and both search oracles on the same scenes; every variant meets the same
scenes and targets, so each is compared with the first, planner by planner and episode by
episode (McNemar's exact test); planners named in dev.<section>.against are also compared
with another planner under the same variant.

Reads the support stage's chosen thresholds (reports/support/thresholds.json) and, where a
planner reads the collapse predictor, models/<trials.ch6.model> (dvc repro trials' upstream
first; the truth-map planners and the oracles need no network). Writes
experiments/reports/<section>.{json,md}; not a dvc stage. Sections: ch6_pull (what an abort teaches,
what the pull maps mean), ch6_pull_thresholds (the pull-head CP planners' thresholds,
trials.ch6.pull_prob_threshold / pull_score_threshold), ch6_pull_watch (their watch of the
pull in depth, trials.ch6.pull_watch_m), ch6_no_plan (what the pull planners do when their
rule rejects every candidate, trials.ch6.when_no_plan), ch6_no_plan_thresholds (the pull-head
CP planners' thresholds once they do that), ch6_idle_hold (the bimanual pull planners' idle
arm, trials.ch6.idle_hold_share), ch6_clear (whose shares their collapse score takes,
trials.ch6.score_over, and when_no_plan clear), ch6_hold (how the bimanual pull
planners score and choose a held pull, trials.ch6.truth_hold and hold_feared), ch6_vs_pfd
(the pull-head CP planners against physics from depth, the params' own settings, on more
episodes than a table has), ch6_box (the box-head planners, per box and learned plus physics,
against physics from depth and the pixel pull planners), ch6_box_physics (the box head fused
per box with physics from depth, support/box_fusion.json, against physics from depth),
ch6_box_hold (how that planner, bimanual, scores a pull made holding a box, trials.ch6.box_hold),
ch6_release (how the executor lets go of an aborted pull's box and of a held box),
ch6_fit_hypotheses (how many scenes the learned-plus-physics planners fit to one observation,
trials.ch6.fit_hypotheses; a variant that changes them gets its fusion chosen again on the
support stage's val scenes, variant_thresholds), ch6_box_contact (the contact in their support
edges, trials.ch6.box_contact: the box head's, or learned from it and the fitted scenes'
contacts; its fusion chosen again likewise), ch6_box_cp_max (the box planners' cp_max,
trials.ch6.box_cp_max: the support stage's outcome threshold or a lower one), ch6_box_edge (their
support graph at the best F1 with the head's contact, or precision-first with the learned
contact, trials.ch6.box_edge_precision; its fusion chosen again likewise).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from experiments.command import OUT, open_recheck, run_command, save
from experiments.config import DevConfig
from experiments.stats import (
    ALPHA,
    CRITERIA,
    below_oracle_text,
    current_variant,
    paired,
    paired_cells,
    plain,
    rate_text,
)

if TYPE_CHECKING:
    from clutterbench.trials.ch6.episodes import Ch6Job

THRESHOLDS = Path("reports/support/thresholds.json")
ORACLE_VARIANT = "-"
"""The oracles read no variant: they run once per stream under this name."""


FUSION_FIELDS = frozenset({"fit_hypotheses", "fit_noise_mm", "box_contact", "box_edge_precision"})
"""Fields of trials.ch6 that change what the box-physics fusion sees: a variant that sets one
gets that fusion chosen again for itself (variant_thresholds)."""


def variant_thresholds(params: Mapping[str, Any], variant: str, ch6: Any, section: str) -> Path:
    """The thresholds file a variant's learned-plus-physics planners read, with its fusion
    (box_fusion.json) beside it: the support stage's own, or, for a variant that sets a
    FUSION_FIELDS field, the fusion chosen again as the support stage chooses it (the same
    val scenes, the box head, the fitted pulls the variant asks for) and written with a copy
    of the stage's thresholds to experiments/reports/<section>/<variant>/."""
    import shutil

    from clutterbench.collapse.box_head import EDGE_HEADS
    from clutterbench.collapse.box_predict import BoxMaps
    from clutterbench.criteria import label_thresholds
    from clutterbench.data.config import GenerateConfig
    from clutterbench.io import write_json
    from clutterbench.precision import inference_from_params
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.support.evaluate import split_scenes
    from clutterbench.support.run import choose_box_fusion, fitted_contacts_of, fitted_pulls_of

    cfg = load_section(SupportEvalConfig, "support", params)
    sim = load_section(SimConfig, "sim", params)
    inference_from_params(params)
    val = split_scenes(
        Path("data/generate"),
        Path(f"data/split/{cfg.val_dataset}.json"),
        "val",
        cfg.val_scenes,
        cfg.moved_threshold_m,
        cfg.min_pixels,
        sim.camera,
        heads=EDGE_HEADS,
        collapse_free=label_thresholds(params),
    )
    model, head = Path(f"models/{cfg.model}/best.pt"), Path("models/box_head/best.pt")
    box_maps = BoxMaps.from_paths(model, head, sim.camera, "pull", 0.5)
    catalogue = load_section(GenerateConfig, "generate", params).datasets[cfg.val_dataset].catalogue
    fusion = choose_box_fusion(
        val,
        box_maps,
        fitted_pulls_of(params, cfg, sim, ch6, catalogue),
        fitted_contacts_of(cfg, sim, ch6, catalogue),
        ch6.box_edge_precision,
    )
    out = OUT / section / variant
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "box_fusion.json", {"chosen": fusion, "val_scenes": len(val)})
    shutil.copyfile(THRESHOLDS, out / THRESHOLDS.name)
    return out / THRESHOLDS.name


def condition_label(variant: str, planner: str) -> str:
    return f"{variant}:{planner}"


def oracle_of(planner: str) -> str:
    """The search oracle of a planner's action set: holding (bimanual) or one arm."""
    return "oracle_hold" if planner.startswith("bimanual") else "oracle"


def trial_jobs(
    dev: DevConfig, params: Mapping[str, Any], section: str = "ch6_pull"
) -> list[Ch6Job]:
    """Every (stream, variant, planner) episode's job, condition "<variant>:<planner>/<stream>",
    with trials.ch6 as params set it but for the variant's overrides, and both oracles'."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6.episodes import (
        box_fields,
        ch6_jobs,
        load_planners,
        planner_info,
        planner_support,
    )
    from clutterbench.trials.config import ConditionConfig, TrialsConfig

    base = load_section(BaseConfig, "base", params)
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    cfg = getattr(dev, section)
    load_planners(trials.planner_modules, cfg.planners)
    predicted = [p for p in cfg.planners if "cp" in planner_info(p).networks]
    if predicted and not Path(f"models/{trials.ch6.model}/best.pt").exists():
        raise ClutterbenchError(
            f"models/{trials.ch6.model}/best.pt missing (planner {predicted[0]} reads it); "
            f"run train@{trials.ch6.model}"
        )
    arms = [(v, p) for v in cfg.variants for p in cfg.planners]
    arms += [(ORACLE_VARIANT, o) for o in ("oracle", "oracle_hold")] * cfg.oracle
    rule = ConditionConfig.__dataclass_fields__["rule"].default
    refit = {  # the variants whose fusion is chosen again for them
        v: variant_thresholds(params, v, dataclasses.replace(trials.ch6, **over), section)
        for v, over in cfg.variants.items()
        if FUSION_FIELDS & set(over)
        and any(planner_info(p).maps == "box_physics" for p in cfg.planners)
    }
    if refit and cfg.sensing != "ideal":
        raise ClutterbenchError(
            f"dev.{section}: a variant that refits the fusion runs on exact depth only "
            f"(sensing {cfg.sensing})"
        )
    jobs = []
    for stream in cfg.streams:
        for variant, planner in arms:
            over = cfg.variants.get(variant, {})
            ch6 = dataclasses.replace(trials.ch6, **over)
            # the planners see through the recheck's sensor; the oracles read the world
            seen = {"sensing": cfg.sensing, "perception": cfg.perception}
            if variant == ORACLE_VARIANT:
                seen = {}
            sensing = seen.get("sensing", "ideal")
            support, cp_max = planner_support(THRESHOLDS, planner, rule, ch6, sensing)
            box, box_cp_max = box_fields(refit.get(variant, THRESHOLDS), planner, ch6, sensing)
            cp_max = box_cp_max if box_cp_max is not None else cp_max
            jobs += ch6_jobs(
                f"{condition_label(variant, planner)}/{stream}",
                ConditionConfig(planner, stream, cfg.episodes, rule, **seen),
                trials=dataclasses.replace(trials, ch6=ch6),
                sim=sim,
                seed=base.seed,
                support=support,
                cp_max=cp_max,
                model_path=Path(f"models/{trials.ch6.model}/best.pt"),
                stream_cfg=dev.streams[stream],
                **box,
            )
    return jobs


def summary_rows(records: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per condition: success and strict success (Wilson 95%), the episodes that gave
    up, and the points below the oracle of the planner's action set on the same stream."""
    from clutterbench.trials.core.stats import aggregate

    rows = []
    for r in aggregate(records).to_dict("records"):
        label, stream = r["condition"].split("/")
        variant, planner = label.split(":")
        mine = [x for x in records if x["condition"] == r["condition"]]
        row = {"condition": r["condition"], "stream": stream, "variant": variant}
        row["planner"] = planner
        for key in CRITERIA:
            row |= {f"{key}_{f}": plain(r[f"{key}_{f}"]) for f in ("k", "n", "rate", "lo", "hi")}
        row["gave_up"] = sum(x["end"] == "gave_up" for x in mine)
        rows.append(row)
    oracles = {(r["stream"], r["planner"]): r for r in rows if r["variant"] == ORACLE_VARIANT}
    for row in rows:
        top = oracles.get((row["stream"], oracle_of(row["planner"])))
        for key in CRITERIA:
            gap = 100 * (top[f"{key}_rate"] - row[f"{key}_rate"]) if top else None
            row[f"{key}_below_oracle_points"] = None if row["variant"] == ORACLE_VARIANT else gap
    return rows


def comparisons(
    records: Sequence[Mapping[str, Any]],
    variants: Sequence[str],
    planners: Sequence[str],
    streams: Sequence[str],
    against: Mapping[str, str] | None = None,
) -> list[dict[str, Any]]:
    """Each variant against the first of `variants`, per stream, planner and criterion; then,
    under each variant, each planner of `against` against its planner there; paired."""
    by_variant = [
        paired(records, condition_label(v, p), condition_label(variants[0], p), stream, key)
        | {"arm": p, "name": v, "other": variants[0]}
        for stream in streams
        for p in planners
        for v in variants[1:]
        for key in CRITERIA
    ]
    by_planner = [
        paired(records, condition_label(v, p), condition_label(v, q), stream, key)
        | {"arm": v, "name": p, "other": q}
        for stream in streams
        for v in variants
        for p, q in (against or {}).items()
        for key in CRITERIA
    ]
    return by_variant + by_planner


def what_it_shows(comps: Sequence[Mapping[str, Any]]) -> str:
    """The paired differences beyond chance (Bonferroni), and per variant and planner the
    episodes it wins and loses against the first variant, summed over streams."""
    level = ALPHA / max(len(comps), 1)
    sig = [c for c in comps if c["p"] < level]
    total: dict[tuple[str, str, str], list[Mapping[str, Any]]] = {}
    for c in comps:
        total.setdefault((c["name"], c["arm"], c["criterion"]), []).append(c)
    pooled = "; ".join(
        f"{name} against {cs[0]['other']} ({arm}), {CRITERIA[key]}: "
        f"{sum(c['only_piles'] for c in cs)} episodes won only by it, "
        f"{sum(c['only_against'] for c in cs)} lost only by it"
        for (name, arm, key), cs in total.items()
    )
    if not sig:
        return (
            f"No paired difference beyond chance (McNemar, Bonferroni level {level:.3g} over "
            f"{len(comps)}). Summed over streams: {pooled}."
        )
    cells = "; ".join(
        f"{c['name']} against {c['other']} {c['difference_points']:+.1f} points "
        f"{CRITERIA[c['criterion']]}, {c['arm']} on {c['stream']} (p = {c['p']:.2g})"
        for c in sig
    )
    return f"Beyond chance (McNemar, Bonferroni level {level:.3g}): {cells}. Summed: {pooled}."


TITLES = {
    "ch6_pull": "what the ch. 6 pull planners do after an abort, and what their maps mean",
    "ch6_pull_thresholds": "the thresholds of the ch. 6 pull-head CP planners",
    "ch6_pull_watch": "the ch. 6 pull-head CP planners watching their pull in depth",
    "ch6_no_plan": "what the ch. 6 pull planners do when their rule rejects every candidate",
    "ch6_no_plan_thresholds": "the thresholds of the ch. 6 pull-head CP planners that pull "
    "the least risk when their rule rejects every candidate",
    "ch6_idle_hold": "the ch. 6 bimanual pull planners holding a neighbour with the idle arm",
    "ch6_clear": "whose shares the ch. 6 pull planners' collapse score takes, and clearing "
    "around a rejected plan",
    "ch6_hold": "how the ch. 6 bimanual pull planners score and choose a held pull",
    "ch6_vs_pfd": "the ch. 6 pull-head CP planners against physics from depth",
    "ch6_box": "the ch. 6 box-head planners (per box, and learned plus physics) against "
    "physics from depth",
    "ch6_box_physics": "the ch. 6 learned-plus-physics planners (the box head fused per box "
    "with each pull simulated on the fitted boxes) against physics from depth",
    "ch6_box_hold": "how the ch. 6 learned-plus-physics bimanual planner scores a pull made "
    "holding a box (the held box left out, or the held pull simulated on the fitted boxes)",
    "ch6_fit_hypotheses": "how many scenes the ch. 6 learned-plus-physics planners fit to one "
    "observation (the fit alone, or with fits of the depth image with noise; each variant's "
    "fusion chosen again on the val scenes)",
    "ch6_box_contact": "the contact in the ch. 6 learned-plus-physics planners' support edges "
    "(the box head's, or learned from it and the fitted scenes' contacts; each variant's fusion "
    "chosen again on the val scenes)",
    "ch6_box_cp_max": "the collapse score over which the ch. 6 learned-plus-physics planners "
    "reject a pull or stop it (the support stage's outcome threshold, or lower)",
    "ch6_box_edge": "the support graph of the ch. 6 learned-plus-physics planners (the best F1 "
    "with the head's contact, or precision-first with the learned contact; each variant's "
    "fusion chosen again on the val scenes)",
    "ch6_release": "how the ch. 6 executor lets go of an aborted pull's box and of a held box "
    "(every planner and both search oracles under each variant)",
}


def seen_text(config: Mapping[str, Any]) -> str:
    """What the planners saw, when not the exact depth and the simulator's masks."""
    sensing = config.get("sensing", "ideal")
    perception = config.get("perception", "instance")
    if (sensing, perception) == ("ideal", "instance"):
        return ""
    masks = "masks from depth" if perception == "depth" else "the simulator's masks"
    return (
        f" The planners saw depth through the `{sensing}` sensor preset and {masks} (their "
        "box head and thresholds: those chosen for that sensor); the oracles read the world."
    )


def markdown(result: Mapping[str, Any]) -> str:
    c = result["config"]
    variants = "; ".join(
        f"`{name}`: " + (", ".join(f"{k} {v}" for k, v in over.items()) or "params' own")
        for name, over in c["variants"].items()
    )
    title = TITLES[result.get("section", "ch6_pull")]
    oracles = ", and both search oracles," if c.get("oracle", True) else ""
    lines = [
        f"# Dev recheck: {title} ({result['scale']} scale)",
        "",
        f"The planners {', '.join(c['planners'])} under each variant of `trials.ch6` "
        f"({variants}){oracles} on dev streams (own seeds, never a table's "
        f"scenes), {c['episodes']} episodes each; the params' own: "
        f"{result['current'] or 'none of them'}.{seen_text(c)}",
        "",
        "| stream | variant | planner | success | strict success | gave up "
        "| below its oracle: success / strict (points) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['stream']} | {r['variant']} | {r['planner']} | "
            f"{rate_text(r, 'success')} | {rate_text(r, 'strict_success')} | "
            f"{r['gave_up']} | {below_oracle_text(r)} |"
        )
    lines += [
        "",
        "## Paired, episode by episode",
        "",
        "| stream | planner (variant) | criterion | compared | won only by it "
        "| won only by the other | difference (points) | McNemar p |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for p in result["comparisons"]:
        lines.append(
            f"| {p['stream']} | {p['arm']} | {CRITERIA[p['criterion']]} | "
            f"{p['name']} vs {p['other']} | {paired_cells(p)}"
        )
    lines += [
        "",
        f"**What it shows.** {result['shows']}",
        "",
        "- success: collapse-free (the thesis' trial notion, criteria.py); strict: also "
        "no other box moved beyond trials.ch6.moved_threshold_m. The oracles search with the "
        "trials' own pull; a bimanual planner's oracle is oracle_hold.",
        f"- {result['n_episodes']} episodes in {result['seconds'] / 60:.1f} min.",
    ]
    return "\n".join(lines) + "\n"


def ch6_pull(
    params: Mapping[str, Any], out_dir: Path = OUT, section: str = "ch6_pull"
) -> dict[str, Any]:
    """Run the recheck of dev.<section>; writes out_dir/<section>.{json,md}."""
    from clutterbench.parallel import ParallelConfig
    from clutterbench.trials.ch6.episodes import run_ch6_episode
    from clutterbench.trials.core.harness import run_episodes

    started = time.perf_counter()
    base, dev, trials, cfg = open_recheck(params, section)
    jobs = trial_jobs(dev, params, section)
    parallel = load_section(ParallelConfig, "parallel", params)
    results = run_episodes("dev ch6 pull", run_ch6_episode, jobs, trials.workers, parallel)
    records = [r.record for r in results]
    comps = comparisons(records, list(cfg.variants), cfg.planners, cfg.streams, cfg.against)
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "section": section,
        "config": as_dict(cfg),
        "streams": {s: as_dict(dev.streams[s]) for s in cfg.streams},
        "current": current_variant(cfg.variants, trials.ch6),
        "rows": summary_rows(records),
        "comparisons": comps,
        "shows": what_it_shows(comps),
        "n_episodes": len(records),
    }
    return save(result, started, out_dir, section, markdown)


SECTIONS = tuple(TITLES)


def main() -> None:
    section = sys.argv[1] if len(sys.argv) > 1 else SECTIONS[0]
    if section not in SECTIONS or len(sys.argv) > 2:
        sys.exit(f"usage: python -m experiments.ch6_pull [{' | '.join(SECTIONS)}]")
    run_command(lambda params: ch6_pull(params, section=section), section)


if __name__ == "__main__":
    main()

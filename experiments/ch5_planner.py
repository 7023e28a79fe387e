"""Recheck on dev streams: how the ch. 5 planner carries a blocker, and whether it may push.

    python -m experiments.ch5_planner     # make dev-ch5-planner (~7 min at default scale)

Two choices of `trials.ch5` decide where a blocker B_s goes when it is carried aside:
- `blocker_goal`: thesis eq. (5.6) carries B_s by w'/2 + w_s/2 + g, which clears the candidate
  it fills when B_s stands centred on it; off the centre it carries it too far (a goal outside
  the shelf) or not far enough. "candidate" carries B_s until its near edge reaches the
  candidate's far edge; "eq_5_6" is eq. (5.6) as printed.
- `upright_footprint`: a leaning B_s (C^r / C^l) is set upright as it moves; true plans its goal
  and its way with the footprint it will have upright (planning.replenish.carried), false with
  the leaning box as seen.
Each variant of dev.ch5_planner.variants sets some of them. Beyond the thesis, the planner
`contact` (trials_ch5's contact_* rows) carries a movable blocker although boxes stand in its
way, where the thesis' planner has no plan (it gives up). This recheck runs each planner of
dev.ch5_planner.planners under each variant on the dev streams of dev.ch5_planner.streams (own
seeds, never a table's scenes), through the detector and through the generator's ground-truth
clusters, and the oracle (whose action set is built the same way) on the same scenes; all
meet the same scenes, so each variant is compared with the first, and under each variant each
planner with the first, episode by episode (McNemar's exact test).

Reads the pipeline's models/detector, models/<trials.ch5.model> and the threshold evaluate@
<model>_ch5 chose (dvc repro trials_ch5's upstream first). Writes experiments/reports/ch5_planner.
{json,md}; not a dvc stage.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from clutterbench.config import BaseConfig, as_dict, load_section
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
    from clutterbench.trials.ch5.episodes import Ch5Job


def condition_label(variant: str, planner: str, perception: str) -> str:
    return f"{variant}:{planner}:{perception}"


def trial_jobs(dev: DevConfig, params: Mapping[str, Any]) -> list[Ch5Job]:
    """Every (stream, variant, arm) episode's job, condition "<variant>:<planner>:
    <perception>/<stream>": each planner through each perception, the oracle through the
    ground-truth clusters (and the detector's actions, as in trials_ch5), each with trials.ch5
    as params set it but for the variant's overrides."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch5.episodes import ch5_jobs, check_models, collapse_threshold
    from clutterbench.trials.config import Ch5ConditionConfig, TrialsConfig

    base = load_section(BaseConfig, "base", params)
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    cfg = dev.ch5_planner
    arms = [(a, p) for a in cfg.planners for p in cfg.perceptions]
    arms += [("oracle", "clusters")] * cfg.oracle
    conds = {
        f"{condition_label(variant, planner, perception)}/{stream}": (
            variant,
            Ch5ConditionConfig(planner, stream, cfg.episodes, perception),
        )
        for stream in cfg.streams
        for variant in cfg.variants
        for planner, perception in arms
    }
    check_models({k: c for k, (_, c) in conds.items()}, trials.ch5)
    prob = collapse_threshold(trials.ch5)
    jobs = []
    for name, (variant, cond) in conds.items():
        jobs += ch5_jobs(
            name,
            cond,
            trials=trials,
            sim=sim,
            seed=base.seed,
            prob_threshold=prob,
            scene_type=cond.stream.removeprefix("dev_ch5_"),
            oracle_detector="detector" in cfg.perceptions,
            params=dataclasses.replace(trials.ch5, **cfg.variants[variant]),
            stream_cfg=dev.streams[cond.stream],
            record_images=False,
        )
    return jobs


def summary_rows(records: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per condition: success and strict success (Wilson 95%), how the episodes
    ended, and the points below the oracle of the same variant and stream."""
    from clutterbench.trials.core.stats import aggregate

    rows = []
    for r in aggregate(records).to_dict("records"):
        label, stream = r["condition"].split("/")
        variant, planner, perception = label.split(":")
        mine = [x for x in records if x["condition"] == r["condition"]]
        row = {"condition": r["condition"], "stream": stream, "variant": variant}
        row |= {"planner": planner, "perception": perception}
        for key in CRITERIA:
            row |= {f"{key}_{f}": plain(r[f"{key}_{f}"]) for f in ("k", "n", "rate", "lo", "hi")}
        row["gave_up"] = sum(x["end"] == "gave_up" for x in mine)
        rows.append(row)
    oracle = {(r["stream"], r["variant"]): r for r in rows if r["planner"] == "oracle"}
    for row in rows:
        top = oracle.get((row["stream"], row["variant"]))
        for key in CRITERIA:
            gap = 100 * (top[f"{key}_rate"] - row[f"{key}_rate"]) if top else None
            row[f"{key}_below_oracle_points"] = None if row["planner"] == "oracle" else gap
    return rows


def comparisons(
    records: Sequence[Mapping[str, Any]],
    variants: Sequence[str],
    streams: Sequence[str],
    planners: Sequence[str] = ("replenish",),
) -> list[dict[str, Any]]:
    """Each variant against the first of `variants`, per stream, arm and criterion; then under
    each variant, each planner against the first of `planners`, per perception; paired."""
    arms = dict.fromkeys(r["condition"].split("/")[0].split(":", 1)[1] for r in records)
    perceptions = dict.fromkeys(a.split(":")[1] for a in arms if not a.startswith("oracle:"))
    pairs = (
        [  # (label a, label b, arm, a's name, b's name)
            (f"{v}:{arm}", f"{variants[0]}:{arm}", arm, v, variants[0])
            for arm in arms
            for v in variants[1:]
        ]
        + [
            (f"{v}:{p}:{seen}", f"{v}:{planners[0]}:{seen}", seen, f"{v}:{p}", f"{v}:{planners[0]}")
            for v in variants
            for p in planners[1:]
            for seen in perceptions
        ]
    )
    return [
        paired(records, a, b, stream, key) | {"arm": arm, "name": name, "other": other}
        for stream in streams
        for a, b, arm, name, other in pairs
        for key in CRITERIA
    ]


def what_it_shows(comps: Sequence[Mapping[str, Any]]) -> str:
    """The paired differences beyond chance (Bonferroni), and per variant (or planner under a
    variant) the episodes it wins and loses against the first, summed over streams and arms."""
    level = ALPHA / max(len(comps), 1)
    sig = [c for c in comps if c["p"] < level]
    total = {}
    for c in comps:
        total.setdefault((c["name"], c["criterion"]), []).append(c)
    pooled = "; ".join(
        f"{name} against {cs[0]['other']}, {CRITERIA[key]}: "
        f"{sum(c['only_piles'] for c in cs)} episodes won only by it, "
        f"{sum(c['only_against'] for c in cs)} lost only by it"
        for (name, key), cs in total.items()
    )
    if not sig:
        return (
            f"No paired difference beyond chance (McNemar, Bonferroni level {level:.3g} over "
            f"{len(comps)}). Summed over streams and arms: {pooled}."
        )
    cells = "; ".join(
        f"{c['name']} {c['difference_points']:+.1f} points "
        f"{CRITERIA[c['criterion']]}, {c['arm']} on {c['stream']} (p = {c['p']:.2g})"
        for c in sig
    )
    return f"Beyond chance (McNemar, Bonferroni level {level:.3g}): {cells}. Summed: {pooled}."


def markdown(result: Mapping[str, Any]) -> str:
    c = result["config"]
    lines = [
        f"# Dev recheck: how the ch. 5 planner carries a blocker ({result['scale']} scale)",
        "",
        f"The planners {', '.join(c.get('planners', ['replenish']))} (trials_ch5's: "
        f"replenish with collapse prediction; contact also pushes what stands in a movable "
        f"blocker's way where it has no plan) under each variant of `trials.ch5` "
        f"({_variants(c['variants'])}), through the detector and the ground-truth clusters, "
        f"and the oracle under the same variant, on dev streams (own seeds, never a table's "
        f"scenes), {c['episodes']} episodes each; the params' own: "
        f"{result['current'] or 'none of them'}.",
        "",
        "| stream | variant | planner | perception | success | strict success | gave up "
        "| below its oracle: success / strict (points) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        gap = below_oracle_text(r)
        lines.append(
            f"| {r['stream']} | {r['variant']} | {r['planner']} | {r['perception']} | "
            f"{rate_text(r, 'success')} | {rate_text(r, 'strict_success')} | "
            f"{r['gave_up']} | {gap} |"
        )
    lines += [
        "",
        "## Paired, episode by episode",
        "",
        "| stream | arm | criterion | compared | won only by it | won only by the other "
        "| difference (points) | McNemar p |",
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
        "no other box moved beyond trials.ch5.moved_threshold_m. Each variant's oracle "
        "simulates the action set built the same way.",
        f"- {result['n_trials']} trials in {result['seconds'] / 60:.1f} min.",
    ]
    return "\n".join(lines) + "\n"


def _variants(variants: Mapping[str, Mapping[str, Any]]) -> str:
    return "; ".join(
        f"`{name}`: " + ", ".join(f"{k} {v}" for k, v in over.items())
        for name, over in variants.items()
    )


def ch5_planner(params: Mapping[str, Any], out_dir: Path = OUT) -> dict[str, Any]:
    """Run the recheck of dev.ch5_planner; writes out_dir/ch5_planner.{json,md}."""
    from clutterbench.trials.ch5.episodes import run_ch5_episode
    from clutterbench.trials.core.harness import run_episodes

    started = time.perf_counter()
    base, dev, trials, cfg = open_recheck(params, "ch5_planner")
    jobs = trial_jobs(dev, params)
    results = run_episodes("dev ch5 planner", run_ch5_episode, jobs, trials.workers)
    records = [r.record for r in results]
    comps = comparisons(records, list(cfg.variants), cfg.streams, cfg.planners)
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "config": as_dict(cfg),
        "streams": {s: as_dict(dev.streams[s]) for s in cfg.streams},
        "current": current_variant(cfg.variants, trials.ch5),
        "rows": summary_rows(records),
        "comparisons": comps,
        "shows": what_it_shows(comps),
        "n_trials": len(records),
    }
    return save(result, started, out_dir, "ch5_planner", markdown)


def main() -> None:
    run_command(ch5_planner, "ch5_planner")


if __name__ == "__main__":
    main()

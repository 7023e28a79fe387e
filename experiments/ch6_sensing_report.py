"""The report of the ch. 6 sensed-training recheck (experiments/ch6_sensing.py): its markdown
and the parts in words."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from experiments.ch4_sensing import LABEL
from experiments.stats import CRITERIA, below_oracle_text, rate_text


def parts_text(parts: Sequence[Mapping[str, Any]]) -> str:
    """The parts in words: per planner, the collapse-free points each of sensor and masks from
    depth takes from its exact-depth, simulator-mask rate, alone and together."""
    out = []
    for (row, planner), cs in _grouped(parts).items():
        cells = ", ".join(
            f"{c['difference_points']:+.1f} with {_seen(c)} (p = {c['p']:.2g})" for c in cs
        )
        out.append(f"{planner} ({row}): {cells}")
    return "Against exact depth with the simulator's masks, collapse-free: " + "; ".join(out) + "."


def _grouped(parts: Sequence[Mapping[str, Any]]) -> dict[tuple[str, str], list[Mapping]]:
    out: dict[tuple[str, str], list[Mapping]] = {}
    for c in parts:
        out.setdefault((c["row"], c["planner"]), []).append(c)
    return out


def _seen(c: Mapping[str, Any]) -> str:
    depth = "exact depth" if c["sensing"] == "ideal" else f"{c['sensing']} depth"
    return f"{depth} and {'masks from depth' if c['masks'] == 'depth' else 'simulator masks'}"


def paired_tables(result: Mapping[str, Any]) -> list[str]:
    """The report's two paired tables: each training against the params' own, and each
    network's planner against its baseline."""
    lines: list[str] = []
    lines += [
        "",
        f"## Paired, episode by episode: each training against {result['current']}",
        "",
        "| stream | planner | criterion | training | won only by it | won only by "
        f"{result['current']} | difference (points) | McNemar p |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for p in result["by_training"]:
        lines.append(
            f"| {p['stream']} | {p['planner']} | {CRITERIA[p['criterion']]} | {p[LABEL]} | "
            f"{p[f'only_{LABEL}']} | {p['only_against']} | {p['difference_points']:+.1f} | "
            f"{p['p']:.2g} |"
        )
    lines += [
        "",
        "## Paired, episode by episode: each network's planner against its baseline",
        "",
        "| stream | planner (training) | criterion | baseline | won only by the planner | "
        "won only by the baseline | difference (points) | McNemar p |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for p in result["by_baseline"]:
        lines.append(
            f"| {p['stream']} | {p['planner']} ({p[LABEL]}) | {CRITERIA[p['criterion']]} | "
            f"{p['baseline']} | {p['only_piles']} | {p['only_against']} | "
            f"{p['difference_points']:+.1f} | {p['p']:.2g} |"
        )
    return lines


def parts_table(result: Mapping[str, Any]) -> list[str]:
    """The report's table of where the points go (none without parts)."""
    parts = result.get("by_part") or []
    if not parts:
        return []
    rate = {r["condition"]: r for r in result["rows"]}
    first = parts[0]
    lines = [
        "",
        "## Where the points go: sensor and masks, apart and together (collapse-free)",
        "",
        f"The params' network ({result['current']}) and the baselines; each cell against exact "
        f"depth with the simulator's masks, episode by episode: points (won only by it / "
        f"only by the first), McNemar p.",
        "",
        "| stream | planner (network) | exact depth, simulator masks | "
        + " | ".join(
            _seen(c) for c in parts[: len(_grouped(parts)[first["row"], first["planner"]])]
        )
        + " |",
        "|---|---|---|" + "---|" * len(_grouped(parts)[first["row"], first["planner"]]),
    ]
    for (row, planner), cs in _grouped(parts).items():
        ref = rate[f"{cs[0]['against']}/{cs[0]['stream']}"]
        cells = " | ".join(
            f"{rate_text(rate[c['piles'] + '/' + c['stream']], 'success')}: "
            f"{c['difference_points']:+.1f} ({c['only_piles']} / {c['only_against']}), "
            f"p = {c['p']:.2g}"
            for c in cs
        )
        lines.append(
            f"| {cs[0]['stream']} | {planner} ({row}) | {rate_text(ref, 'success')} | {cells} |"
        )
    return lines


def scores_table(result: Mapping[str, Any]) -> list[str]:
    """The report's table of how the CP's collapse score read each CP row's pulls."""

    def mean(v: float | None) -> str:
        return "-" if v is None else f"{v:.2f}"

    lines = [
        "",
        "## The CP's collapse score of each pull (its highest during the pull, max_cp)",
        "",
        "| stream | training | planner | pulls kept collapse-free: n, mean score | pulls that "
        "collapsed: n, mean score | pulls aborted |",
        "|---|---|---|---|---|---|",
    ]
    for r in (r for r in result["rows"] if "pulls_safe" in r):
        lines.append(
            f"| {r['stream']} | {r[LABEL]} | {r['planner']} | {r['pulls_safe']}, "
            f"{mean(r['score_safe'])} | {r['pulls_collapsed']}, {mean(r['score_collapsed'])} | "
            f"{r['aborted']} |"
        )
    return lines


def markdown(result: Mapping[str, Any]) -> str:
    from clutterbench.platform_info import instruction_set

    c, cpu = result["config"], result["cpu"]
    first = result["candidates"][0]
    lines = [
        f"# Dev recheck: the ch. 6 collapse predictor trained on the sensor's images "
        f"({result['scale']} scale)",
        "",
        f"`{first['model']}` (every head) retrained on its dataset `{first['dataset']}` with "
        f"each training sensor (train.sensing.preset; ideal: the parametric noise of "
        f"train.noise), its support thresholds chosen on the val scenes as the support stage "
        f"chooses them, then the planners {', '.join(c['planners'])} with each network on dev "
        f"streams (own seeds, never a table's scenes) under the {c['sensing']} sensor with "
        f"masks from depth, as Table 6.3's sensed rows, beside their baselines under the same "
        f"sensing and both search oracles, {c['episodes']} episodes each; the params' preset "
        f"is {result['current']}.",
        "",
        "## Networks",
        "",
        "| training | data | network | best epoch / run | val loss | val IoU | pull-head "
        "thresholds (prob / score) | train s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for cand in result["candidates"]:
        s, best = cand["summary"], cand["summary"]["best"]
        data = "the pipeline's" if cand["data_reused"] else "data/dev"
        net = "an earlier run's" if cand["network_reused"] else "trained by this run"
        pull = cand["chosen"].get(result["pull_method"], {})
        lines.append(
            f"| {cand[LABEL]} | {data} | {net} | {best['epoch']} / {s['epochs_run']} | "
            f"{best['val_loss']:.4f} | {best['val_iou']:.3f} | "
            f"{pull.get('prob_threshold', '-')} / {pull.get('score_threshold', '-')} | "
            f"{cand['seconds']:.0f} |"
        )
    lines += [
        "",
        f"## Trials under {c['sensing']}, masks from depth (Wilson 95%)",
        "",
        "| stream | training | planner | success | strict success | below its oracle: "
        "success / strict (points) | gave up | grasped no box |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['stream']} | {r[LABEL]} | {r['planner']} | {rate_text(r, 'success')} | "
            f"{rate_text(r, 'strict_success')} | {below_oracle_text(r)} | {r['gave_up']} | "
            f"{r['missed_grasp']} |"
        )
    lines += scores_table(result)
    lines += paired_tables(result)
    lines += parts_table(result)
    lines += [
        "",
        f"**What it shows.** {result['shows']}",
        "",
        "- success: collapse-free (the thesis' trial notion, criteria.py); strict: also no "
        "other box moved beyond trials.ch6.moved_threshold_m; judged from physics as in Table "
        "6.3. The search oracles read the world, not the sensor; a holding planner's is "
        "oracle_hold.",
        "- The networks share the data, the split and the training seed; each picked its "
        "epoch and its support thresholds on the exact-depth val scenes, as the stages do. "
        "The baselines read the support stage's thresholds, as in the trials stage.",
        f"- Networks in {result['network_precision']} on {cpu['cpu_model']} "
        f"({instruction_set(cpu)}), {cpu['torch_threads']} torch threads; this run took "
        f"{result['seconds'] / 60:.1f} min, its {result['n_episodes']} episodes "
        f"{result['trials_seconds'] / 60:.1f}.",
    ]
    return "\n".join(lines) + "\n"

"""Recheck on dev streams: should the ch. 4 network train on the sensor's images?

    python -m experiments.ch4_sensing      # make dev-ch4-sensing (~35 min at default scale)

Table 4.1's sensed rows (trials.ch4_sensed) run the ch. 4 risk planner on a depth sensor's
pictures with masks by region growing, while the networks train on exact depth with the
parametric noise of train.noise (train.sensing: ideal). For each preset of
dev.ch4_sensing.training, train.models.<model> is trained on its dataset as stages split@ and
train@ do (same seed, epochs, precision), its training depth through that preset's sensor model
(train.sensing.preset; spread as params'), then the risk planner (stage trials_ch4's episode)
runs with each network on every stream of dev.ch4_sensing.streams under dev.ch4_sensing.sensing
with masks from depth, beside the oracle on the same scenes. The networks meet the same scenes,
so they are compared episode by episode (McNemar's exact test) against the params' own
train.sensing.preset.

The pipeline's data/generate/<dataset> is used where its shards were made with the same params;
anything else is made under data/dev/ch4_sensing/ and reused by a rerun whose params match.
Writes experiments/reports/ch4_sensing.{json,md}; not a dvc stage.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from clutterbench.config import BaseConfig, as_dict, load_section
from experiments.ch4_piles import candidate_data, candidate_network, ch4_dataset, summary_rows
from experiments.command import OUT, open_recheck, run_command, save
from experiments.config import Ch4SensingConfig, DevConfig
from experiments.stats import ALPHA, CRITERIA, below_oracle_text, paired, rate_text

SCRATCH = Path("data/dev/ch4_sensing")
LABEL = "training"
"""The key of a candidate (its train.sensing preset) in the report's rows."""


def with_training_sensing(params: Mapping[str, Any], preset: str) -> dict[str, Any]:
    """`params` with train.sensing.preset set to `preset` (its spread kept)."""
    out = copy.deepcopy(dict(params))
    sensing = dict(out["train"].get("sensing") or {})
    out["train"] = {**out["train"], "sensing": {**sensing, "preset": preset}}
    return out


def candidate_networks(
    cfg: Ch4SensingConfig, dataset: str, params: Mapping[str, Any], data_dir: Path, scratch: Path
) -> list[dict[str, Any]]:
    """One network per training preset, all on the params' dataset -> the report's facts."""
    from clutterbench.data.config import GenerateConfig

    piles = load_section(GenerateConfig, "generate", params).datasets[dataset].n_objects
    gen_dir, digest, data_reused = candidate_data(dataset, piles, params, data_dir, scratch)
    candidates = []
    for preset in cfg.training:
        net = candidate_network(
            cfg.model, with_training_sensing(params, preset), gen_dir, digest, scratch / preset
        )
        candidates.append({LABEL: preset, "data": str(gen_dir / dataset)} | net)
        candidates[-1]["data_reused"] = data_reused
        print(f"training {preset}: best epoch {net['summary']['best']['epoch']}", flush=True)
    return candidates


def trial_jobs(
    candidates: Sequence[Mapping[str, Any]], dev: DevConfig, params: Mapping[str, Any]
) -> list[Any]:
    """Stage trials_ch4's jobs: the risk planner with each candidate's network under the
    recheck's sensor and masks from depth, and the oracle, on every dev stream (conditions
    '<training>/<stream>')."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch4.episodes import ch4_jobs
    from clutterbench.trials.config import Ch4ConditionConfig, TrialsConfig

    cfg: Ch4SensingConfig = dev.ch4_sensing
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    seed = load_section(BaseConfig, "base", params).seed
    sensed = {"perception": "depth", "sensing": cfg.sensing}
    runs = [(c[LABEL], "risk", cfg.model, Path(c["checkpoint"]), sensed) for c in candidates]
    if cfg.oracle:
        runs.append(("oracle", "oracle", None, None, {}))
    jobs = []
    for stream in cfg.streams:
        for label, planner, model, checkpoint, seen in runs:
            cond = Ch4ConditionConfig(planner, stream, episodes=cfg.episodes, model=model, **seen)
            for job in ch4_jobs(
                f"{label}/{stream}",
                cond,
                trials=trials,
                sim=sim,
                seed=seed,
                stream_cfg=dev.streams[stream],
                record_images=False,
            ):
                jobs.append(dataclasses.replace(job, model_path=checkpoint))
    return jobs


def comparisons_of(
    records: Sequence[Mapping[str, Any]], cfg: Ch4SensingConfig, against: str
) -> list[dict[str, Any]]:
    """Each other candidate against `against`, per stream and criterion, episode by episode
    (the candidate under LABEL, its wins under only_<LABEL>)."""
    out = []
    for stream in cfg.streams:
        for preset in cfg.training:
            if preset == against:
                continue
            for key in CRITERIA:
                p = paired(records, preset, against, stream, key)
                p[LABEL], p[f"only_{LABEL}"] = p.pop("piles"), p.pop("only_piles")
                out.append(p)
    return out


def run_and_pair(
    title: str,
    episode: Any,
    jobs: Sequence[Any],
    cfg: Any,
    params: Mapping[str, Any],
    scratch: Path,
) -> tuple[list[dict[str, Any]], float, str, list[dict[str, Any]]]:
    """A sensed-training recheck's episodes, run as the trials stages run them (records also in
    scratch/records.jsonl), and each candidate paired against the params' own training preset
    (the first of cfg.training where the params' is none of them) -> (records, trials seconds,
    that preset, the comparisons)."""
    from clutterbench.collapse.config import TrainConfig
    from clutterbench.trials.config import TrialsConfig
    from clutterbench.trials.core.harness import run_episodes
    from clutterbench.trials.core.records import write_records

    t0 = time.perf_counter()
    workers = load_section(TrialsConfig, "trials", params).workers
    records = [r.record for r in run_episodes(title, episode, list(jobs), workers)]
    trials_s = time.perf_counter() - t0
    write_records(scratch / "records.jsonl", records)
    current = load_section(TrainConfig, "train", params).sensing.preset
    against = current if current in cfg.training else cfg.training[0]
    return records, trials_s, against, comparisons_of(records, cfg, against)


def what_it_shows(
    comparisons: Sequence[Mapping[str, Any]], rows: Sequence[Mapping[str, Any]], current: str
) -> str:
    """The finding in words, from the numbers: per other preset, the paired differences beyond
    chance (Bonferroni) and which way they go; then each network's points below the oracle."""
    level = ALPHA / max(len(comparisons), 1)
    out = []
    for alt in dict.fromkeys(c[LABEL] for c in comparisons):
        mine = [c for c in comparisons if c[LABEL] == alt]
        sig = [c for c in mine if c["p"] < level]
        n = len({c["stream"] for c in mine})
        mean = ", ".join(
            f"{sum(c['difference_points'] for c in mine if c['criterion'] == k) / n:+.1f} "
            f"{CRITERIA[k]}"
            for k in CRITERIA
        )
        if not sig:
            out.append(
                f"Training on {alt} instead of {current} changes no dev-stream rate beyond "
                f"chance (paired McNemar p >= {level:.3g} on every stream and criterion, "
                f"Bonferroni over {len(comparisons)}; mean difference over the streams, points: "
                f"{mean})."
            )
            continue
        cells = "; ".join(
            f"{c['difference_points']:+.1f} points {CRITERIA[c['criterion']]} on {c['stream']} "
            f"(p = {c['p']:.2g})"
            for c in sig
        )
        if all(c["difference_points"] > 0 for c in sig):
            verdict = f"the dev streams favour training on {alt}"
        elif all(c["difference_points"] < 0 for c in sig):
            verdict = f"the dev streams favour training on {current}"
        else:
            verdict = "the dev streams are split"
        out.append(
            f"Training on {alt} against {current} (paired McNemar, Bonferroni level "
            f"{level:.3g}): {cells}; {verdict} (mean over the streams, points: {mean})."
        )
    for stream in dict.fromkeys(r["stream"] for r in rows):
        gaps = ", ".join(
            f"{r[LABEL]} {below_oracle_text(r)}"
            for r in rows
            if r["stream"] == stream and r["success_below_oracle_points"] is not None
        )
        out.append(f"Below the oracle on {stream} (success / strict, points): {gaps}.")
    return " ".join(out)


def markdown(result: Mapping[str, Any]) -> str:
    from clutterbench.platform_info import instruction_set

    c, cpu = result["config"], result["cpu"]
    lines = [
        f"# Dev recheck: the ch. 4 network trained on the sensor's images ({result['scale']} "
        "scale)",
        "",
        f"`{c['model']}` retrained on its dataset `{result['dataset']}` ({result['n_scenes']} "
        f"scenes) with each training sensor (train.sensing.preset; ideal: the parametric noise "
        f"of train.noise), then the ch. 4 risk planner (stage trials_ch4's episode) with each "
        f"network on dev streams (own seeds, never a table's scenes) under the {c['sensing']} "
        f"sensor with masks by region growing, as Table 4.1's sensed rows, {c['episodes']} "
        f"episodes each; the params' preset is {result['current']}.",
        "",
        "## Networks",
        "",
        "| training | data | network | train scenes | train pairs | best epoch / run | val loss "
        "| val IoU (C) | train s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for cand in result["candidates"]:
        s, best = cand["summary"], cand["summary"]["best"]
        data = "the pipeline's" if cand["data_reused"] else "data/dev"
        net = "an earlier run's" if cand["network_reused"] else "trained by this run"
        lines.append(
            f"| {cand[LABEL]} | {data} | {net} | {cand['train_scenes']} | {s['train_pairs']} | "
            f"{best['epoch']} / {s['epochs_run']} | {best['val_loss']:.4f} | "
            f"{best['val_iou']:.3f} | {cand['seconds']:.0f} |"
        )
    lines += [
        "",
        f"## Trials under {c['sensing']} (Wilson 95%)",
        "",
        "| stream | boxes | catalogue | training | success | strict success "
        "| below oracle: success / strict (points) | mean disturbed boxes |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lo, hi = r["n_objects"]
        lines.append(
            f"| {r['stream']} | {lo if lo == hi else f'{lo}-{hi}'} | {r['catalogue']} | "
            f"{r[LABEL]} | {rate_text(r, 'success')} | {rate_text(r, 'strict_success')} | "
            f"{below_oracle_text(r)} | {r['mean_n_disturbed']:.2f} |"
        )
    lines += [
        "",
        f"## Paired, episode by episode (against {result['current']})",
        "",
        "| stream | criterion | training | won only by it | won only by "
        f"{result['current']} | difference (points) | McNemar p |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in result["comparisons"]:
        lines.append(
            f"| {p['stream']} | {CRITERIA[p['criterion']]} | {p[LABEL]} | {p[f'only_{LABEL}']} "
            f"| {p['only_against']} | {p['difference_points']:+.1f} | {p['p']:.2g} |"
        )
    lines += [
        "",
        f"**What it shows.** {result['shows']}",
        "",
        "- success: collapse-free (the thesis' trial notion, criteria.py); strict: also no "
        "other box moved more than trials.ch4.moved_threshold_m. Both judged after the "
        "support's release, as in Table 4.1. The oracle reads the world, not the sensor.",
        "- The networks share the data, the split and the training seed; each picked its "
        "epoch on the exact-depth val images, as stage train@ does.",
        f"- Networks in {result['network_precision']} on {cpu['cpu_model']} "
        f"({instruction_set(cpu)}), {cpu['torch_threads']} torch threads; this run took "
        f"{result['seconds'] / 60:.1f} min, its trials {result['trials_seconds'] / 60:.1f}.",
    ]
    return "\n".join(lines) + "\n"


def ch4_sensing(
    params: Mapping[str, Any],
    data_dir: Path = Path("data"),
    scratch: Path = SCRATCH,
    out_dir: Path = OUT,
) -> dict[str, Any]:
    """Run the recheck of dev.ch4_sensing; writes out_dir/ch4_sensing.{json,md}."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.platform_info import cpu_description
    from clutterbench.precision import inference_from_params
    from clutterbench.trials.ch4.episodes import run_ch4_episode

    started = time.perf_counter()
    base, dev, _, cfg = open_recheck(params, "ch4_sensing")
    dataset, _ = ch4_dataset(cfg, params, "ch4_sensing")
    candidates = candidate_networks(cfg, dataset, params, data_dir, scratch)
    jobs = trial_jobs(candidates, dev, params)
    records, trials_s, against, comparisons = run_and_pair(
        "dev ch4 sensing", run_ch4_episode, jobs, cfg, params, scratch
    )
    rows = summary_rows(records, dev, LABEL)
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "config": as_dict(cfg),
        "streams": {s: as_dict(dev.streams[s]) for s in cfg.streams},
        "dataset": dataset,
        "n_scenes": load_section(GenerateConfig, "generate", params).datasets[dataset].n_scenes,
        "current": against,
        "candidates": candidates,
        "rows": rows,
        "comparisons": comparisons,
        "network_precision": inference_from_params(params),
        "trials_seconds": trials_s,
        "cpu": cpu_description(),
    }
    result["shows"] = what_it_shows(comparisons, rows, against)
    return save(result, started, out_dir, "ch4_sensing", markdown)


def main() -> None:
    run_command(ch4_sensing, "ch4_sensing")


if __name__ == "__main__":
    main()

"""Recheck on dev streams: should the ch. 5 collapse map network train on the sensor's images?

    python -m experiments.ch5_sensing      # make dev-ch5-sensing

Table 5.2's sensed rows (trials.ch5_sensed) run the replenishment planner on a depth sensor's
pictures, its clusters from the detector trained on that sensor's images (stage
detector_sensed), while the collapse map network (trials.ch5.model) trains on exact depth with
the parametric noise of train.noise (train.sensing: ideal). For each preset of
dev.ch5_sensing.training, that network is trained on its dataset as stages split@ and train@ do
(same seed, epochs, precision), its training depth through that preset's sensor model
(train.sensing.preset; spread as params'); its collapse threshold is chosen on the val split as
evaluate@<model>_ch5 chooses it (trials.ch5.prob_threshold null). Then the planner (stage
trials_ch5's episode) runs with each network on every stream of dev.ch5_sensing.streams under
dev.ch5_sensing.sensing, beside the oracle on the same scenes. The networks meet the same
scenes, so they are compared episode by episode (McNemar's exact test) against the params' own
train.sensing.preset.

Reads models/detector_<sensing>/best.pt (dvc repro detector_sensed first). The pipeline's
data/generate/<dataset> is used where it was made with the same params; anything else is made
under data/dev/ch5_sensing/ and reused by a rerun whose params match.
Writes experiments/reports/ch5_sensing.{json,md}; not a dvc stage.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from experiments.ch4_piles import candidate_network
from experiments.ch4_sensing import LABEL, run_and_pair, what_it_shows, with_training_sensing
from experiments.command import OUT, open_recheck, run_command, save
from experiments.config import Ch5SensingConfig, DevConfig
from experiments.detector_sensing import dataset_dir
from experiments.stats import CRITERIA, below_oracle_text, plain, rate_text

NAME = "ch5_sensing"
SCRATCH = Path("data/dev/ch5_sensing")
PLANNER = "replenish"
"""The ch. 5 planner that reads the collapse map network (the thesis' method)."""


def candidate_networks(
    cfg: Ch5SensingConfig, params: Mapping[str, Any], data_dir: Path, scratch: Path
) -> list[dict[str, Any]]:
    """One network per training preset, all on the params' dataset, each with the threshold
    chosen on its val split -> the report's facts."""
    from clutterbench.collapse.config import EvaluateConfig, TrainConfig
    from clutterbench.collapse.evaluate import SplitRef, val_chosen_threshold
    from clutterbench.criteria import label_thresholds
    from clutterbench.data.config import GenerateConfig
    from clutterbench.trials.config import TrialsConfig

    model = load_section(TrialsConfig, "trials", params).ch5.model
    dataset = load_section(TrainConfig, "train", params).models[model].dataset
    gen = load_section(GenerateConfig, "generate", params)
    threshold_m = gen.datasets[dataset].moved_threshold_m
    evaluate = load_section(EvaluateConfig, "evaluate", params)
    run = f"{model}_ch5"  # the evaluate run whose val threshold trials_ch5 reads
    evaluate = evaluate.for_run(run) if run in evaluate.runs else evaluate
    gen_dir, digest, data_reused = dataset_dir(dataset, params, data_dir, scratch)
    candidates = []
    for preset in cfg.training:
        where = scratch / preset
        trained = with_training_sensing(params, preset)
        net = candidate_network(model, trained, gen_dir, digest, where)
        val = SplitRef(dataset, where / "split" / f"{dataset}.json", "val", threshold_m)
        val = dataclasses.replace(val, collapse_free=label_thresholds(params))
        chosen = val_chosen_threshold(Path(net["checkpoint"]), gen_dir, val, evaluate)
        candidates.append(
            {LABEL: preset, "model": model, "dataset": dataset, "data_reused": data_reused}
            | net
            | {"prob_threshold": chosen["threshold"], "val_iou_at_threshold": chosen["iou"]}
        )
        print(
            f"training {preset}: best epoch {net['summary']['best']['epoch']}, "
            f"threshold {chosen['threshold']:.2f} (val IoU {chosen['iou']:.3f})",
            flush=True,
        )
    return candidates


def trial_jobs(
    candidates: Sequence[Mapping[str, Any]], dev: DevConfig, params: Mapping[str, Any]
) -> list[Any]:
    """Stage trials_ch5's jobs: the planner with each candidate's network and threshold under
    the recheck's sensor, its clusters from that sensor's detector, and the oracle on the
    generator's clusters, on every dev stream (conditions '<training>/<stream>')."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch5.episodes import ch5_jobs, detector_path
    from clutterbench.trials.config import Ch5ConditionConfig, TrialsConfig

    cfg: Ch5SensingConfig = dev.ch5_sensing
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    seed = load_section(BaseConfig, "base", params).seed
    runs = [
        (c[LABEL], PLANNER, "detector", cfg.sensing, Path(c["checkpoint"]), c["prob_threshold"])
        for c in candidates
    ]
    if cfg.oracle:
        first = candidates[0]
        runs.append(
            ("oracle", "oracle", "clusters", "ideal", Path(first["checkpoint"]), 0.5),
        )
    jobs = []
    for stream in cfg.streams:
        for label, planner, perception, sensing, checkpoint, prob in runs:
            cond = Ch5ConditionConfig(planner, stream, cfg.episodes, perception, sensing)
            if perception == "detector" and not detector_path(cond).exists():
                raise ClutterbenchError(
                    f"{detector_path(cond)} missing; run dvc repro detector_sensed (the "
                    f"detector trained on {sensing}'s images)"
                )
            for job in ch5_jobs(
                f"{label}/{stream}",
                cond,
                trials=trials,
                sim=sim,
                seed=seed,
                prob_threshold=prob,
                scene_type=stream.removeprefix("dev_ch5_"),
                stream_cfg=dev.streams[stream],
                record_images=False,
            ):
                jobs.append(dataclasses.replace(job, model_path=checkpoint))
    return jobs


def detector_facts(sensing: str) -> dict[str, Any]:
    """The detector the sensed planner read: its path and the sha256 of its checkpoint."""
    import hashlib

    from clutterbench.trials.ch5.episodes import detector_path
    from clutterbench.trials.config import Ch5ConditionConfig

    path = detector_path(Ch5ConditionConfig(PLANNER, "unused", sensing=sensing))
    return {"path": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}


def summary_rows(records: Sequence[Mapping[str, Any]], dev: DevConfig) -> list[dict[str, Any]]:
    """One row per condition ('<training>/<stream>'): success and strict success (Wilson 95%),
    the episodes that gave up, and the points below the oracle on the same stream."""
    from clutterbench.trials.core.stats import aggregate

    rows = []
    for r in aggregate(records).to_dict("records"):
        label, stream = r["condition"].split("/")
        s = dev.streams[stream]
        row = {"condition": r["condition"], LABEL: label, "stream": stream}
        row |= {"n_objects": list(s.n_objects), "catalogue": s.catalogue}
        for key in CRITERIA:
            row |= {f"{key}_{f}": plain(r[f"{key}_{f}"]) for f in ("k", "n", "rate", "lo", "hi")}
        row["gave_up"] = sum(
            x["end"] == "gave_up" for x in records if x["condition"] == r["condition"]
        )
        rows.append(row)
    oracle = {r["stream"]: r for r in rows if r[LABEL] == "oracle"}
    for row in rows:
        top = oracle.get(row["stream"])
        for key in CRITERIA:
            gap = 100 * (top[f"{key}_rate"] - row[f"{key}_rate"]) if top else None
            row[f"{key}_below_oracle_points"] = None if row[LABEL] == "oracle" else gap
    return rows


def markdown(result: Mapping[str, Any]) -> str:
    from clutterbench.platform_info import instruction_set

    c, cpu = result["config"], result["cpu"]
    first = result["candidates"][0]
    lines = [
        f"# Dev recheck: the ch. 5 collapse map network trained on the sensor's images "
        f"({result['scale']} scale)",
        "",
        f"`{first['model']}` retrained on its dataset `{first['dataset']}` with each training "
        f"sensor (train.sensing.preset; ideal: the parametric noise of train.noise), its "
        f"collapse threshold chosen on the val split as evaluate@ chooses it, then the "
        f"replenishment planner (stage trials_ch5's episode) with each network on dev streams "
        f"(own seeds, never a table's scenes) under the {c['sensing']} sensor, its clusters "
        f"from the detector trained on that sensor's images, as Table 5.2's sensed rows, "
        f"{c['episodes']} episodes each; the params' preset is {result['current']}.",
        "",
        "## Networks",
        "",
        "| training | data | network | best epoch / run | val loss | val IoU | threshold (val "
        "IoU at it) | train s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for cand in result["candidates"]:
        s, best = cand["summary"], cand["summary"]["best"]
        data = "the pipeline's" if cand["data_reused"] else "data/dev"
        net = "an earlier run's" if cand["network_reused"] else "trained by this run"
        lines.append(
            f"| {cand[LABEL]} | {data} | {net} | {best['epoch']} / {s['epochs_run']} | "
            f"{best['val_loss']:.4f} | {best['val_iou']:.3f} | {cand['prob_threshold']:.2f} "
            f"({cand['val_iou_at_threshold']:.3f}) | {cand['seconds']:.0f} |"
        )
    lines += [
        "",
        f"## Trials under {c['sensing']} (Wilson 95%)",
        "",
        "| stream | boxes | training | success | strict success "
        "| below oracle: success / strict (points) | gave up |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lo, hi = r["n_objects"]
        lines.append(
            f"| {r['stream']} | {lo if lo == hi else f'{lo}-{hi}'} | {r[LABEL]} | "
            f"{rate_text(r, 'success')} | {rate_text(r, 'strict_success')} | "
            f"{below_oracle_text(r)} | {r['gave_up']} |"
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
        "other box moved beyond the label threshold; judged from physics as in Table 5.2. The "
        "oracle reads the world, not the sensor.",
        "- The networks share the data, the split and the training seed; each picked its "
        "epoch and its threshold on the exact-depth val images, as the stages do.",
        f"- The detector: `{result['detector']['path']}` (sha256 "
        f"{result['detector']['sha256'][:12]}).",
        f"- Networks in {result['network_precision']} on {cpu['cpu_model']} "
        f"({instruction_set(cpu)}), {cpu['torch_threads']} torch threads; this run took "
        f"{result['seconds'] / 60:.1f} min, its trials {result['trials_seconds'] / 60:.1f}.",
    ]
    return "\n".join(lines) + "\n"


def ch5_sensing(
    params: Mapping[str, Any],
    data_dir: Path = Path("data"),
    scratch: Path = SCRATCH,
    out_dir: Path = OUT,
) -> dict[str, Any]:
    """Run the recheck of dev.ch5_sensing; writes out_dir/ch5_sensing.{json,md}."""
    from clutterbench.platform_info import cpu_description
    from clutterbench.precision import inference_from_params
    from clutterbench.trials.ch5.episodes import run_ch5_episode

    started = time.perf_counter()
    base, dev, _, cfg = open_recheck(params, "ch5_sensing")
    candidates = candidate_networks(cfg, params, data_dir, scratch)
    jobs = trial_jobs(candidates, dev, params)
    records, trials_s, against, comparisons = run_and_pair(
        "dev ch5 sensing", run_ch5_episode, jobs, cfg, params, scratch
    )
    rows = summary_rows(records, dev)
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "config": as_dict(cfg),
        "streams": {s: as_dict(dev.streams[s]) for s in cfg.streams},
        "current": against,
        "candidates": candidates,
        "rows": rows,
        "comparisons": comparisons,
        "detector": detector_facts(cfg.sensing),
        "network_precision": inference_from_params(params),
        "trials_seconds": trials_s,
        "cpu": cpu_description(),
    }
    result["shows"] = what_it_shows(comparisons, rows, against)
    return save(result, started, out_dir, NAME, markdown)


if __name__ == "__main__":
    run_command(ch5_sensing, NAME)

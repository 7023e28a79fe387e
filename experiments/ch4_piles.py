"""Recheck on dev streams: the piles the ch. 4 networks are trained on.

    python -m experiments.ch4_piles       # make dev-ch4-piles (~30 min at default scale)

The ch. 4 networks are trained on piles of 5-10 boxes (generate.datasets.ch4_*.n_objects),
the thesis' on piles of 6; the range was chosen after seeing Table 4.1's 10-box cells, a
table stream. This recheck makes the choice on dev streams instead (dev.streams, never a
table's scenes). For each range of dev.ch4_piles.pile_ranges it takes the network's dataset
with that n_objects (every other param as params'), split and trained as stages split@ and
train@ do (same seed, epochs, precision), then runs the ch. 4 risk planner (stage trials_ch4's
episode) with each network on every stream of dev.ch4_piles.streams, beside the oracle on
the same scenes. The networks meet the same scenes, so they are compared episode by episode
(McNemar's exact test).

The pipeline's data/generate/<dataset> is used where its shards were made with the same
params; anything else is made under data/dev/ch4_piles/ and reused by a rerun whose params
match. The pipeline's checkpoint is never reused: it does not record the data it was trained
on, and both networks should come from one machine and precision. Writes
experiments/reports/ch4_piles.{json,md}; not a dvc stage.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, read_json, write_json
from experiments.command import OUT, open_recheck, run_command, save
from experiments.config import (
    Ch4PilesConfig,
    Ch4SensingConfig,
    DevConfig,
)
from experiments.stats import (
    ALPHA,
    CRITERIA,
    below_oracle_text,
    paired,
    paired_cells,
    plain,
    rate_text,
)

if TYPE_CHECKING:
    pass

SCRATCH = Path("data/dev/ch4_piles")


def piles_label(piles: Sequence[int]) -> str:
    return f"{piles[0]}-{piles[1]}"


# -- data and networks ------------------------------------------------------------------------
def made_with(out_dir: Path, digest: str) -> bool:
    """Whether dataset dir `out_dir` is complete and every shard was made under `digest`."""
    manifest_file = out_dir / "manifest.json"
    if not manifest_file.exists():
        return False
    manifest = read_json(manifest_file)
    if not isinstance(manifest, dict) or manifest.get("config_hash") != digest:
        return False
    try:
        return all(
            str(load_npz(out_dir / s, ["config_hash"])["config_hash"]) == digest
            for s in manifest["shards"]
        )
    except (ClutterbenchError, KeyError, TypeError):
        return False


def candidate_data(
    dataset: str, piles: tuple[int, int], params: Mapping[str, Any], data_dir: Path, scratch: Path
) -> tuple[Path, str, bool]:
    """Dataset `dataset` with piles of `piles` boxes -> (its generate dir, config hash, whether
    the pipeline's own data/generate/<dataset> is it)."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import config_hash, generate_dataset
    from clutterbench.sim.config import SimConfig

    gen = load_section(GenerateConfig, "generate", params)
    sim = load_section(SimConfig, "sim", params)
    seed = load_section(BaseConfig, "base", params).seed
    try:
        ds = dataclasses.replace(gen.datasets[dataset], n_objects=piles)
    except ValueError as exc:
        raise ClutterbenchError(f"dev.ch4_piles.pile_ranges {list(piles)}: {exc}") from None
    digest = config_hash(dataset, ds, sim, seed)
    if made_with(data_dir / "generate" / dataset, digest):
        return data_dir / "generate", digest, True
    generate_dataset(dataset, ds, gen, sim, seed, scratch / "generate" / dataset)
    return scratch / "generate", digest, False


def candidate_network(
    model: str, params: Mapping[str, Any], gen_dir: Path, digest: str, scratch: Path
) -> dict[str, Any]:
    """Split the dataset in `gen_dir` and train train.models.<model> on it as the stages do
    (a rerun with the same data and training params reuses the network) -> facts for the
    report: checkpoint, training summary, seconds, reused."""
    from clutterbench.collapse.config import TrainConfig
    from clutterbench.collapse.train import TrainPaths, train_model
    from clutterbench.criteria import label_thresholds
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.split import SplitConfig, split_dataset
    from clutterbench.precision import resolve_precision
    from clutterbench.sim.config import SimConfig

    seed = load_section(BaseConfig, "base", params).seed
    cfg = load_section(TrainConfig, "train", params)
    dataset = cfg.models[model].dataset
    fractions = load_section(SplitConfig, "split", params).datasets[dataset]
    threshold = load_section(GenerateConfig, "generate", params).datasets[dataset].moved_threshold_m
    stamp = {
        "data": digest,
        "split": as_dict(fractions),
        "train": as_dict(dataclasses.replace(cfg, models={model: cfg.models[model]})),
        "precision": resolve_precision(cfg.precision),
        "seed": seed,
        "moved_threshold_m": threshold,
        "collapse_free": list(label_thresholds(params)),  # a pull_collapse head's labels
        "fovy_deg": load_section(SimConfig, "sim", params).camera.fovy_deg,  # a sensor's focal
    }
    paths = TrainPaths(
        gen_dir=gen_dir,
        split_file=scratch / "split" / f"{dataset}.json",
        model_dir=scratch / "model",
        report_dir=scratch / "train",
        timing_file=scratch / "timing.json",
    )
    stamp_file = scratch / "network.json"
    done = [stamp_file, paths.model_dir / "best.pt", paths.report_dir / "summary.json"]
    done.append(paths.timing_file)
    reused = all(p.exists() for p in done) and read_json(stamp_file) == stamp
    if not reused:
        split_dataset(dataset, fractions, seed, gen_dir, paths.split_file.parent)
        stamp_file.unlink(missing_ok=True)
        train_model(model, cfg, threshold, seed, paths, label_thresholds(params), stamp["fovy_deg"])
        write_json(stamp_file, stamp)
    split = read_json(paths.split_file)
    return {
        "checkpoint": str(paths.model_dir / "best.pt"),
        "summary": read_json(paths.report_dir / "summary.json"),
        "train_scenes": len(split["train"]),
        "seconds": read_json(paths.timing_file)["seconds"],
        "network_reused": reused,
    }


# -- trials -------------------------------------------------------------------------------------
def trial_jobs(
    candidates: Sequence[dict[str, Any]], dev: DevConfig, params: Mapping[str, Any]
) -> list[dict[str, Any]]:
    """Stage trials_ch4's jobs: the risk planner with each candidate's network, and the
    oracle, on every dev stream of the recheck (conditions '<piles>/<stream>')."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch4.episodes import ch4_jobs
    from clutterbench.trials.config import Ch4ConditionConfig, TrialsConfig

    cfg: Ch4PilesConfig = dev.ch4_piles
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    seed = load_section(BaseConfig, "base", params).seed
    runs = [(c["piles"], "risk", cfg.model, Path(c["checkpoint"])) for c in candidates]
    if cfg.oracle:
        runs.append(("oracle", "oracle", None, None))
    jobs = []
    for stream in cfg.streams:
        for label, planner, model, checkpoint in runs:
            cond = Ch4ConditionConfig(planner, stream, episodes=cfg.episodes, model=model)
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


def summary_rows(
    records: Sequence[Mapping[str, Any]], dev: DevConfig, label: str = "piles"
) -> list[dict[str, Any]]:
    """One row per condition ('<candidate>/<stream>', the candidate under `label`): success
    and strict success with Wilson 95% intervals, the mean disturbed boxes, and the points
    below the oracle on the same stream."""
    from clutterbench.trials.core.stats import aggregate

    frame = aggregate(records)
    rows = []
    for r in frame.to_dict("records"):
        candidate, stream = r["condition"].split("/")
        row = {"condition": r["condition"], label: candidate, "stream": stream}
        s = dev.streams[stream]
        row |= {"n_objects": list(s.n_objects), "catalogue": s.catalogue}
        for key in CRITERIA:
            row |= {f"{key}_{f}": plain(r[f"{key}_{f}"]) for f in ("k", "n", "rate", "lo", "hi")}
        row["mean_n_disturbed"] = float(r["mean_n_disturbed"])
        rows.append(row)
    oracle = {r["stream"]: r for r in rows if r[label] == "oracle"}
    for row in rows:
        for key in CRITERIA:
            top = oracle.get(row["stream"])
            gap = 100 * (top[f"{key}_rate"] - row[f"{key}_rate"]) if top else None
            row[f"{key}_below_oracle_points"] = None if row[label] == "oracle" else gap
    return rows


def what_it_shows(
    comparisons: Sequence[Mapping[str, Any]], rows: Sequence[Mapping[str, Any]], current: str
) -> str:
    """The recheck's finding in words, from the numbers: per alternative range, the paired
    differences beyond chance (Bonferroni) and which way they go, and the oracle gaps."""
    level = ALPHA / max(len(comparisons), 1)
    out = []
    for alt in dict.fromkeys(c["piles"] for c in comparisons):
        mine = [c for c in comparisons if c["piles"] == alt]
        sig = [c for c in mine if c["p"] < level]
        big = max(mine, key=lambda c: (abs(c["difference_points"]), -c["p"]))
        if not sig:
            out.append(
                f"Training on piles of {alt} instead of {current} changes no dev-stream rate "
                f"beyond chance (paired McNemar p >= {level:.3g} on every stream and criterion, "
                f"Bonferroni over {len(comparisons)}; largest difference "
                f"{big['difference_points']:+.1f} points, {CRITERIA[big['criterion']]} on "
                f"{big['stream']}, p = {big['p']:.2f}): these dev streams give no evidence "
                f"for {current} over {alt}, nor against it."
            )
            continue
        cells = "; ".join(
            f"{c['difference_points']:+.1f} points {CRITERIA[c['criterion']]} on {c['stream']} "
            f"(p = {c['p']:.2g})"
            for c in sig
        )
        quiet = [
            s
            for s in dict.fromkeys(c["stream"] for c in mine)
            if s not in {c["stream"] for c in sig}
        ]
        if quiet:
            cells += f"; within chance on {', '.join(quiet)}"
        if all(c["difference_points"] > 0 for c in sig):
            verdict = f"the dev streams favour {alt} over {current}"
        elif all(c["difference_points"] < 0 for c in sig):
            verdict = f"the dev streams support {current} over {alt}"
        else:
            verdict = "the dev streams are split between them"
        out.append(
            f"Piles of {alt} against {current} (paired McNemar, Bonferroni level {level:.3g}): "
            f"{cells}; {verdict}."
        )
    most = max(r["n_objects"][1] for r in rows)
    for stream in dict.fromkeys(r["stream"] for r in rows if r["n_objects"][1] == most):
        gaps = ", ".join(
            f"{r['piles']} {r['success_below_oracle_points']:.0f} / "
            f"{r['strict_success_below_oracle_points']:.0f}"
            for r in rows
            if r["stream"] == stream and r["success_below_oracle_points"] is not None
        )
        if gaps:
            out.append(f"Below the oracle on {stream} (success / strict, points): {gaps}.")
    return " ".join(out)


# -- the report ---------------------------------------------------------------------------------
def markdown(result: Mapping[str, Any]) -> str:
    from clutterbench.platform_info import instruction_set

    c, cpu = result["config"], result["cpu"]
    lines = [
        f"# Dev recheck: the ch. 4 training piles ({result['scale']} scale)",
        "",
        f"`{c['model']}` retrained on its dataset `{result['dataset']}` "
        f"({result['n_scenes']} scenes) with each pile range, then the ch. 4 risk planner "
        f"(stage trials_ch4's episode) with each network on dev streams (own seeds, never a "
        f"table's scenes), {c['episodes']} episodes each; the params' range is "
        f"{result['current']}.",
        "",
        "## Networks",
        "",
        "| piles | data | network | train scenes | train pairs | best epoch / run | val loss "
        "| val IoU (C) | train s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for cand in result["candidates"]:
        s, best = cand["summary"], cand["summary"]["best"]
        data = "the pipeline's" if cand["data_reused"] else "data/dev"
        net = "an earlier run's" if cand["network_reused"] else "trained by this run"
        lines.append(
            f"| {cand['piles']} | {data} | {net} | {cand['train_scenes']} | "
            f"{s['train_pairs']} | {best['epoch']} / {s['epochs_run']} | "
            f"{best['val_loss']:.4f} | {best['val_iou']:.3f} | {cand['seconds']:.0f} |"
        )
    lines += [
        "",
        "## Trials (Wilson 95%)",
        "",
        "| stream | boxes | catalogue | network piles | success | strict success "
        "| below oracle: success / strict (points) | mean disturbed boxes |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        gap = below_oracle_text(r)
        lo, hi = r["n_objects"]
        lines.append(
            f"| {r['stream']} | {lo if lo == hi else f'{lo}-{hi}'} | {r['catalogue']} | "
            f"{r['piles']} | {rate_text(r, 'success')} | {rate_text(r, 'strict_success')} | "
            f"{gap} | "
            f"{r['mean_n_disturbed']:.2f} |"
        )
    lines += [
        "",
        f"## Paired, episode by episode (against {result['current']})",
        "",
        "| stream | criterion | piles | won only by it | won only by "
        f"{result['current']} | difference (points) | McNemar p |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in result["comparisons"]:
        lines.append(
            f"| {p['stream']} | {CRITERIA[p['criterion']]} | {p['piles']} | {paired_cells(p)}"
        )
    lines += [
        "",
        f"**What it shows.** {result['shows']}",
        "",
        "- success: collapse-free (the thesis' trial notion, criteria.py); strict: also "
        "no other box moved more than trials.ch4.moved_threshold_m. Both judged after the "
        "support's release, as in Table 4.1.",
        "- The networks share the training seed; the ranges share the number of scenes, so "
        "smaller piles give fewer (extract, support) pairs. Validation scores are on each "
        "range's own val piles, so they do not compare across rows.",
        f"- Networks in {result['network_precision']} on {cpu['cpu_model']} "
        f"({instruction_set(cpu)}), {cpu['torch_threads']} torch threads; this run took "
        f"{result['seconds'] / 60:.1f} min, its trials {result['trials_seconds'] / 60:.1f}.",
    ]
    return "\n".join(lines) + "\n"


# -- the command -----------------------------------------------------------------------------
def ch4_dataset(
    cfg: Ch4PilesConfig | Ch4SensingConfig, params: Mapping[str, Any], key: str = "ch4_piles"
) -> tuple[str, Any]:
    """The dataset of dev.<key>.model, which must be a ch. 4 network -> (its name, its
    generate config)."""
    from clutterbench.collapse.config import TrainConfig
    from clutterbench.data.config import GenerateConfig

    train = load_section(TrainConfig, "train", params)
    if cfg.model not in train.models:
        known = ", ".join(train.models)
        raise ClutterbenchError(f"dev.{key}.model: no such network '{cfg.model}' ({known})")
    dataset = train.models[cfg.model].dataset
    ds = load_section(GenerateConfig, "generate", params).datasets[dataset]
    if getattr(train.models[cfg.model].net, "n_masks", 1) != 2 or not ds.pulls:
        raise ClutterbenchError(
            f"dev.{key}.model: '{cfg.model}' is not a ch. 4 network (2 masks in, trained on pulls)"
        )
    return dataset, ds


def candidate_networks(
    cfg: Ch4PilesConfig, dataset: str, params: Mapping[str, Any], data_dir: Path, scratch: Path
) -> list[dict[str, Any]]:
    """One network per range of dev.ch4_piles.pile_ranges, on its data (candidate_data,
    candidate_network) -> the report's facts of each."""
    candidates = []
    for piles in cfg.pile_ranges:
        label = piles_label(piles)
        where = scratch / f"piles_{label}"
        t0 = time.perf_counter()
        gen_dir, digest, data_reused = candidate_data(dataset, piles, params, data_dir, where)
        generate_s = time.perf_counter() - t0
        net = candidate_network(cfg.model, params, gen_dir, digest, where)
        candidates.append(
            {"piles": label, "data": str(gen_dir / dataset), "data_reused": data_reused}
            | {"generate_seconds": generate_s}
            | net
        )
        print(f"piles {label}: best epoch {net['summary']['best']['epoch']}", flush=True)
    return candidates


def ch4_piles(
    params: Mapping[str, Any],
    data_dir: Path = Path("data"),
    scratch: Path = SCRATCH,
    out_dir: Path = OUT,
) -> dict[str, Any]:
    """Run the recheck of dev.ch4_piles; writes out_dir/ch4_piles.{json,md}."""
    from clutterbench.platform_info import cpu_description
    from clutterbench.precision import inference_from_params
    from clutterbench.trials.ch4.episodes import run_ch4_episode
    from clutterbench.trials.core.harness import run_episodes
    from clutterbench.trials.core.records import write_records

    started = time.perf_counter()
    base, dev, trials, cfg = open_recheck(params, "ch4_piles")
    dataset, ds = ch4_dataset(cfg, params)
    candidates = candidate_networks(cfg, dataset, params, data_dir, scratch)
    precision = inference_from_params(params)
    t0 = time.perf_counter()
    jobs = trial_jobs(candidates, dev, params)
    results = run_episodes("dev ch4 piles", run_ch4_episode, jobs, trials.workers)
    # condition "<piles>/<stream>": the piles label
    records = [
        r.record | {"piles": j.condition.split("/")[0]} for r, j in zip(results, jobs, strict=True)
    ]
    trials_s = time.perf_counter() - t0
    write_records(scratch / "records.jsonl", records)
    rows = summary_rows(records, dev)
    current = piles_label(ds.n_objects)
    against = current if current in [c["piles"] for c in candidates] else candidates[-1]["piles"]
    comparisons = [
        paired(records, c["piles"], against, stream, key)
        for stream in cfg.streams
        for c in candidates
        if c["piles"] != against
        for key in CRITERIA
    ]
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "config": as_dict(cfg),
        "streams": {s: as_dict(dev.streams[s]) for s in cfg.streams},
        "dataset": dataset,
        "n_scenes": ds.n_scenes,
        "current": against,
        "candidates": candidates,
        "rows": rows,
        "comparisons": comparisons,
        "network_precision": precision,
        "trials_seconds": trials_s,
        "cpu": cpu_description(),
    }
    result["shows"] = what_it_shows(comparisons, rows, against)
    return save(result, started, out_dir, "ch4_piles", markdown)


def main() -> None:
    run_command(ch4_piles, "ch4_piles")


if __name__ == "__main__":
    main()

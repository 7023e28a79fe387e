"""Recheck on dev streams: should the ch. 6 collapse predictor train on the sensor's images?

    python -m experiments.ch6_sensing      # make dev-ch6-sensing

Table 6.3's sensed rows (trials.sensed) run the ch. 6 planners on a depth sensor's pictures
with masks by region growing, while the collapse predictor (trials.ch6.model, every head)
trains on exact depth with the parametric noise of train.noise (train.sensing: ideal). For
each preset of dev.ch6_sensing.training, that network is trained on its dataset as stages
split@ and train@ do (same seed, epochs, precision, heads), its training depth through that
preset's sensor model (train.sensing.preset; spread as params'); its support thresholds are
chosen on the val scenes as the support stage chooses them (exact val depth, as the stages
pick every network's epoch). Then each planner of dev.ch6_sensing.planners (planners that read
the CP and no other network) runs with each network on every stream of
dev.ch6_sensing.streams under dev.ch6_sensing.sensing with masks from depth, beside its Table
6.3 baseline (the training-free planner it is paired with there) under the same sensor and
masks, and both search oracles. Every row meets the same scenes and targets, so the networks
are compared episode by episode (McNemar's exact test) against the params' own
train.sensing.preset, and each network's planner against its baseline.

The pipeline's data/generate/<dataset> is used where it was made with the same params;
anything else is made under data/dev/ch6_sensing/ and reused by a rerun whose params match, as
are the networks. The baselines read reports/support/thresholds.json, as the trials stage does.
Writes experiments/reports/ch6_sensing.{json,md}; not a dvc stage.
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
from experiments.ch4_sensing import LABEL, comparisons_of, run_and_pair, with_training_sensing
from experiments.ch6_pull import ORACLE_VARIANT, THRESHOLDS, condition_label
from experiments.ch6_sensing_report import markdown, parts_text
from experiments.command import OUT, open_recheck, run_command, save
from experiments.config import Ch6SensingConfig, DevConfig
from experiments.detector_sensing import dataset_dir
from experiments.stats import ALPHA, CRITERIA, paired, plain

NAME = "ch6_sensing"
SCRATCH = Path("data/dev/ch6_sensing")
BASELINE = "baseline"
"""The label of the rows of the training-free planners (they read no network)."""
PARTS = (("ideal", "instance"), ("sensor", "instance"), ("ideal", "depth"))
"""(sensing, masks) each planner also runs under with the params' own network, beside the
sensor with masks from depth: where the points go (sensor: dev.ch6_sensing.sensing)."""


def part_label(label: str, sensing: str, perception: str) -> str:
    """A row's label when it saw other than the sensor with masks from depth."""
    return f"{label} ({sensing}, {perception} masks)"


def parts_of(cfg: Ch6SensingConfig) -> list[tuple[str, str]]:
    """PARTS with the recheck's sensor named."""
    return [(cfg.sensing if s == "sensor" else s, m) for s, m in PARTS]


def params_preset(cfg: Ch6SensingConfig, params: Mapping[str, Any]) -> str:
    """The params' own training preset, or the first candidate where it is none of them (the
    one every other is paired against, as run_and_pair says)."""
    from clutterbench.collapse.config import TrainConfig

    current = load_section(TrainConfig, "train", params).sensing.preset
    return current if current in cfg.training else cfg.training[0]


def check_planners(cfg: Ch6SensingConfig) -> list[str]:
    """Each planner reads the collapse predictor and no other network -> their baselines, in
    order (one-line errors otherwise)."""
    from clutterbench.trials.ch6.episodes import planner_info

    baselines = []
    for name in cfg.planners:
        info = planner_info(name)
        if info.networks != {"cp"}:
            raise ClutterbenchError(
                f"dev.ch6_sensing.planners: {name} reads {sorted(info.networks) or 'no network'}"
                ", not the collapse predictor alone"
            )
        if info.baseline is None:
            raise ClutterbenchError(f"dev.ch6_sensing.planners: {name} has no baseline")
        baselines.append(info.baseline)
    return list(dict.fromkeys(baselines))


def chosen_thresholds(
    params: Mapping[str, Any], checkpoint: Path, gen_dir: Path, split_file: Path, out: Path
) -> Path:
    """The support stage's first step for the network `checkpoint`: every method's thresholds
    chosen on the val scenes of support.val_dataset (val_sweep, choose_all), written as
    out/thresholds.json in the stage's format (the box head's entries copied from the stage's
    own: no planner here reads them) -> its path."""
    from clutterbench.criteria import label_thresholds
    from clutterbench.io import read_json
    from clutterbench.precision import inference_from_params
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.support.evaluate import choose_all, contact_edge_rate
    from clutterbench.support.run import (
        SupportPaths,
        ValChoice,
        load_predictors,
        val_scenes,
        val_sweep,
        write_thresholds,
    )

    cfg = load_section(SupportEvalConfig, "support", params)
    sim = load_section(SimConfig, "sim", params)
    precision = inference_from_params(params)
    models = load_predictors(checkpoint, sim.camera.image_size)
    read = {"heads": models.heads, "collapse_free": label_thresholds(params)}
    paths = dataclasses.replace(
        SupportPaths.of(cfg, out, out), model=checkpoint, gen_dir=gen_dir, split_file=split_file
    )
    val = val_scenes(cfg, sim, paths, read)
    sweep = val_sweep(val, cfg, models)
    chosen = choose_all(sweep)
    box = read_json(THRESHOLDS)["box_head"]
    edge_rate = contact_edge_rate(val, chosen["coverage"])
    write_thresholds(out, ValChoice(sweep, chosen, edge_rate, box, {}), len(val), precision, {})
    return out / "thresholds.json"


def candidate_networks(
    cfg: Ch6SensingConfig, params: Mapping[str, Any], data_dir: Path, scratch: Path
) -> list[dict[str, Any]]:
    """One network per training preset, all on the params' dataset, each with the support
    thresholds chosen on its val scenes -> the report's facts."""
    from clutterbench.collapse.config import TrainConfig
    from clutterbench.io import read_json
    from clutterbench.trials.config import TrialsConfig

    model = load_section(TrialsConfig, "trials", params).ch6.model
    dataset = load_section(TrainConfig, "train", params).models[model].dataset
    gen_dir, digest, data_reused = dataset_dir(dataset, params, data_dir, scratch)
    candidates = []
    for preset in cfg.training:
        where = scratch / preset
        net = candidate_network(
            model, with_training_sensing(params, preset), gen_dir, digest, where
        )
        split_file = where / "split" / f"{dataset}.json"
        thresholds = chosen_thresholds(params, Path(net["checkpoint"]), gen_dir, split_file, where)
        candidates.append(
            {LABEL: preset, "model": model, "dataset": dataset, "data_reused": data_reused}
            | net
            | {"thresholds": str(thresholds), "chosen": read_json(thresholds)["chosen"]}
        )
        print(f"training {preset}: best epoch {net['summary']['best']['epoch']}", flush=True)
    return candidates


def trial_jobs(
    candidates: Sequence[Mapping[str, Any]], dev: DevConfig, params: Mapping[str, Any]
) -> list[Any]:
    """Stage trials' jobs: each planner with each candidate's network and thresholds under the
    recheck's sensor and masks from depth ('<training>:<planner>/<stream>'), the planners'
    baselines under the same ('baseline:<planner>/<stream>'), both search oracles on the
    world ('-:<oracle>/<stream>') and, with dev.ch6_sensing.parts, the params' network's
    planners and the baselines under each of PARTS ('<label> (<sensing>, <masks> masks):...'),
    on every dev stream."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6.episodes import ch6_jobs, planner_support
    from clutterbench.trials.config import ConditionConfig, TrialsConfig

    cfg: Ch6SensingConfig = dev.ch6_sensing
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    seed = load_section(BaseConfig, "base", params).seed
    seen = {"sensing": cfg.sensing, "perception": "depth"}
    runs = [
        (c[LABEL], p, Path(c["checkpoint"]), Path(c["thresholds"]), seen)
        for c in candidates
        for p in cfg.planners
    ]
    runs += [(BASELINE, p, None, THRESHOLDS, seen) for p in check_planners(cfg)]
    runs += [(ORACLE_VARIANT, o, None, THRESHOLDS, {}) for o in ("oracle", "oracle_hold")] * (
        cfg.oracle
    )
    if cfg.parts:  # the params' network's planners and the baselines, under each part
        own = next(c for c in candidates if c[LABEL] == params_preset(cfg, params))
        for sensing, masks in parts_of(cfg):
            how = {"sensing": sensing, "perception": masks}
            runs += [
                (
                    part_label(own[LABEL], sensing, masks),
                    p,
                    Path(own["checkpoint"]),
                    Path(own["thresholds"]),
                    how,
                )
                for p in cfg.planners
            ]
            runs += [
                (part_label(BASELINE, sensing, masks), p, None, THRESHOLDS, how)
                for p in check_planners(cfg)
            ]
    rule = ConditionConfig.__dataclass_fields__["rule"].default
    jobs = []
    for stream in cfg.streams:
        for label, planner, checkpoint, thresholds, how in runs:
            support, cp_max = planner_support(thresholds, planner, rule, trials.ch6)
            built = ch6_jobs(
                f"{condition_label(label, planner)}/{stream}",
                ConditionConfig(planner, stream, cfg.episodes, rule, **how),
                trials=trials,
                sim=sim,
                seed=seed,
                support=support,
                cp_max=cp_max,
                model_path=checkpoint,
                stream_cfg=dev.streams[stream],
            )
            jobs += [dataclasses.replace(j, record_images=False) for j in built]
    return jobs


def summary_rows(records: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per condition: success and strict success (Wilson 95%), the episodes that gave
    up or grasped no box, and the points below the planner's search oracle on the stream."""
    from clutterbench.trials.ch6.episodes import planner_info
    from clutterbench.trials.core.stats import aggregate

    rows = []
    for r in aggregate(records).to_dict("records"):
        label, stream = r["condition"].split("/")
        training, planner = label.split(":")
        mine = [x for x in records if x["condition"] == r["condition"]]
        row = {"condition": r["condition"], "stream": stream, LABEL: training, "planner": planner}
        for key in CRITERIA:
            row |= {f"{key}_{f}": plain(r[f"{key}_{f}"]) for f in ("k", "n", "rate", "lo", "hi")}
        row["gave_up"] = sum(x["end"] == "gave_up" for x in mine)
        row["missed_grasp"] = sum(x["end"] == "missed_grasp" for x in mine)
        reads_cp = "cp" in planner_info(planner).networks  # max_cp is the CP's score
        rows.append(row | (pull_scores(mine) if reads_cp else {}))
    oracles = {(r["stream"], r["planner"]): r for r in rows if r[LABEL] == ORACLE_VARIANT}
    for row in rows:
        top = oracles.get((row["stream"], planner_info(row["planner"]).ceiling))
        for key in CRITERIA:
            gap = 100 * (top[f"{key}_rate"] - row[f"{key}_rate"]) if top else None
            row[f"{key}_below_oracle_points"] = None if row[LABEL] == ORACLE_VARIANT else gap
    return rows


def pull_scores(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """How a CP row's collapse score (its highest during each pull, max_cp) read the pulls
    that kept the scene collapse-free and those that collapsed it: their count and mean score,
    and the pulls it aborted."""
    steps = [s for r in records for s in r.get("steps") or () if s.get("max_cp") is not None]
    out: dict[str, Any] = {}
    for kind, kept in (("safe", True), ("collapsed", False)):
        scores = [float(s["max_cp"]) for s in steps if s.get("collapse_free") is kept]
        out[f"pulls_{kind}"] = len(scores)
        out[f"score_{kind}"] = sum(scores) / len(scores) if scores else None
    out["aborted"] = sum(
        bool(s.get("aborted_before_motion") or s.get("aborted_after_motion")) for s in steps
    )
    return out


def comparisons(
    records: Sequence[Mapping[str, Any]], cfg: Ch6SensingConfig, against: str
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(each other candidate against `against`, planner by planner; each candidate's planner
    against its baseline), per stream and criterion, episode by episode."""
    from clutterbench.trials.ch6.episodes import planner_info

    by_training = []
    for planner in cfg.planners:
        mine = [
            r | {"condition": r["condition"].replace(f":{planner}/", "/")}
            for r in records
            if f":{planner}/" in r["condition"]
        ]
        by_training += [c | {"planner": planner} for c in comparisons_of(mine, cfg, against)]
    by_baseline = [
        paired(
            records,
            condition_label(preset, planner),
            condition_label(BASELINE, planner_info(planner).baseline),
            stream,
            key,
        )
        | {LABEL: preset, "planner": planner, "baseline": planner_info(planner).baseline}
        for stream in cfg.streams
        for preset in cfg.training
        for planner in cfg.planners
        for key in CRITERIA
    ]
    return by_training, by_baseline


def by_part(
    records: Sequence[Mapping[str, Any]], cfg: Ch6SensingConfig, against: str
) -> list[dict[str, Any]]:
    """Where the points go: for the params' network's planners and the baselines, each other
    (sensing, masks) against exact depth with the simulator's masks, collapse-free, episode by
    episode (empty without dev.ch6_sensing.parts)."""
    if not cfg.parts:
        return []
    first, *others = parts_of(cfg)
    out = []
    for stream in cfg.streams:
        for label, planner in [(against, p) for p in cfg.planners] + [
            (BASELINE, b) for b in check_planners(cfg)
        ]:
            ref = condition_label(part_label(label, *first), planner)
            for sensing, masks in [*others, (cfg.sensing, "depth")]:
                shown = label if masks == "depth" and sensing == cfg.sensing else None
                name = shown or part_label(label, sensing, masks)
                out.append(
                    paired(records, condition_label(name, planner), ref, stream, "success")
                    | {"row": label, "planner": planner, "sensing": sensing, "masks": masks}
                )
    return out


def what_it_shows(
    by_training: Sequence[Mapping[str, Any]],
    by_baseline: Sequence[Mapping[str, Any]],
    rows: Sequence[Mapping[str, Any]],
    against: str,
) -> str:
    """The finding in words, from the numbers: the paired differences between trainings beyond
    chance (Bonferroni over them) and which way they go; then, per network and planner, the
    collapse-free difference to the baseline and whether it is beyond chance (exact McNemar
    p < ALPHA, the table's own test); then the points below the oracles."""
    level = ALPHA / max(len(by_training), 1)
    sig = [c for c in by_training if c["p"] < level]
    out = []
    if not sig:
        out.append(
            f"No training changes a planner's dev-stream rate beyond chance against {against} "
            f"(paired McNemar p >= {level:.3g} on every planner, stream and criterion, "
            f"Bonferroni over {len(by_training)})."
        )
    else:
        cells = "; ".join(
            f"{c[LABEL]} {c['difference_points']:+.1f} points {CRITERIA[c['criterion']]} for "
            f"{c['planner']} on {c['stream']} (p = {c['p']:.2g})"
            for c in sig
        )
        ups = all(c["difference_points"] > 0 for c in sig)
        downs = all(c["difference_points"] < 0 for c in sig)
        verdict = (
            "the dev streams favour training on the sensor"
            if ups
            else f"the dev streams favour training on {against}"
            if downs
            else "the dev streams are split"
        )
        out.append(
            f"Against {against} (paired McNemar, Bonferroni level {level:.3g}): {cells}; {verdict}."
        )
    vs = [
        f"{c['planner']} ({c[LABEL]}) {c['difference_points']:+.1f} points against "
        f"{c['baseline']} on {c['stream']} (p = {c['p']:.2g}"
        f"{', beyond chance' if c['p'] < ALPHA else ''})"
        for c in by_baseline
        if c["criterion"] == "success"
    ]
    out.append("Collapse-free, against the baseline under the same sensing: " + "; ".join(vs) + ".")
    gaps = ", ".join(
        f"{r['planner']} ({r[LABEL]}) {r['success_below_oracle_points']:.0f}"
        for r in rows
        if r["success_below_oracle_points"] is not None and " (" not in r[LABEL]  # no part
    )
    out.append(f"Points below the search oracle (collapse-free): {gaps}.")
    return " ".join(out)


def ch6_sensing(
    params: Mapping[str, Any],
    data_dir: Path = Path("data"),
    scratch: Path = SCRATCH,
    out_dir: Path = OUT,
) -> dict[str, Any]:
    """Run the recheck of dev.ch6_sensing; writes out_dir/ch6_sensing.{json,md}."""
    from clutterbench.platform_info import cpu_description
    from clutterbench.precision import inference_from_params
    from clutterbench.trials.ch6.episodes import planner_info, run_ch6_episode
    from clutterbench.trials.config import ConditionConfig

    started = time.perf_counter()
    base, dev, trials, cfg = open_recheck(params, "ch6_sensing")
    check_planners(cfg)
    if not THRESHOLDS.exists():
        raise ClutterbenchError(f"{THRESHOLDS} missing (the baselines read it); run support")
    candidates = candidate_networks(cfg, params, data_dir, scratch)
    jobs = trial_jobs(candidates, dev, params)
    records, trials_s, against, _ = run_and_pair(
        "dev ch6 sensing", run_ch6_episode, jobs, cfg, params, scratch
    )
    by_training, by_baseline = comparisons(records, cfg, against)
    parts = by_part(records, cfg, against)
    rows = summary_rows(records)
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "config": as_dict(cfg),
        "streams": {s: as_dict(dev.streams[s]) for s in cfg.streams},
        "current": against,
        "candidates": candidates,
        "pull_method": planner_info(cfg.planners[0]).support_method(
            ConditionConfig.__dataclass_fields__["rule"].default, trials.ch6.pull_map_meaning
        ),
        "rows": rows,
        "by_training": by_training,
        "by_baseline": by_baseline,
        "by_part": parts,
        "network_precision": inference_from_params(params),
        "n_episodes": len(records),
        "trials_seconds": trials_s,
        "cpu": cpu_description(),
    }
    result["shows"] = what_it_shows(by_training, by_baseline, rows, against)
    if parts:
        result["shows"] += " " + parts_text(parts)
    return save(result, started, out_dir, NAME, markdown)


if __name__ == "__main__":
    run_command(ch6_sensing, NAME)

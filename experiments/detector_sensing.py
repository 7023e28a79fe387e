"""Recheck on validation scenes: should the arrangement detector train on the sensor's images?

    python -m experiments.detector_sensing     # make dev-detector-sensing (~45 min at default)

Table 5.2's sensed rows (trials.ch5_sensed) run the arrangement detector on a depth sensor's
pictures, while it trains on exact depth with the parametric noise of detector.noise
(detector.sensing: ideal). For each preset of dev.detector_sensing.training, the detector is
trained as stage detector trains it (same data, split, seed, epochs, precision), its training
depth through that preset's sensor model (detector.sensing.preset; spread as params'). Each
network is then scored on the val split's images as each preset of
dev.detector_sensing.scored_on returns them (sim/sensor.py's `sense`, seeded by base.seed and
the image): mAP@0.5 and, at the thesis' score threshold, precision and recall. The difference
of mAP between two networks on the same images is bootstrapped over scenes (the same resampled
scenes for both). Val scenes are never a table's: the test split, which the detector stage
scores, is not read.

The pipeline's data/generate/<detector.dataset> is used where its shards were made with the
same params (`dvc repro split@<dataset>` makes them); else the dataset is made under
data/dev/detector_sensing/. Networks are kept there and reused by a rerun whose params match.
Writes experiments/reports/detector_sensing.{json,md}; not a dvc stage.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json
from experiments.ch4_piles import made_with
from experiments.command import OUT, run_command, save
from experiments.config import load_dev

NAME = "detector_sensing"
SCRATCH = Path("data/dev/detector_sensing")
CI = (2.5, 97.5)
"""The bootstrap interval's percentiles."""


def dataset_dir(
    name: str, params: Mapping[str, Any], data_dir: Path, scratch: Path
) -> tuple[Path, str, bool]:
    """Generated dataset `name`'s generate dir (the pipeline's where made with these params,
    else made under `scratch`) -> (that dir, the data's config hash, whether it is the
    pipeline's)."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import config_hash, generate_dataset
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.config import TrialsConfig

    gen = load_section(GenerateConfig, "generate", params)
    if name not in gen.datasets:
        raise ClutterbenchError(f"generate.datasets: unknown dataset '{name}'")
    sim = load_section(SimConfig, "sim", params)
    seed = load_section(BaseConfig, "base", params).seed
    # a dataset with pull outcomes pulls as the ch. 6 trials do, as stage generate makes it
    ch6 = load_section(TrialsConfig, "trials", params).ch6
    pull = (ch6.pull_increment_m, ch6.grasp_lift_m)
    digest = config_hash(name, gen.datasets[name], sim, seed, pull)
    if made_with(data_dir / "generate" / name, digest):
        return data_dir / "generate", digest, True
    if not made_with(scratch / "generate" / name, digest):
        generate_dataset(
            name, gen.datasets[name], gen, sim, seed, scratch / "generate" / name, pull
        )
    return scratch / "generate", digest, False


def candidate(
    preset: str, params: Mapping[str, Any], gen_dir: Path, digest: str, scratch: Path
) -> dict[str, Any]:
    """The detector trained with detector.sensing.preset `preset` as stage detector trains it (a
    rerun with the same data and params reuses it) -> facts for the report."""
    from clutterbench.collapse.config import TrainSensingConfig
    from clutterbench.collapse.detector import DetectorParams, DetectorPaths, train_detector
    from clutterbench.data.split import SplitConfig, split_dataset
    from clutterbench.precision import resolve_precision
    from clutterbench.sim.config import SimConfig

    seed = load_section(BaseConfig, "base", params).seed
    p = load_section(DetectorParams, "detector", params)
    p = dataclasses.replace(p, sensing=TrainSensingConfig(preset, p.sensing.spread))
    fractions = load_section(SplitConfig, "split", params).datasets[p.dataset]
    fovy = load_section(SimConfig, "sim", params).camera.fovy_deg
    stamp = {
        "data": digest,
        "split": as_dict(fractions),
        "detector": as_dict(p),
        "precision": resolve_precision(p.precision),
        "seed": seed,
        "fovy_deg": fovy,
    }
    where = scratch / preset
    paths = DetectorPaths(
        gen_dir=gen_dir,
        split_file=where / "split" / f"{p.dataset}.json",
        model_dir=where / "model",
        report_dir=where / "detector",
        timing_file=where / "timing.json",
    )
    stamp_file, summary_file = where / "network.json", where / "summary.json"
    done = (stamp_file, summary_file, paths.model_dir / "best.pt", paths.timing_file)
    reused = all(f.exists() for f in done) and read_json(stamp_file) == stamp
    if not reused:
        split_dataset(p.dataset, fractions, seed, gen_dir, paths.split_file.parent)
        stamp_file.unlink(missing_ok=True)
        _, summary = train_detector(p, seed, paths, fovy)
        write_json(summary_file, summary)
        write_json(stamp_file, stamp)
    return {
        "training": preset,
        "checkpoint": str(paths.model_dir / "best.pt"),
        "split_file": str(paths.split_file),
        "summary": read_json(summary_file),
        "seconds": float(read_json(paths.timing_file)["train_s"]),
        "network_reused": reused,
    }


def scores(
    candidates: Sequence[Mapping[str, Any]], params: Mapping[str, Any], gen_dir: Path
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(one row per network and val sensing: mAP, per-class AP, precision / recall at the score
    threshold; per val sensing and pair of networks: the mAP difference, bootstrapped)."""
    from clutterbench.collapse.detection_metrics import mean_ap
    from clutterbench.collapse.detector import (
        ArrangementDetector,
        DetectorParams,
        ap_summary,
        detect_all,
        truth_of,
    )
    from clutterbench.data.arrangement import load_arrangement_split
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.sensor import sense_images

    cfg = load_dev(params).detector_sensing
    p = load_section(DetectorParams, "detector", params)
    seed = load_section(BaseConfig, "base", params).seed
    fovy = load_section(SimConfig, "sim", params).camera.fovy_deg
    val = load_arrangement_split(gen_dir, Path(candidates[0]["split_file"]), "val")
    if len(val) == 0:
        raise ClutterbenchError(f"detector_sensing: dataset '{p.dataset}' has no val scenes")
    truth = truth_of(val)
    nets = {
        c["training"]: ArrangementDetector.from_checkpoint(Path(c["checkpoint"]))
        for c in candidates
    }
    rows, diffs = [], []
    draws = np.random.default_rng(seed).integers(0, len(val), size=(cfg.bootstrap, len(val)))
    for scored_on in cfg.scored_on:
        images = dataclasses.replace(val, depth_m=sense_images(val.depth_m, scored_on, fovy, seed))
        dets = {name: detect_all(net, images, p.eval_score_threshold) for name, net in nets.items()}
        for name, d in dets.items():
            map50, prs = mean_ap(d, truth, p.net.n_classes, p.match_iou)
            rows.append(
                {"training": name, "scored_on": scored_on}
                | ap_summary(prs, map50, p.score_threshold)
            )
        first, *others = list(nets)
        for other in others:
            boot = []
            for idx in draws:
                t = [truth[i] for i in idx]
                a = mean_ap([dets[other][i] for i in idx], t, p.net.n_classes, p.match_iou)[0]
                b = mean_ap([dets[first][i] for i in idx], t, p.net.n_classes, p.match_iou)[0]
                boot.append(a - b)
            lo, hi = np.nanpercentile(boot, CI)
            mine = {r["training"]: r["map50"] for r in rows if r["scored_on"] == scored_on}
            diffs.append(
                {"scored_on": scored_on, "training": other, "against": first}
                | {"difference": mine[other] - mine[first], "ci": [float(lo), float(hi)]}
            )
    return rows, diffs


def what_it_shows(diffs: Sequence[Mapping[str, Any]]) -> str:
    """The finding in words, from the numbers."""
    out = []
    for d in diffs:
        lo, hi = d["ci"]
        beyond = "beyond" if lo > 0 or hi < 0 else "within"
        out.append(
            f"on val images through {d['scored_on']}, the detector trained on {d['training']} "
            f"scores mAP@0.5 {d['difference']:+.3f} against the one trained on {d['against']} "
            f"(95% scene bootstrap [{lo:+.3f}, {hi:+.3f}]: {beyond} chance)"
        )
    text = "; ".join(out)
    return text[:1].upper() + text[1:]


def markdown(result: Mapping[str, Any]) -> str:
    from clutterbench.platform_info import instruction_set

    c, cpu = result["config"], result["cpu"]
    lines = [
        f"# Dev recheck: the arrangement detector trained on the sensor's images "
        f"({result['scale']} scale)",
        "",
        f"The detector (thesis 5.2.1) trained as stage detector trains it on `{result['dataset']}` "
        f"with each training sensor (detector.sensing.preset; ideal: the parametric noise of "
        f"detector.noise), then scored on the {result['val_images']} val images as each sensor "
        "returns them (never the test split, which the stage scores).",
        "",
        "## Networks",
        "",
        "| training | data | network | best epoch / run | val mAP@0.5 (its own sensor's images) "
        "| train s |",
        "|---|---|---|---|---|---|",
    ]
    data = "the pipeline's" if result["data_reused"] else "data/dev"
    for cand in result["candidates"]:
        s = cand["summary"]
        net = "an earlier run's" if cand["network_reused"] else "trained by this run"
        lines.append(
            f"| {cand['training']} | {data} | {net} | {s['best']['epoch']} / {s['epochs_run']} "
            f"| {s['best'].get('val_map50') or float('nan'):.3f} | {cand['seconds']:.0f} |"
        )
    from clutterbench.sim.clusters import CLASSES

    seen = result["rows"][0]["per_class"]  # the thesis' order, whatever the JSON's
    classes = [k for k in CLASSES if k in seen] + [k for k in seen if k not in CLASSES]
    lines += [
        "",
        "## Val scores by the sensor of the images",
        "",
        "| images | training | mAP@0.5 | "
        + " | ".join(f"AP {k}" for k in classes)
        + " | precision / recall at the threshold (mean over classes) |",
        "|---|---|---|" + "---|" * len(classes) + "---|",
    ]
    for r in result["rows"]:
        pcs = [r["per_class"][k] for k in classes]
        prec = np.nanmean([v["precision_at_threshold"] for v in pcs])
        rec = np.nanmean(
            [np.nan if v["recall_at_threshold"] is None else v["recall_at_threshold"] for v in pcs]
        )
        aps = " | ".join("n/a" if v["ap50"] is None else f"{v['ap50']:.3f}" for v in pcs)
        lines.append(
            f"| {r['scored_on']} | {r['training']} | {r['map50']:.3f} | {aps} | "
            f"{prec:.3f} / {rec:.3f} |"
        )
    lines += [
        "",
        f"## Paired differences ({c['bootstrap']} scene bootstrap draws, 95%)",
        "",
        "| images | training | against | mAP@0.5 difference | interval |",
        "|---|---|---|---|---|",
    ]
    for d in result["differences"]:
        lines.append(
            f"| {d['scored_on']} | {d['training']} | {d['against']} | {d['difference']:+.3f} | "
            f"[{d['ci'][0]:+.3f}, {d['ci'][1]:+.3f}] |"
        )
    lines += [
        "",
        f"**What it shows.** {result['shows']}.",
        "",
        "- Both networks share the data, the split and the training seed; the val split also "
        "picked each one's epoch, on the images of its own training sensor.",
        f"- Networks on {cpu['cpu_model']} ({instruction_set(cpu)}), {cpu['torch_threads']} "
        f"torch threads; this run took {result['seconds'] / 60:.1f} min.",
    ]
    return "\n".join(lines) + "\n"


def detector_sensing(
    params: Mapping[str, Any],
    data_dir: Path = Path("data"),
    scratch: Path = SCRATCH,
    out_dir: Path = OUT,
) -> dict[str, Any]:
    """Run the recheck of dev.detector_sensing; writes out_dir/detector_sensing.{json,md}."""
    from clutterbench.collapse.detector import DetectorParams
    from clutterbench.platform_info import cpu_description

    started = time.perf_counter()
    base = load_section(BaseConfig, "base", params)
    cfg = load_dev(params).detector_sensing
    dataset = load_section(DetectorParams, "detector", params).dataset
    gen_dir, digest, data_reused = dataset_dir(dataset, params, data_dir, scratch)
    candidates = []
    for preset in cfg.training:
        candidates.append(candidate(preset, params, gen_dir, digest, scratch))
        print(f"training {preset}: best epoch {candidates[-1]['summary']['best']['epoch']}")
    rows, diffs = scores(candidates, params, gen_dir)
    result = {
        "scale": base.scale,
        "seed": base.seed,
        "config": as_dict(cfg),
        "dataset": dataset,
        "data_reused": data_reused,
        "val_images": candidates[0]["summary"]["val_images"],
        "candidates": candidates,
        "rows": rows,
        "differences": diffs,
        "cpu": cpu_description(),
    }
    result["shows"] = what_it_shows(diffs)
    return save(result, started, out_dir, NAME, markdown)


if __name__ == "__main__":
    run_command(detector_sensing, NAME)

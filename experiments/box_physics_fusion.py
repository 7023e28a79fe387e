"""Recheck: do the box head and physics from depth, fused per box, predict what a pull does
better than either? Chosen and scored on the val scenes the box_head stage validates on.

    python -m experiments.box_physics_fusion     # make dev-box-physics-fusion (after box_head)

For each of the stage's val scenes (the first support.box_head.val_scenes of the val
dataset's val split) and each visible box x pulled, three answers for every other visible
box y:
- `box_head`: the box head's probability (collapse/box_predict.py BoxMaps), per pull label
  kind (what the pull moves, what it collapses);
- `physics_from_depth`: the boxes fitted to the depth image and masks, settled, x pulled out
  by the trials' executor (the support stage's physics-from-depth row, the planners' model):
  1 where that marks y, else 0; a box the fit dropped has no answer;
- `fused`: a logistic regression on the head's logit and the simulated outcome (two
  inputs: simulated and marked, simulated and not), one per label kind.
The support graph's edge is the fused outcome times a contact probability, the box head's in
the stage. On one fit, the fused graph is also scored with other contacts (CONTACTS): the
fitted scene's own (its boxes touching once settled, the truth's rule, sim.labelling
settled_contacts; the head's where a box was not fitted), the mean of the two, a learned
contact (a logistic regression of the true contact on the head's contact logit and the fitted
share of touching, support/box_fusion.py `fit_contact`: trials.ch6.box_contact learned, fitted
on the other half as the fusion is), and the true
contact (a ceiling no robot has): how much of the graph's error is the contact's.
Physics from depth and the fusion are scored for each number of scenes fitted to the image in
FITS (trials.ch6.fit_hypotheses: the fit, then fits of noisy copies of the depth image with
trials.ch6.fit_noise_mm; the outcome the share of fits whose pull marks y).
The fusion is cross-fitted: the val scenes in two halves (alternate scenes), the weights and
every threshold fitted on one half and scored on the other, both ways, so each scene's
score comes from choices made without it. Scored per pair (AUROC, precision and recall at
1/2, ECE) and as Table 6.2's support graph (an edge where outcome x contact exceeds a
threshold chosen on the other half by the f1 of mean precision and recall; mean precision
and recall over scenes, against that label kind's truth). The contacts' graphs are also
scored at the precision-first operating point (PRECISION_FIRST: the edge threshold of the
highest recall among those whose precision reaches it on the other half) and over every
threshold (the JSON's `curve`, out of fold). Never the test dataset.
Writes experiments/reports/box_physics_fusion.{json,md,png} (the png: precision against recall of
the contacts' graphs); not a dvc stage.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.collapse.box_head import EDGE_HEADS, off_diagonal
from clutterbench.support.box_fusion import (
    FusionScene,
    answer_scene,
    choose_edge_threshold,
    choose_fusion,
    fit_contact,
    fitted_contacts,
    fitted_pulls,
    graph_scores,
    method_probs,
    precision_first,
)
from clutterbench.support.box_train import THRESHOLDS, binary_scores
from experiments.command import OUT, run_command, save

NAME = "box_physics_fusion"
METHODS = ("box_head", "physics_from_depth", "fused")
FOLDS = 2
FITS = (1, 4)
"""The numbers of scenes fitted to one image that the recheck scores (trials.ch6.fit_hypotheses)."""
CONTACTS = ("head", "fitted", "mean", "learned", "truth")
"""The contacts of the one-fit fused graph's edges (module docstring)."""
PRECISION_FIRST = 0.90
"""The precision-first operating point: the edge threshold of the highest mean recall among
those whose mean precision reaches this on the other half (the highest precision where none
does), the precision the project aims Table 6.2's per-box graph at."""


def contact_of(name: str, weights: Sequence[float] = ()):
    """ContactFn of contact `name` over scenes whose fitted_contact is filled in (the share of
    their fits in which x and y touch, NaN where a fit lacks either); `weights`: the learned
    contact's (support/box_fusion.py fit_contact)."""
    from clutterbench.support.box_fusion import head_contact, learned_contact

    if name == "learned":
        if len(weights) != 4:
            raise ValueError("the learned contact needs its four weights (fit_contact)")
        return learned_contact(weights)

    def contact(sc: FusionScene) -> np.ndarray:
        head = head_contact(sc)
        if name == "head":
            return head
        if name == "truth":
            return sc.contact.astype(np.float64)
        mine = sc.fitted_contact
        assert mine is not None, "the fitted contacts were not asked for"
        known = np.isfinite(mine)
        if name == "fitted":
            return np.where(known, mine, head)
        if name == "mean":
            return np.where(known, 0.5 * (np.nan_to_num(mine) + head), head)
        raise ValueError(f"unknown contact {name!r}")

    return contact


def contact_cross_fit(scenes: Sequence[FusionScene], kind: str) -> dict[str, Any]:
    """The fused graph under `kind` with each of CONTACTS: per fold, the fusion's weights and
    the contact's edge threshold chosen on the other folds, scored on it."""
    folds = [list(scenes[f::FOLDS]) for f in range(FOLDS)]
    rest = [[sc for g, part in enumerate(folds) if g != f for sc in part] for f in range(FOLDS)]
    # the fusion's weights do not depend on the contact: once per fold
    weights = [np.array(choose_fusion(fit, kind)["weights"]) for fit in rest]
    rows = {}
    for name in CONTACTS:
        graph, edge, learned, touch_p, touch_y = [], [], [], [], []
        first, first_edge, curves = [], [], []
        for held, fit, w in zip(folds, rest, weights, strict=True):
            cw = fit_contact(fit) if name == "learned" else ()
            learned.append([round(float(v), 4) for v in cw])
            contact = contact_of(name, cw)
            prob = lambda sc, w=w: method_probs(sc, kind, "fused", w)  # noqa: E731
            t = choose_edge_threshold(fit, prob, kind, contact)
            edge.append(t)
            graph.append((graph_scores(held, prob, kind, t, contact), len(held)))
            touch_p.append(np.concatenate([off_diagonal(contact(sc)) for sc in held]))
            touch_y.append(np.concatenate([off_diagonal(sc.contact) for sc in held]))
            # every threshold, on the other half (to choose) and out of fold (to score)
            chosen = precision_first(
                [graph_scores(fit, prob, kind, float(u), contact) for u in THRESHOLDS],
                PRECISION_FIRST,
            )
            curve = [graph_scores(held, prob, kind, float(u), contact) for u in THRESHOLDS]
            first_edge.append(float(THRESHOLDS[chosen]))
            first.append((curve[chosen], len(held)))
            curves.append((curve, len(held)))
        n = sum(k for _, k in graph)
        rows[name] = {
            "contact_auroc": binary_scores(
                np.concatenate(touch_p), np.concatenate(touch_y).astype(float), 0.5
            )["auroc"],
            "graph_precision": sum(pr[0] * k for pr, k in graph) / n,
            "graph_recall": sum(pr[1] * k for pr, k in graph) / n,
            "edge_thresholds": edge,
            "precision_first": {
                "graph_precision": sum(pr[0] * k for pr, k in first) / n,
                "graph_recall": sum(pr[1] * k for pr, k in first) / n,
                "edge_thresholds": first_edge,
            },
            "curve": [
                {
                    "edge": float(u),
                    "graph_precision": sum(c[i][0] * k for c, k in curves) / n,
                    "graph_recall": sum(c[i][1] * k for c, k in curves) / n,
                }
                for i, u in enumerate(THRESHOLDS)
            ],
        }
        if name == "learned":
            rows[name]["weights"] = learned
    return rows


def _probs_truth(scenes: Sequence[FusionScene], kind: str, method: str, w) -> tuple:
    p = [off_diagonal(method_probs(sc, kind, method, w)) for sc in scenes]
    y = [off_diagonal(sc.truth[kind]) for sc in scenes]
    return np.concatenate(p), np.concatenate(y).astype(float)


def cross_fit(scenes: Sequence[FusionScene], kind: str) -> dict[str, Any]:
    """Per method, out-of-fold pair probabilities and graph scores under `kind`; each fold's
    fusion weights and edge thresholds fitted on the other folds only."""
    folds = [list(scenes[f::FOLDS]) for f in range(FOLDS)]
    out: dict[str, Any] = {m: {"p": [], "y": [], "graph": [], "edge": []} for m in METHODS}
    weights = []
    for f, held in enumerate(folds):
        fit = [sc for g, part in enumerate(folds) if g != f for sc in part]
        chosen = choose_fusion(fit, kind)  # as the support stage chooses it on its val scenes
        w = np.array(chosen["weights"])
        weights.append(w)
        box_edge = choose_edge_threshold(fit, lambda sc: method_probs(sc, kind, "box_head"), kind)
        edge = {"box_head": box_edge, "physics_from_depth": chosen["physics_edge"]}
        edge["fused"] = chosen["edge"]
        for m in METHODS:
            prob = lambda sc, m=m, w=w: method_probs(sc, kind, m, w)  # noqa: E731
            t = edge[m]
            p, y = _probs_truth(held, kind, m, w)
            out[m]["p"].append(p)
            out[m]["y"].append(y)
            out[m]["edge"].append(t)
            out[m]["graph"].append((graph_scores(held, prob, kind, t), len(held)))
    rows = {}
    for m in METHODS:
        p, y = np.concatenate(out[m]["p"]), np.concatenate(out[m]["y"])
        s = binary_scores(p, y, 0.5)
        n = sum(k for _, k in out[m]["graph"])
        gp = sum(pr[0] * k for pr, k in out[m]["graph"]) / n
        gr = sum(pr[1] * k for pr, k in out[m]["graph"]) / n
        rows[m] = {
            "auroc": s["auroc"],
            "precision": s["precision"],
            "recall": s["recall"],
            "f1": s["f1"],
            "ece": s["ece"],
            "graph_precision": gp,
            "graph_recall": gr,
            "edge_thresholds": out[m]["edge"],
        }
    rows["fused"]["weights"] = [[round(float(v), 4) for v in w] for w in weights]
    return rows


def _val_scenes(params: Mapping[str, Any]):
    from clutterbench.config import load_section
    from clutterbench.criteria import label_thresholds
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.support.evaluate import split_scenes

    cfg = load_section(SupportEvalConfig, "support", params)
    sim = load_section(SimConfig, "sim", params)
    scenes = split_scenes(
        Path("data/generate"),
        Path(f"data/split/{cfg.val_dataset}.json"),
        "val",
        cfg.box_head.val_scenes,
        threshold_m=cfg.moved_threshold_m,
        min_pixels=cfg.min_pixels,
        camera=sim.camera,
        heads=EDGE_HEADS,
        collapse_free=label_thresholds(params),
    )
    return [sc for sc in scenes if len(sc.ids) > 1], cfg, sim


def recheck(params: Mapping[str, Any], out_dir: Path = OUT) -> dict[str, Any]:
    from clutterbench.collapse.box_predict import BoxMaps
    from clutterbench.config import load_section
    from clutterbench.criteria import label_thresholds
    from clutterbench.data.config import GenerateConfig
    from clutterbench.precision import inference_from_params
    from clutterbench.progress import progress_bar
    from clutterbench.trials.config import TrialsConfig

    started = time.perf_counter()
    inference_from_params(params)
    scenes, cfg, sim = _val_scenes(params)
    catalogue = load_section(GenerateConfig, "generate", params).datasets[cfg.val_dataset].catalogue
    cp, box = Path(f"models/{cfg.model}/best.pt"), Path("models/box_head/best.pt")
    maps = BoxMaps.from_paths(cp, box, sim.camera, "pull", 0.5)
    ch6 = load_section(TrialsConfig, "trials", params).ch6
    collapse_free = label_thresholds(params)
    by_fits = {}
    for fits in FITS:
        simulate = fitted_pulls(
            sim,
            dataclasses.replace(ch6, fit_hypotheses=fits),
            cfg.moved_threshold_m,
            collapse_free,
            catalogue,
            cfg.min_pixels,
        )
        answers = []
        with progress_bar(
            f"box_physics_fusion: val scenes, {fits} fit(s)", total=len(scenes)
        ) as advance:
            for sc in scenes:
                answers.append(answer_scene(sc, maps, simulate))
                advance(1)
        by_fits[fits] = {
            "pulls_simulated": int(sum(a.known.sum() for a in answers)),
            "kinds": {kind: cross_fit(answers, kind) for kind in EDGE_HEADS},
        }
        if fits == FITS[0]:
            touching = fitted_contacts(
                sim, dataclasses.replace(ch6, fit_hypotheses=fits), catalogue, cfg.min_pixels
            )
            with progress_bar("box_physics_fusion: fitted contacts", total=len(scenes)) as tick:
                for sc, a in zip(scenes, answers, strict=True):
                    a.fitted_contact = touching(sc.depth_m, sc.masks)
                    tick(1)
            contacts = {kind: contact_cross_fit(answers, kind) for kind in EDGE_HEADS}
    one, most = by_fits[FITS[0]]["kinds"]["pull"], by_fits[FITS[-1]]["kinds"]["pull"]
    result = {
        "val_scenes": len(answers),
        "pairs": int(sum(len(a.ids) * (len(a.ids) - 1) for a in answers)),
        "pulls": int(sum(len(a.ids) for a in answers)),
        "fit_noise_mm": ch6.fit_noise_mm,
        "fits": {str(k): v for k, v in by_fits.items()},
        "contacts": contacts,
        "shows": (
            f"box_physics_fusion (pull, support graph): box head "
            f"{one['box_head']['graph_precision']:.3f} / {one['box_head']['graph_recall']:.3f}, "
            f"fused on {FITS[0]} fit {one['fused']['graph_precision']:.3f} / "
            f"{one['fused']['graph_recall']:.3f}, on {FITS[-1]} fits "
            f"{most['fused']['graph_precision']:.3f} / {most['fused']['graph_recall']:.3f} "
            f"(mean precision / recall, val, cross-fitted); AUROC fused "
            f"{one['fused']['auroc']:.4f} -> {most['fused']['auroc']:.4f}; with the true contact "
            f"{contacts['pull']['truth']['graph_precision']:.3f} / "
            f"{contacts['pull']['truth']['graph_recall']:.3f}, with the learned contact "
            f"{contacts['pull']['learned']['graph_precision']:.3f} / "
            f"{contacts['pull']['learned']['graph_recall']:.3f}"
        ),
    }
    figure(result, out_dir / f"{NAME}.png")
    return save(result, started, out_dir, NAME, markdown)


def figure(result: Mapping[str, Any], path: Path) -> None:
    """The fused graph's mean precision against mean recall over every edge threshold (out
    of fold), one curve per contact and a panel per label kind; the best-F1 and the
    precision-first operating points marked, and the precision PRECISION_FIRST asks for."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from clutterbench.io import atomic_path

    kinds = list(result["contacts"])
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.2 * len(kinds), 4.6), squeeze=False)
    for ax, kind in zip(axes[0], kinds, strict=True):
        for name, r in result["contacts"][kind].items():
            curve = r["curve"]
            line = ax.plot(
                [c["graph_recall"] for c in curve],
                [c["graph_precision"] for c in curve],
                marker=".",
                label=name,
            )[0]
            pf = r["precision_first"]
            ax.plot(r["graph_recall"], r["graph_precision"], "o", color=line.get_color())
            ax.plot(pf["graph_recall"], pf["graph_precision"], "*", ms=12, color=line.get_color())
        ax.axhline(PRECISION_FIRST, color="0.5", lw=0.8, ls="--")
        ax.set(
            title=f"{kind}: the fused support graph on val (out of fold)",
            xlabel="mean recall",
            ylabel="mean precision",
            xlim=(0.6, 1.0),
            ylim=(0.75, 1.0),
        )
        ax.grid(alpha=0.3)
        ax.legend(title="contact", fontsize=8, loc="lower left")
    fig.text(
        0.01,
        0.01,
        "dots: edge thresholds 0.05-0.95; o: best F1 (the support stage's rule); "
        f"*: precision-first ({PRECISION_FIRST:g}, dashed)",
        fontsize=8,
    )
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, metadata={"Software": None})
    plt.close(fig)


def markdown(result: Mapping[str, Any]) -> str:
    fits = result["fits"]
    lines = [
        "# The box head and physics from depth, fused per box",
        "",
        f"`python -m experiments.box_physics_fusion` (module docstring: what each row is). "
        f"{result['val_scenes']} val scenes of the box_head stage, {result['pairs']} (pulled, "
        f"other) pairs, {result['pulls']} pulls; physics from depth simulated "
        + ", ".join(f"{v['pulls_simulated']} of them on {k} fit(s)" for k, v in fits.items())
        + " (the others: boxes the fit dropped, where the head answers). Fits after the first: "
        f"the depth image with {result['fit_noise_mm']:g} mm of noise. Cross-fitted over "
        f"{FOLDS} halves of the val scenes; never the test dataset. "
        f"{result['seconds'] / 60:.1f} min.",
        "",
        "| label kind | method | fits | AUROC | precision at 1/2 | recall at 1/2 | F1 | ECE | "
        "graph: mean precision | graph: mean recall | edge thresholds (per half) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    first = next(iter(fits))
    for kind in fits[first]["kinds"]:
        for m in METHODS:
            for k, v in fits.items():
                if m == "box_head" and k != first:
                    continue  # the head fits nothing
                r = v["kinds"][kind][m]
                lines.append(
                    f"| {kind} | {m} | {'—' if m == 'box_head' else k} | {r['auroc']:.4f} | "
                    f"{r['precision']:.3f} | {r['recall']:.3f} | {r['f1']:.3f} | {r['ece']:.3f} "
                    f"| {r['graph_precision']:.3f} | {r['graph_recall']:.3f} | "
                    f"{', '.join(f'{t:g}' for t in r['edge_thresholds'])} |"
                )
    lines += [
        "",
        "Fusion weights per half (head logit, simulated and marked, simulated and not, bias):",
    ]
    for k, v in fits.items():
        lines.append(
            f"- {k} fit(s): "
            + "; ".join(f"{kind}: {rows['fused']['weights']}" for kind, rows in v["kinds"].items())
        )
    lines += contact_lines(result["contacts"])
    learned = result["contacts"]["pull"]["learned"]["weights"]
    lines += [
        "",
        "Learned contact weights per half (head contact logit, fitted and touching, fitted and "
        f"not, bias): {learned}",
    ]
    lines += ["", result["shows"]]
    return "\n".join(lines) + "\n"


def contact_lines(contacts: Mapping[str, Any]) -> list[str]:
    """The markdown of the contacts' graphs: at the best F1, then at the precision-first
    operating point."""
    lines: list[str] = []
    lines += [
        "",
        f"## The edges' contact (fused, {FITS[0]} fit, cross-fitted)",
        "",
        "head: the box head's contact probability (the support stage's); fitted: the fitted "
        "scene's boxes touching once settled (the truth's rule), the head's where a box was not "
        "fitted; mean: of the two; learned: a logistic regression of the true contact on the "
        "head's contact logit and the fitted share of touching (fitted on the other half); "
        "truth: the true contact, a ceiling no robot has. Contact AUROC: the contact alone, per "
        "pair, out of fold.",
        "",
        "| label kind | contact | contact AUROC | graph: mean precision | graph: mean recall | "
        "edge thresholds (per half) |",
        "|---|---|---|---|---|---|",
    ]
    for kind, rows in contacts.items():
        for name, r in rows.items():
            lines.append(
                f"| {kind} | {name} | {r['contact_auroc']:.4f} | {r['graph_precision']:.3f} | "
                f"{r['graph_recall']:.3f} | {', '.join(f'{t:g}' for t in r['edge_thresholds'])} |"
            )
    lines += [
        "",
        f"### The precision-first operating point (precision {PRECISION_FIRST:g})",
        "",
        "The same fused graphs at another edge threshold: per half, the threshold of the "
        f"highest mean recall among those whose mean precision reaches {PRECISION_FIRST:g} on "
        "the other half (the highest precision where none does), scored on this half. Beside "
        "it, the threshold of the best F1 (the support stage's rule, the table above).",
        "",
        "| label kind | contact | best F1: precision / recall | precision-first: precision / "
        "recall | precision-first edge thresholds (per half) |",
        "|---|---|---|---|---|",
    ]
    for kind, rows in contacts.items():
        for name, r in rows.items():
            pf = r["precision_first"]
            lines.append(
                f"| {kind} | {name} | {r['graph_precision']:.3f} / {r['graph_recall']:.3f} | "
                f"{pf['graph_precision']:.3f} / {pf['graph_recall']:.3f} | "
                f"{', '.join(f'{t:g}' for t in pf['edge_thresholds'])} |"
            )
    return lines


if __name__ == "__main__":
    run_command(recheck, NAME)

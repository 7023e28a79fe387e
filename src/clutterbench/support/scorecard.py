"""Score a pull-consequence predictor on the test set (data/testset, stage testset): for every
visible box x of every scene, the predictor is given the depth image, the visible boxes'
masks, the camera and x, and answers for each visible box the probability that pulling x out
collapses it, or a pixel map (read per box: its mean over each box). The scorecard: per label
kind (what pulling x collapses, what it moves, what deleting it moves) precision, recall and
F1 at 1/2, AUROC, calibration (ECE, Brier), pixel IoU where a map was given, overall with 95%
bootstrap intervals over scenes, and per family and visible-box count. One JSON row per
predictor; the leaderboard is every row as one table."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.data.testset_load import LABEL_KINDS, labels, visible
from clutterbench.data.testset_sensed import IDEAL
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json, write_text
from clutterbench.progress import progress_bar
from clutterbench.support.box_train import auroc, binary_scores

PredictFn = Callable[[np.ndarray, np.ndarray, np.ndarray, int], np.ndarray]
"""(depth_m (H, W) float32, masks (K, H, W) bool of the visible boxes, camera K (3, 3), the
pulled box's position among them) -> (K,) probabilities (the pulled box's own ignored) or an
(H, W) probability map."""
THRESHOLD = 0.5
BOOTSTRAP = 1000
BOOTSTRAP_SEED = 0
HEADLINE = "pull_collapse"
"""The label kind a predictor is ranked by (what a planner needs: what the pull collapses)."""


def per_box(out: Any, masks: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(K,) probabilities from a predictor's answer, and the map when it gave one; one line
    when the answer is neither shape or not probabilities."""
    k, h, w = masks.shape
    try:
        a = np.asarray(out, dtype=np.float64)
    except (TypeError, ValueError):
        raise ClutterbenchError(f"predictor returned {type(out).__name__}, not numbers") from None
    if a.shape == (k,):
        probs, heat = a, None
    elif a.shape == (h, w):
        heat = a
        probs = np.array([a[m].mean() for m in masks])
    else:
        raise ClutterbenchError(
            f"predictor returned shape {a.shape}; expected ({k},) per box or ({h}, {w}) a map"
        )
    if not np.isfinite(probs).all() or (probs < 0).any() or (probs > 1).any():
        raise ClutterbenchError("predictor returned values outside [0, 1] (or NaN)")
    return probs, heat


def predict_all(ts: dict, predict: PredictFn, name: str) -> pd.DataFrame:
    """One row per (scene, pulled x, other y): the prediction and every label kind's truth,
    with the pixel IoU of the map (where given) against each kind's truth area."""
    truth = {kind: labels(ts, kind) for kind in LABEL_KINDS}
    cam = np.asarray(ts["manifest"]["camera"]["K"], dtype=np.float64)
    rows: list[dict[str, Any]] = []
    n = len(ts["n_objects"])
    with progress_bar(f"score {name}", total=n) as advance:
        for s in range(n):
            ids = visible(ts, s)
            if len(ids) >= 2:
                masks = np.stack([ts["instance"][s] == k + 1 for k in ids])
                for i, x in enumerate(ids):
                    answer = _answer(ts, predict, name, (s, i, x), masks, cam)
                    rows += _pair_rows(ts, s, ids, i, x, masks, answer, truth)
            advance(1)
    return pd.DataFrame(rows)


def _answer(ts, predict, name, where, masks, cam) -> tuple[np.ndarray, np.ndarray | None]:
    """The predictor's answer for pulling box x (position i among the masks) of scene s,
    read per box; whatever it raises or returns wrong is one line naming the scene and the
    box, so the user can replay that very call."""
    s, i, x = where
    try:
        return per_box(predict(ts["depth_m"][s].astype(np.float32), masks, cam, i), masks)
    except Exception as exc:  # noqa: BLE001 - the user's code: whatever it raised, one line
        if isinstance(exc, ClutterbenchError):
            what = str(exc).removeprefix("predictor ")
        else:
            what = f"raised {type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise ClutterbenchError(
            " ".join(
                f"predictor {name}, {scene_name(ts, s)}, pulled box {x} (pulled={i} of "
                f"{len(masks)} masks): {what}".split()
            )
        ) from exc


def scene_name(ts: dict, s: int) -> str:
    """'scene 212 (ch6_test scene 12)': a scene's index in the test set and where it comes
    from (its source and its index there), as an error names it."""
    named = "source" in ts and "scene_index" in ts
    src = f"{ts['source'][s]} scene {int(ts['scene_index'][s])}" if named else ""
    return f"scene {s}" + (f" ({src})" if src else "")


def _pair_rows(ts, s, ids, i, x, masks, answer, truth) -> list[dict[str, Any]]:
    probs, heat = answer
    base = {"scene": s, "family": str(ts["family"][s]), "visible": len(ids), "pulled": x}
    ious = {}
    if heat is not None:
        for kind, lab in truth.items():
            area = masks[lab[s, x, ids]].any(axis=0)
            pred = heat > THRESHOLD
            union = (area | pred).sum()
            ious[f"iou_{kind}"] = float((area & pred).sum() / union) if union else np.nan
    out = []
    for j, y in enumerate(ids):
        if j == i:
            continue
        row = base | {"other": y, "p": float(probs[j])}
        row |= {kind: bool(lab[s, x, y]) for kind, lab in truth.items()}
        out.append(row | (ious if j == (1 if i == 0 else 0) else {}))  # one IoU per pull
    return out


def _scores(rows: pd.DataFrame, kind: str) -> dict[str, float]:
    s = binary_scores(rows["p"].to_numpy(), rows[kind].to_numpy(), THRESHOLD)
    return {
        k: s[k] for k in ("precision", "recall", "f1", "auroc", "ece", "brier", "n", "positives")
    }


def _interval(rows: pd.DataFrame, kind: str, rng: np.random.Generator) -> dict[str, list]:
    """95% bootstrap intervals over scenes of AUROC, precision and recall (scenes drawn with
    replacement, each with all its pairs)."""
    order = np.argsort(rows["scene"].to_numpy(), kind="stable")
    p = rows["p"].to_numpy()[order]
    y = rows[kind].to_numpy().astype(bool)[order]
    _, starts = np.unique(rows["scene"].to_numpy()[order], return_index=True)
    sizes = np.diff(np.append(starts, len(p)))
    draws: dict[str, list[float]] = {"auroc": [], "precision": [], "recall": []}
    for _ in range(BOOTSTRAP):
        pick = rng.integers(0, len(starts), len(starts))
        idx = scene_rows(starts[pick], sizes[pick])
        pp, yy = p[idx], y[idx]
        pred = pp > THRESHOLD
        tp = int((pred & yy).sum())
        draws["auroc"].append(auroc(pp, yy))
        draws["precision"].append(tp / int(pred.sum()) if pred.any() else np.nan)
        draws["recall"].append(tp / int(yy.sum()) if yy.any() else np.nan)
    return {k: _percentiles(np.asarray(v, dtype=np.float64)) for k, v in draws.items()}


def scene_rows(first: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """The row indices of the drawn scenes, in draw order: first[k], first[k] + 1, ...,
    first[k] + sizes[k] - 1 for each draw k, concatenated."""
    offsets = np.cumsum(sizes) - sizes
    return np.arange(int(sizes.sum())) + np.repeat(first - offsets, sizes)


def _percentiles(v: np.ndarray) -> list[float | None]:
    """[2.5th, 97.5th] percentile of the defined draws (None: no draw defined it)."""
    v = v[np.isfinite(v)]
    if not len(v):
        return [None, None]
    return [round(float(np.percentile(v, 2.5)), 4), round(float(np.percentile(v, 97.5)), 4)]


def scorecard(rows: pd.DataFrame, name: str, about: str, manifest: dict) -> dict[str, Any]:
    """The predictor's JSON row: every label kind overall (with intervals), per family and per
    visible-box count, and the pixel IoU where it gave maps."""
    if rows.empty:
        raise ClutterbenchError("the test set holds no scene with two visible boxes")
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    card: dict[str, Any] = {
        "name": name,
        "about": about,
        "testset_sha256": manifest["sha256"],
        "scenes": int(rows["scene"].nunique()),
        "pairs": len(rows),
        "threshold": THRESHOLD,
    }
    if manifest.get("sensing"):
        card["sensing"] = manifest["sensing"]  # a sensed track's row (data/testset_sensed.py)
    groups = {
        **{f"family={f}": rows["family"] == f for f in sorted(rows["family"].unique())},
        "visible=2-5": rows["visible"] <= 5,
        "visible=6-10": rows["visible"] >= 6,
    }
    for kind in LABEL_KINDS:
        entry = _scores(rows, kind) | {"interval_95": _interval(rows, kind, rng)}
        entry["groups"] = {g: _scores(rows[sel], kind) for g, sel in groups.items() if sel.any()}
        if f"iou_{kind}" in rows:
            entry["pixel_iou"] = float(rows[f"iou_{kind}"].mean())
        card[kind] = _round(entry)
    return card


def _round(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _round(v) for k, v in obj.items()}
    if isinstance(obj, float):
        return None if not np.isfinite(obj) else round(obj, 4)
    return obj


def write_row(card: dict[str, Any], rows_dir: Path, stem: str | None = None) -> Path:
    """rows_dir/<stem or the card's name>.json."""
    path = rows_dir / f"{stem or card['name']}.json"
    write_json(path, card)
    return path


def leaderboard(
    rows_dir: Path,
    out: Path,
    testset_sha256: str | None,
    sensed: Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """out/leaderboard.{md,csv}: every predictor row under rows_dir's folders (baselines/, the
    stage's; submitted/, evaluate-predictor's; fresh/, evaluate-predictor --fresh's) scored on
    this test set (its hash; None: no test set, no published rows) or on fresh scenes, ranked
    by AUROC of what the pull collapses, each saying which set it was scored on; then, per
    sensed track (`sensed`: preset -> its sha256; and any fresh sensed row's), a section and
    out/leaderboard_<preset>.csv of the rows scored on it; then the planners' rows (agents/
    and fresh/, evaluate-agent's). Returns the ideal track's table."""
    cards = [read_json(p) for p in sorted(rows_dir.glob("*/*.json"))]
    agents = [c for c in cards if c.get("kind") == "agent"]
    tracks = track_cards([c for c in cards if c.get("kind") != "agent"], sensed or {})
    ideal = tracks.pop(IDEAL)
    published = [c for c in ideal if testset_sha256 and c.get("testset_sha256") == testset_sha256]
    cards = published + [c for c in ideal if is_fresh(c)]
    tracks = {t: c for t, c in tracks.items() if c}
    if not cards and not agents and not tracks:
        raise ClutterbenchError(f"{rows_dir}: no scorecard of this test set")
    lines = ["# Pull-consequence leaderboard", "", *TRUST_NOTE, ""]
    table = _ranked(cards)
    if cards:
        intro = _predictor_intro(published, testset_sha256)
        if tracks:
            intro[0] = "Ideal track (the renderer's exact depth). " + intro[0]
        lines += [*intro, "", *_markdown(table)]
    for track, rows in sorted(tracks.items()):
        lines += sensed_section(track, rows, (sensed or {}).get(track))
        write_text(out / f"leaderboard_{track}.csv", _ranked(rows).to_csv(index=False))
    lines += planner_section(agents)
    write_text(out / "leaderboard.md", "\n".join(lines) + "\n")
    write_text(out / "leaderboard.csv", table.to_csv(index=False))
    return table


def track_cards(cards: list[dict[str, Any]], sensed: Mapping[str, str]) -> dict[str, list]:
    """The predictor rows by track: IDEAL -> every row that names no sensor (filtered by the
    caller); each sensed preset -> its rows scored on that track (its sha256) or on fresh
    scenes sensed by it."""
    out: dict[str, list] = {IDEAL: [], **{t: [] for t in sensed}}
    for c in cards:
        track = c.get("sensing") or IDEAL
        if track == IDEAL:
            out[IDEAL].append(c)
        elif is_fresh(c) or c.get("testset_sha256") == sensed.get(track):
            out.setdefault(track, []).append(c)
    return out


def _ranked(cards: list[dict[str, Any]]) -> pd.DataFrame:
    table = pd.DataFrame([_board_row(c) for c in cards])
    if cards:
        table = table.sort_values(["pull_collapse AUROC", "predictor"], ascending=[False, True])
    return table


def sensed_section(track: str, rows: list[dict[str, Any]], sha: str | None) -> list[str]:
    """A sensed track's part of the leaderboard: what it is, then its rows ranked."""
    first = next((c for c in rows if not is_fresh(c)), None)
    size = f"{first['scenes']} scenes, {first['pairs']} (pulled, other) pairs; " if first else ""
    at = f"sha256 {sha[:12]}: " if sha else ""
    return [
        "",
        f"## Sensed track: {track}",
        "",
        f"The same scenes, masks and labels, each depth image through the {track} depth-sensor "
        f"model (docs/sensing.md; {at}{size}ranked and scored as above). "
        f"`clutterbench evaluate-predictor --track {track}` adds a row on it.",
        "",
        *_markdown(_ranked(rows)),
    ]


TRUST_NOTE = [
    "- **Published rows are on trust.** The published test set holds its own labels "
    "(data/published/testset), and the benchmark episodes' starts (data/benchmark) and the "
    "trials' outcomes are public too, so a predictor or planner could look them up: a number "
    "scored on them says how a row did on those scenes, not that it was blind to them.",
    "- **Fresh rows are the trusted ones.** `--fresh N` (evaluate-predictor, evaluate-agent) "
    "draws N new scenes or episodes from a seed drawn at scoring time, labels them there by "
    "simulation and scores on them; `scored on` names the seed, and `--seed S` reproduces "
    "the score (a row whose seed was chosen says `(--seed)`: whoever chose it could have "
    "labelled its scenes first).",
    "- **What the numbers are.** pull_collapse AUROC: how well a predictor's probabilities "
    "rank the boxes a pull collapses above the ones it leaves standing, over every (pulled, "
    "other) pair of the set; [95%]: a bootstrap over that set's scenes; precision and recall "
    f"at {THRESHOLD}; ECE: how far its probabilities are from the observed frequencies; "
    "pull_moved and deletion_moved AUROC: the same for what the pull moves and for what "
    "deleting the box moves (the thesis' labels). Planners: success per episode, "
    "collapse-free and strict, with Wilson 95% intervals.",
    "- **What they are not.** Simulated physics on this project's scene generator, not a "
    "real robot; two rows on different sets (published and fresh, or two seeds) differ by the "
    "scenes drawn as well, so compare them through their intervals; a fresh set's labels are "
    "the physics of the CPU that scored it.",
]
"""The leaderboard's header: what its numbers mean and what they do not (docs/
pull-consequence-testset.md says more)."""


def _predictor_intro(published: Sequence[dict[str, Any]], sha: str | None) -> list[str]:
    head = ""
    if published:
        head = (
            f"Test set sha256 {str(sha)[:12]}: {published[0]['scenes']} scenes, "
            f"{published[0]['pairs']} (pulled, other) pairs. "
        )
    return [
        head + "Ranked by AUROC of what the pull collapses; precision and recall at "
        f"{THRESHOLD}; [95% bootstrap over scenes]; `scored on` names the set. "
        "`clutterbench evaluate-predictor` adds a row on the published set, "
        "`clutterbench evaluate-predictor --fresh N` one on N fresh scenes."
    ]


def is_fresh(card: dict[str, Any]) -> bool:
    """A row scored on fresh scenes (`--fresh`): its card says so."""
    return (card.get("scored_on") or {}).get("set") == "fresh"


def scored_on_text(card: dict[str, Any]) -> str:
    """'published (sha b50dcdf6a723)' or 'fresh 200 scenes, seed 123' (with '(--seed)' when
    the seed was chosen, not drawn): which set a row was scored on."""
    on = card.get("scored_on") or {}
    if on.get("set") == "fresh":
        given = " (--seed)" if on.get("seed_from") == "given" else ""
        return f"fresh {on['scenes']} scenes, seed {on['seed']}{given}"
    sha = on.get("sha256") or card.get("testset_sha256") or card.get("benchmark_sha256")
    return f"published (sha {sha[:12]})" if sha else "published"


def _markdown(table: pd.DataFrame) -> list[str]:
    lines = [
        "| " + " | ".join(table.columns) + " |",
        "|" + "|".join("---" for _ in table.columns) + "|",
    ]
    for _, r in table.iterrows():
        lines.append("| " + " | ".join(_cell(v) for v in r) + " |")
    return lines


def _rate_cell(r: dict[str, Any]) -> str:
    lo, hi = r["interval_95"]
    return f"{r['k']}/{r['n']} = {100 * r['rate']:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"


def planner_section(agents: Sequence[dict[str, Any]]) -> list[str]:
    """The planners' part of the leaderboard: each agent's rates on its stream, then, per
    agent, its pairing with every trials condition on the same episodes."""
    lines = [
        "",
        "## Planners on the benchmark streams",
        "",
    ]
    if not agents:
        return [
            *lines,
            "No planner rows yet: `clutterbench evaluate-agent MODULE:FACTORY "
            "--leaderboard` adds one.",
        ]
    lines += [
        "Episodes of a trials stream (published: the same scenes and targets as Table 6.3) or "
        "fresh episodes of its kind, judged from physics; success per episode with [Wilson "
        "95%]. `clutterbench evaluate-agent --leaderboard` adds a row, with `--fresh N` one "
        "on N fresh episodes (paired with no planner: none ran them).",
        "",
    ]
    rows = [
        {
            "agent": a["name"],
            "scored on": scored_on_text(a),
            "stream": a["stream"],
            "episodes": f"{a['first_episode']}..{a['first_episode'] + a['episodes'] - 1}",
            "collapse-free success": _rate_cell(a["success"]),
            "strict success": _rate_cell(a["strict_success"]),
            "about": a.get("agent", ""),
        }
        for a in sorted(agents, key=lambda a: (a["stream"], -a["success"]["rate"], a["name"]))
    ]
    lines += _markdown(pd.DataFrame(rows))
    for a in sorted(agents, key=lambda a: a["name"]):
        paired = a["success_paired"]
        if not paired:
            continue
        lines += [
            "",
            f"### {a['name']} against each planner on the same episodes (collapse-free)",
            "",
        ]
        table = pd.DataFrame(
            [
                {
                    "planner [condition]": cond,
                    "episodes": p["episodes"],
                    "agent": p["agent_k"],
                    "planner": p["baseline_k"],
                    "won only by the agent": p["only_agent"],
                    "won only by the planner": p["only_baseline"],
                    "agent - planner (points)": f"{p['points']:+.1f}",
                    "McNemar p": f"{p['p']:.2g}",
                }
                for cond, p in paired.items()
            ]
        )
        lines += _markdown(table)
    return lines


def _board_row(card: dict[str, Any]) -> dict[str, Any]:
    pc = card[HEADLINE]
    lo, hi = pc["interval_95"]["auroc"]
    return {
        "predictor": card["name"],
        "scored on": scored_on_text(card),
        "pull_collapse AUROC": pc["auroc"],
        "[95%]": f"[{lo:.3f}, {hi:.3f}]" if lo is not None and hi is not None else "—",
        "precision": pc["precision"],
        "recall": pc["recall"],
        "ECE": pc["ece"],
        "pull_moved AUROC": card["pull_moved"]["auroc"],
        "deletion_moved AUROC": card["deletion_moved"]["auroc"],
        "about": card["about"],
    }


def _cell(v: Any) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—"
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def score(ts: dict, predict: PredictFn, name: str, about: str) -> dict[str, Any]:
    return scorecard(predict_all(ts, predict, name), name, about, ts["manifest"])


def check_name(name: str, taken: Sequence[str] = ()) -> str:
    if not name or not all(c.isalnum() or c in "-_." for c in name) or name.startswith("."):
        raise ClutterbenchError(f"predictor name {name!r}: letters, digits, '-', '_', '.' only")
    return name

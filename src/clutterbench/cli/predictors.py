"""`clutterbench evaluate-predictor`: score a pull-consequence predictor written anywhere on the
test set and add its row to the leaderboard; `clutterbench publish-testset`: commit a default
run's test set as the published one, so a fresh clone scores without running the pipeline.

Which test set: --testset; else data/testset where stage testset has written one (this
checkout's run, which the baselines in reports/leaderboard/baselines were scored on); else the
published copy in git, data/published/testset (the run that published it scored the committed
baselines on the same bytes). Their labels are public, so a score on them is on trust; with
--fresh N the predictor is scored on N scenes drawn from an unpublished seed and labelled now
(data/testset_fresh.py), the set written to data/fresh/<seed>/ and the row saying so.

Which track: --track (default ideal, the renderer's exact depth); a sensed track, e.g.
`--track d415`, is the same set with its depth images through that sensor model, written
beside it (data/testset_sensed/d415, data/testset_sensed.py); with --fresh the fresh set is sensed
likewise."""

from __future__ import annotations

import importlib
import importlib.util
import shutil
import tempfile
from pathlib import Path
from typing import Annotated

import typer

from clutterbench.cli.common import FreshSeed, app, default_path, project_params, user_errors
from clutterbench.errors import ClutterbenchError

TESTSET = "data/testset"
PUBLISHED = "data/published/testset"
TESTSET_FILES = ("scenes.npz", "manifest.json", "load_testset.py")
FRESH = "data/fresh"
"""Where `--fresh` writes each fresh set (FRESH/<seed>/, a test set like any other)."""


def testset_dir(given: Path | None) -> Path:
    """The test set to score on (module docstring): given, the run's own, or the published."""
    if given is not None:
        if not (given / "manifest.json").is_file():
            raise ClutterbenchError(f"{given}: no test set (no manifest.json)")
        return given
    for relative in (TESTSET, PUBLISHED):
        path = default_path(None, relative)
        if (path / "manifest.json").is_file():
            return path
    raise ClutterbenchError(
        f"no test set: neither {TESTSET} (dvc repro testset) nor the published {PUBLISHED}"
    )


def load_predict(spec: str):
    """MODULE[:FUNCTION] (a .py file or an importable module; FUNCTION defaults to predict)."""
    module_name, _, func = spec.partition(":")
    func = func or "predict"
    try:
        if module_name.endswith(".py"):
            path = Path(module_name)
            if not path.is_file():
                raise ClutterbenchError(f"{path}: no such file")
            loader_spec = importlib.util.spec_from_file_location(path.stem, path)
            assert loader_spec is not None and loader_spec.loader is not None
            module = importlib.util.module_from_spec(loader_spec)
            loader_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(module_name)
    except ClutterbenchError:
        raise
    except Exception as exc:  # noqa: BLE001 - the user's module: one line, whatever it raised
        raise ClutterbenchError(
            f"{module_name}: cannot import ({type(exc).__name__}: {exc})"
        ) from None
    predict = getattr(module, func, None)
    if not callable(predict):
        raise ClutterbenchError(
            f"{module_name} has no function {func}(depth_m, masks, camera_K, pulled)"
        )
    return predict, first_sentence(module.__doc__ or "")


def first_sentence(doc: str) -> str:
    """A module docstring's first sentence on one line: the leaderboard's "about" cell."""
    paragraph = " ".join(doc.strip().split("\n\n")[0].split())
    return paragraph.split(". ")[0].removesuffix(".") + "." if paragraph else ""


FreshScenes = Annotated[
    int | None,
    typer.Option(
        "--fresh",
        min=1,
        help="Score on N fresh scenes instead, drawn from an unpublished seed and labelled "
        "now by simulation: a score that cannot have read its labels.",
    ),
]
Track = Annotated[
    str,
    typer.Option(
        "--track",
        help="ideal (the renderer's exact depth) or a sensed track's sensor preset (e.g. "
        "d415): the same scenes and labels, the depth images through that sensor model.",
    ),
]
FreshDir = Annotated[
    Path | None,
    typer.Option("--fresh-dir", help=f"With --fresh: where its sets go (default {FRESH})."),
]


@app.command("evaluate-predictor")
def evaluate_predictor(
    predictor: Annotated[
        str,
        typer.Argument(
            metavar="MODULE[:FUNCTION]",
            help="FUNCTION(depth_m, masks, camera_K, pulled) -> per-box probabilities or a "
            "pixel map; MODULE: a .py file or an importable module (e.g. "
            "docs/examples/example_predictor.py).",
        ),
    ],
    name: Annotated[
        str | None, typer.Option("--name", help="Its row's name (default: the module's).")
    ] = None,
    testset: Annotated[
        Path | None,
        typer.Option(
            "--testset",
            help=f"Default: {TESTSET} where stage testset wrote one, else {PUBLISHED}. With "
            "--fresh: the set whose sources, thresholds and camera the fresh scenes follow.",
        ),
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", help="Default: reports/leaderboard.")] = None,
    fresh: FreshScenes = None,
    seed: FreshSeed = None,
    fresh_dir: FreshDir = None,
    track: Track = "ideal",
) -> None:
    """Score a predictor on every (scene, pulled box) of the test set's track (or of N fresh
    scenes), write its scorecard (OUT/submitted/NAME.json; fresh: OUT/fresh/predictor-NAME.json;
    a sensed track's: NAME@TRACK.json) and the leaderboard with it (OUT/leaderboard.md)."""
    with user_errors():
        from clutterbench.data.testset_sensed import IDEAL, sensed_tracks
        from clutterbench.support.scorecard import (
            check_name,
            leaderboard,
            score,
            scored_on_text,
            write_row,
        )

        if seed is not None and fresh is None:
            raise ClutterbenchError("--seed: only with --fresh N")
        check_track(track)
        ts_dir = testset_dir(testset)
        reference = load_testset(ts_dir)
        if reference["manifest"].get("sensing"):
            raise ClutterbenchError(
                f"{ts_dir}: a sensed track; --testset names the ideal set, --track "
                f"{reference['manifest']['sensing']} the track beside it"
            )
        ts = reference if track == IDEAL or fresh is not None else track_set(ts_dir, track)
        predict, about = load_predict(predictor)  # before any labelling: a broken module fails now
        label = check_name(name or Path(predictor.partition(":")[0]).stem.split(".")[-1])
        board = default_path(out, "reports/leaderboard")
        scored_on = None
        if fresh is not None:
            ts, scored_on = fresh_set(ts_dir, fresh, seed, default_path(fresh_dir, FRESH), track)
        try:
            card = score(ts, predict, label, about)
        except ClutterbenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - the predictor's own error, in one line
            raise ClutterbenchError(
                f"predictor {label} raised {type(exc).__name__}: {exc}"
            ) from None
        stem = label if track == IDEAL else f"{label}@{track}"
        if scored_on is not None:
            card["scored_on"] = scored_on
            path = write_row(card, board / "fresh", f"predictor-{stem}")
        else:
            path = write_row(card, board / "submitted", stem)
        leaderboard(board, board, reference["manifest"]["sha256"], sensed_tracks(ts_dir))
        pc = card["pull_collapse"]
        typer.echo(
            f"{label} ({scored_on_text(card)}): pull_collapse AUROC {pc['auroc']} "
            f"precision {pc['precision']} recall {pc['recall']} ({card['pairs']} pairs) "
            f"-> {path}, {board / 'leaderboard.md'}"
        )


def load_testset(ts_dir: Path) -> dict:
    """A test set loaded (hash, schema) with its manifest's pins checked, each problem one
    line."""
    from clutterbench.data.testset_load import load
    from clutterbench.data.testset_pins import check_pins

    try:
        check_pins(ts_dir)
        return load(ts_dir)
    except (ValueError, OSError) as exc:
        raise ClutterbenchError(f"{ts_dir}: {exc}") from None


def check_track(track: str) -> str:
    """--track: ideal or a sensor preset (sim/sensor.py PRESETS), else one line."""
    from clutterbench.sim.sensor import PRESETS

    if track not in PRESETS:
        raise ClutterbenchError(f"--track {track}: one of {', '.join(PRESETS)}")
    return track


def track_set(ts_dir: Path, track: str) -> dict:
    """The test set's `track` loaded: ts_dir itself (ideal) or the sensed track beside it."""
    from clutterbench.data.testset_sensed import IDEAL, track_dir

    path = track_dir(ts_dir, check_track(track))
    if not (path / "manifest.json").is_file():
        raise ClutterbenchError(
            f"--track {track}: no such track beside {ts_dir} ({path}; stage testset writes "
            "the sensed track of support.sensing's first sensor)"
        )
    ts = load_testset(path)
    if (ts["manifest"].get("sensing") or IDEAL) != track:
        raise ClutterbenchError(f"{path}: its manifest says it is not the {track} track")
    return ts


def fresh_set(
    reference: Path, n: int, seed: int | None, root: Path, track: str = "ideal"
) -> tuple[dict, dict]:
    """N fresh scenes labelled now (support/testset_fresh.py) in root/<seed>/ (a sensed
    track: sensed too, into root/<seed>_<track>/) -> (the set, the card's `scored_on`); the
    seed is printed before the labelling starts."""
    from clutterbench.config import load_base, load_section
    from clutterbench.data.testset_fresh import draw_seed
    from clutterbench.data.testset_sensed import IDEAL, export_sensed, track_dir
    from clutterbench.platform_info import cpu_model
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.testset_fresh import fresh_testset
    from clutterbench.trials.config import TrialsConfig

    params = project_params()
    if not params:
        raise ClutterbenchError("--fresh: no params.yaml in this project to draw scenes with")
    seed, seed_from = draw_seed(seed)
    out = root / str(seed)
    typer.echo(f"fresh: {n} scenes, seed {seed} ({seed_from}) -> {out}")
    trials = load_section(TrialsConfig, "trials", params)
    manifest = fresh_testset(params, trials, reference, n, seed, out, load_base(params).cores)
    if track != IDEAL:
        manifest = export_sensed(out, track, load_section(SimConfig, "sim", params).camera)
        out = track_dir(out, track)
    scored_on = {
        "set": "fresh",
        "scenes": n,
        "seed": seed,
        "seed_from": seed_from,
        "stream_seed": manifest["fresh"]["stream_seed"],
        "sha256": manifest["sha256"],
        "reference_sha256": manifest["fresh"]["reference_sha256"],
        "cpu_model": cpu_model(),  # the labels are this CPU's physics
    }
    return load_testset(out), scored_on


@app.command("publish-testset")
def publish_testset(
    testset: Annotated[Path | None, typer.Option("--testset", help=f"Default: {TESTSET}.")] = None,
    to: Annotated[Path | None, typer.Option("--to", help=f"Default: {PUBLISHED}.")] = None,
) -> None:
    """Copy a run's test set (stage testset, default scale) and its sensed tracks beside it
    (data/testset_sensed/<preset>) to the published copy that git keeps (data/published/testset,
    testset_sensed/<preset>), after checking each loads (hash and schema); the copy replaces the old
    one whole, a published sensed track the run has not dropped."""
    with user_errors():
        from clutterbench.data.testset_sensed import IDEAL, sensed_tracks, track_dir

        src = default_path(testset, TESTSET)
        dst = default_path(to, PUBLISHED)
        tracks = [IDEAL, *sensed_tracks(src)] if (src / "manifest.json").is_file() else [IDEAL]
        shas = {t: checked_sha(track_dir(src, t)) for t in tracks}  # all load, or none is copied
        for track in [*sensed_tracks(dst)] if (dst / "manifest.json").is_file() else []:
            if track not in shas:
                shutil.rmtree(track_dir(dst, track))  # of an older set: not this one's track
        for track, sha in shas.items():
            replace_whole(track_dir(src, track), track_dir(dst, track))
            what = "test set" if track == IDEAL else f"test set's {track} track"
            typer.echo(
                f"{track_dir(dst, track)}: the published {what} is now sha256 {sha[:12]} "
                f"(from {track_dir(src, track)})"
            )


def checked_sha(src: Path) -> str:
    """The sha256 of a test set that has its files and loads (hash and schema), else one
    line."""
    from clutterbench.data.testset_load import load

    missing = [f for f in TESTSET_FILES if not (src / f).is_file()]
    if missing:
        raise ClutterbenchError(f"{src}: no test set ({', '.join(missing)} missing)")
    try:
        return load(src)["manifest"]["sha256"]
    except (ValueError, OSError) as exc:
        raise ClutterbenchError(f"{src}: {exc}") from None


def replace_whole(src: Path, dst: Path) -> None:
    """dst becomes a copy of the test set in src, its manifest pinning every file of it."""
    from clutterbench.data.testset_pins import pin_files

    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".publish-", dir=dst.parent))
    for name in TESTSET_FILES:
        shutil.copy2(src / name, tmp / name)
    pin_files(tmp)  # the published manifest pins every file of the set, its loader included
    old = dst.with_name(dst.name + ".old")
    if dst.exists():
        dst.rename(old)
    tmp.rename(dst)
    shutil.rmtree(old, ignore_errors=True)

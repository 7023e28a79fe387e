"""`clutterbench evaluate-predictor`: score a pull-consequence predictor written anywhere on the
test set and add its row to the leaderboard; `clutterbench publish-testset`: commit a default
run's test set as the published one, so a fresh clone scores without running the pipeline.

Which test set: --testset; else data/testset where stage testset has written one (this
checkout's run, which the baselines in reports/leaderboard/baselines were scored on); else the
published copy in git, data/published/testset (the run that published it scored the committed
baselines on the same bytes). Their labels are public, so a score on them is on trust; with
--fresh N the predictor is scored on N scenes drawn from an unpublished seed and labelled now
(data/testset_fresh.py), the set written to data/fresh/<seed>/ and the row saying so."""

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
) -> None:
    """Score a predictor on every (scene, pulled box) of the test set (or of N fresh scenes),
    write its scorecard (OUT/submitted/NAME.json; fresh: OUT/fresh/predictor-NAME.json) and the
    leaderboard with it (OUT/leaderboard.md)."""
    with user_errors():
        from clutterbench.support.scorecard import (
            check_name,
            leaderboard,
            score,
            scored_on_text,
            write_row,
        )

        if seed is not None and fresh is None:
            raise ClutterbenchError("--seed: only with --fresh N")
        ts_dir = testset_dir(testset)
        reference = load_testset(ts_dir)
        predict, about = load_predict(predictor)  # before any labelling: a broken module fails now
        label = check_name(name or Path(predictor.partition(":")[0]).stem.split(".")[-1])
        board = default_path(out, "reports/leaderboard")
        ts, scored_on = reference, None
        if fresh is not None:
            ts, scored_on = fresh_set(ts_dir, fresh, seed, default_path(fresh_dir, FRESH))
        try:
            card = score(ts, predict, label, about)
        except ClutterbenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - the predictor's own error, in one line
            raise ClutterbenchError(
                f"predictor {label} raised {type(exc).__name__}: {exc}"
            ) from None
        if scored_on is not None:
            card["scored_on"] = scored_on
            path = write_row(card, board / "fresh", f"predictor-{label}")
        else:
            path = write_row(card, board / "submitted")
        leaderboard(board, board, reference["manifest"]["sha256"])
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


def fresh_set(reference: Path, n: int, seed: int | None, root: Path) -> tuple[dict, dict]:
    """N fresh scenes labelled now (support/testset_fresh.py) in root/<seed>/ -> (the set, the
    card's `scored_on`); the seed is printed before the labelling starts."""
    from clutterbench.config import load_base, load_section
    from clutterbench.data.testset_fresh import draw_seed
    from clutterbench.platform_info import cpu_model
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
    """Copy a run's test set (stage testset, default scale) to the published copy that git
    keeps, after checking it loads (hash and schema); the copy replaces the old one whole."""
    with user_errors():
        from clutterbench.data.testset_load import load
        from clutterbench.data.testset_pins import pin_files

        src = default_path(testset, TESTSET)
        dst = default_path(to, PUBLISHED)
        missing = [f for f in TESTSET_FILES if not (src / f).is_file()]
        if missing:
            raise ClutterbenchError(f"{src}: no test set ({', '.join(missing)} missing)")
        try:
            sha = load(src)["manifest"]["sha256"]
        except (ValueError, OSError) as exc:
            raise ClutterbenchError(f"{src}: {exc}") from None
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
        typer.echo(f"{dst}: the published test set is now sha256 {sha[:12]} (from {src})")

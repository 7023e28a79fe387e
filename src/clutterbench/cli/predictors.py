"""`clutterbench evaluate-predictor`: score a pull-consequence predictor written anywhere on the
test set (data/testset, stage testset) and add its row to the leaderboard."""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path
from typing import Annotated

import typer

from clutterbench.cli.common import app, default_path, user_errors
from clutterbench.errors import ClutterbenchError


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
    lines = (module.__doc__ or "").strip().splitlines()
    return predict, lines[0] if lines else ""


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
        Path | None, typer.Option("--testset", help="Default: data/testset.")
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", help="Default: reports/leaderboard.")] = None,
) -> None:
    """Score a predictor on every (scene, pulled box) of the test set, write its scorecard
    (OUT/submitted/NAME.json) and the leaderboard with it (OUT/leaderboard.md)."""
    with user_errors():
        from clutterbench.data.testset_load import load
        from clutterbench.support.scorecard import check_name, leaderboard, score, write_row

        ts_dir = default_path(testset, "data/testset")
        if not (ts_dir / "manifest.json").is_file():
            raise ClutterbenchError(f"{ts_dir}: no test set (run: dvc repro testset)")
        try:
            ts = load(ts_dir)
        except (ValueError, OSError) as exc:
            raise ClutterbenchError(f"{ts_dir}: {exc}") from None
        predict, about = load_predict(predictor)
        label = check_name(name or Path(predictor.partition(":")[0]).stem.split(".")[-1])
        board = default_path(out, "reports/leaderboard")
        try:
            card = score(ts, predict, label, about)
        except ClutterbenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - the predictor's own error, in one line
            raise ClutterbenchError(
                f"predictor {label} raised {type(exc).__name__}: {exc}"
            ) from None
        path = write_row(card, board / "submitted")
        leaderboard(board, board, ts["manifest"]["sha256"])
        pc = card["pull_collapse"]
        typer.echo(
            f"{label}: pull_collapse AUROC {pc['auroc']} precision {pc['precision']} recall "
            f"{pc['recall']} ({card['pairs']} pairs) -> {path}, {board / 'leaderboard.md'}"
        )

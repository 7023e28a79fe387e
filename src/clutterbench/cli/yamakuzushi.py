"""`clutterbench yamakuzushi` and `yamakuzushi-validate`: the ch. 3 game and its checks."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from clutterbench.cli.common import (
    app,
    check_out_file,
    default_path,
    project_params,
    require_file,
    user_errors,
)
from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    pass


@app.command("yamakuzushi")
def yamakuzushi(
    seed: Annotated[int, typer.Option("--seed", metavar="N", help="The pile's seed.")] = 0,
    variant: Annotated[
        str,
        typer.Option("--variant", help="convnet | no_convnet | convnet_no_pomdp | random | oracle"),
    ] = "convnet",
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Slide ConvNet (default: models/slide_convnet/best.pt)."),
    ] = None,
    mcap: Annotated[
        Path | None, typer.Option("--mcap", help="Write the game as MCAP (Foxglove).")
    ] = None,
) -> None:
    """Play one Yamakuzushi game (thesis ch. 3) on the pile of --seed: print each slide (the
    piece, direction, ConvNet probability, sensor moves, outcome judged from physics) and how
    the game ended, as JSON lines. Params: `yamakuzushi` of the project's params.yaml."""
    with user_errors():
        from clutterbench.config import load_section
        from clutterbench.criteria import CollapseFreeConfig
        from clutterbench.parallel import worker_init
        from clutterbench.trials.ch3.config import VARIANTS, Ch3Config
        from clutterbench.trials.ch3.games import Ch3Job, run_ch3_game
        from clutterbench.trials.core.harness import write_mcap

        if variant not in VARIANTS:
            raise ClutterbenchError(f"--variant {variant!r}: not one of {', '.join(VARIANTS)}")
        params = project_params()
        cfg = load_section(Ch3Config, "yamakuzushi", params) if params else Ch3Config()
        collapse_free = (
            load_section(CollapseFreeConfig, "trials.collapse_free", params)
            if params
            else CollapseFreeConfig()
        )
        path = None
        if variant in ("convnet", "convnet_no_pomdp"):
            path = require_file(
                default_path(model, "models/slide_convnet/best.pt"),
                "--model",
                "dvc repro train_slide",
            )
        if mcap is not None:
            check_out_file(mcap, "--mcap", "game.mcap")
        worker_init(1)
        job = Ch3Job(
            condition=variant,
            index=0,
            seed=seed,
            cfg=cfg,
            model=None if path is None else str(path),
            record_images=mcap is not None,
            collapse_free=collapse_free,
        )
        result = run_ch3_game(job)
        for step in result.record["steps"]:
            typer.echo(json.dumps(step))
        head = {k: v for k, v in result.record.items() if k != "steps"}
        typer.echo(json.dumps(head))
        if mcap is not None:
            write_mcap(mcap, [result], {"condition": variant, "seed": str(seed)})


@app.command("yamakuzushi-validate")
def yamakuzushi_validate(
    min_probability: Annotated[
        list[float],
        typer.Option(
            "--min-probability",
            help="A value of yamakuzushi.select.min_probability to play (repeat the option).",
        ),
    ],
    games: Annotated[int, typer.Option("--games", min=1, help="Games per value.")] = 40,
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Slide ConvNet (default: models/slide_convnet/best.pt)."),
    ] = None,
) -> None:
    """Choose `yamakuzushi.select.min_probability` on validation piles (seed stream ch3_val,
    never the games' piles): play --games games with the ConvNet for each value and print
    pieces per game and per-slide success per value, then the value with the most pieces per
    game among those whose per-slide success is at least 90% with 95% confidence (the lower
    end of its interval, a bootstrap over games as in Fig. 3.15's table: the rule the params'
    value comes from)."""
    with user_errors():
        import dataclasses

        from clutterbench.config import BaseConfig, load_section
        from clutterbench.data.slides import pile_seed
        from clutterbench.trials.ch3.config import Ch3Config
        from clutterbench.trials.ch3.games import ch3_jobs, run_ch3_game
        from clutterbench.trials.core.harness import run_episodes
        from clutterbench.trials.core.stats import aggregate_games

        for p in min_probability:
            if not 0.0 <= p <= 1.0:
                raise ClutterbenchError(f"--min-probability {p}: not within [0, 1]")
        params = project_params()
        cfg = load_section(Ch3Config, "yamakuzushi", params) if params else Ch3Config()
        seed = load_section(BaseConfig, "base", params).seed if params else BaseConfig().seed
        path = require_file(
            default_path(model, "models/slide_convnet/best.pt"), "--model", "dvc repro train_slide"
        )
        games_cfg = dataclasses.replace(
            cfg.games, n_games=games, variants=("convnet",), mcap_images=False
        )
        jobs = []
        for p in min_probability:
            select = dataclasses.replace(cfg.select, min_probability=p)
            run = dataclasses.replace(cfg, games=games_cfg, select=select)
            jobs += ch3_jobs(
                cfg=run, seed_of=lambda g: pile_seed(seed, "ch3_val", g), model=str(path)
            )
        results = run_episodes("validation games", run_ch3_game, jobs, cfg.games.workers)
        records = [
            r.record | {"condition": f"{job.cfg.select.min_probability:g}"}
            for r, job in zip(results, jobs, strict=True)
        ]
        summary = aggregate_games(records)
        best = None
        for row in summary.itertuples():
            rate = row.step_success_k / row.step_success_n if row.step_success_n else 0.0
            typer.echo(
                f"min_probability {row.condition}: {row.mean_pieces:.2f} pieces per game, "
                f"per slide {row.step_success_k}/{row.step_success_n} = {rate:.1%} "
                f"[{row.step_success_lo:.1%}, {row.step_success_hi:.1%}], ends: {row.ends}"
            )
            if row.step_success_lo >= 0.9 and (best is None or row.mean_pieces > best[1]):
                best = (row.condition, row.mean_pieces)
        if best is None:
            typer.echo("no value is at >= 90% per slide with 95% confidence on these games")
        else:
            typer.echo(
                f"choice: min_probability {best[0]} (most pieces per game at >= 90% per slide, "
                "interval's lower end)"
            )

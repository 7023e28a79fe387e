"""`clutterbench evaluate-agent`: any gymnasium policy through ClutterShelfPlan-v1 on a stream's
episodes, written as the trials' records."""

from __future__ import annotations

import sys
import traceback
from pathlib import Path
from typing import Annotated

import typer

from clutterbench.cli.common import FreshSeed, app, default_path, user_errors
from clutterbench.errors import ClutterbenchError

FreshEpisodes = Annotated[
    int | None,
    typer.Option(
        "--fresh",
        min=1,
        help="Run N fresh episodes instead (0..N-1 of an unpublished stream of the stream's "
        "kind, drawn from a new seed): a score no lookup of the published episodes can have "
        "made. Replaces --episodes and --first.",
    ),
]


@app.command("evaluate-agent")
def evaluate_agent(
    agent: Annotated[
        str,
        typer.Argument(
            metavar="MODULE:FACTORY",
            help="FACTORY(env) -> a policy (obs -> action, or .act(obs)); MODULE: an importable "
            "module or a .py file (e.g. docs/examples/random_agent.py:make_agent).",
        ),
    ],
    stream: Annotated[
        str, typer.Option("--stream", help="Scene stream (a key of trials.streams).")
    ] = "ch6_3_10",
    episodes: Annotated[int, typer.Option("--episodes", min=1, help="Episodes 0..N-1.")] = 20,
    first: Annotated[int, typer.Option("--first", min=0, help="First episode index.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Output root (default: reports/agents): OUT/NAME/records.jsonl"),
    ] = None,
    name: Annotated[
        str | None, typer.Option("--name", help="Condition name (default: FACTORY).")
    ] = None,
    scale: Annotated[
        str | None, typer.Option("--scale", help="Scale profile (default: base.scale).")
    ] = None,
    board: Annotated[
        bool,
        typer.Option(
            "--leaderboard",
            help="Also add the agent's row, paired with the trials' planners on the same "
            "episodes, to reports/leaderboard/ (agents/NAME.json, leaderboard.md).",
        ),
    ] = False,
    show_traceback: Annotated[
        bool,
        typer.Option("--traceback", help="When the agent raises: its whole trace, then the line."),
    ] = False,
    fresh: FreshEpisodes = None,
    seed: FreshSeed = None,
) -> None:
    """Run an agent through ClutterShelfPlan-v1 on episodes of a stream (the trials' scenes
    and targets, the episode protocol, judged from physics) and write the trials' records,
    summary (both success criteria) and MCAP; print the summary's headline. The published
    episodes' starts and the trials' outcomes are public, so a score on them is on trust;
    --fresh N scores on N episodes drawn from an unpublished seed (printed and recorded)."""
    with user_errors():
        from clutterbench.envs.evaluate import AgentError
        from clutterbench.envs.evaluate import evaluate_agent as run

        out_dir = default_path(out, "reports/agents")
        if out_dir.exists() and not out_dir.is_dir():
            raise ClutterbenchError(f"--out {out_dir}: is a file, not a directory")
        drawn = fresh_seed(fresh, seed, stream)
        if fresh is not None:
            episodes, first = fresh, 0
        try:
            summary = run(
                agent,
                stream,
                episodes,
                out_dir,
                name=name,
                first=first,
                scale=scale,
                board=default_path(None, "reports/leaderboard") if board else None,
                fresh=drawn,
            )
        except AgentError as exc:
            if show_traceback and exc.__cause__ is not None:
                traceback.print_exception(exc.__cause__, file=sys.stderr)
            raise
        cond = summary["condition"]
        typer.echo(
            f"{cond} on {summary['stream']} ({summary['episodes']} episodes): "
            f"success (collapse-free) {summary['success_k']}/{summary['success_n']}, "
            f"strict {summary['strict_success_k']}/{summary['strict_success_n']}; "
            f"wrote {out_dir / cond}/records.jsonl, summary.json"
            + (f", {summary['leaderboard_row']}" if "leaderboard_row" in summary else "")
        )


def fresh_seed(fresh: int | None, seed: int | None, stream: str) -> tuple[int, str] | None:
    """(seed, where it came from) of a --fresh run, printed before any episode runs; None
    without --fresh."""
    from clutterbench.data.testset_fresh import draw_seed

    if fresh is None:
        if seed is not None:
            raise ClutterbenchError("--seed: only with --fresh N")
        return None
    drawn = draw_seed(seed)
    typer.echo(f"fresh: {fresh} episodes of {stream}'s kind, seed {drawn[0]} ({drawn[1]})")
    return drawn

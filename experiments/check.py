"""`python -m experiments.check [PARAMS]`: experiments/params.yaml checked as `clutterbench
check` checks params.yaml (every scale profile, no data), together with the project's params
(PARAMS, default params.yaml): the dev streams, and the planners, streams and model each
recheck names. One line per problem and exit 2, or one line `ok`."""

from __future__ import annotations

import sys
import typing
from pathlib import Path

import yaml

from clutterbench.cli.check import (
    Resolved,
    _at,
    _entries,
    _keys,
    _list,
    _model_ref,
    _ref,
    ch6_planners,
    check_params,
    unknown_name,
)
from clutterbench.config import SCALES
from clutterbench.trials.config import DEV_PREFIX
from experiments.config import PARAMS, Ch6PullConfig, DevConfig


def check_dev(p: Resolved) -> list[str]:
    planners, _ = ch6_planners(p)
    streams = _keys(p, "dev.streams")
    out = [
        f"dev.streams.{s}: a dev stream's name starts with '{DEV_PREFIX}'"
        for s in streams
        if not s.startswith(DEV_PREFIX)
    ]
    types = typing.get_type_hints(DevConfig)
    for check, cfg in _entries(p, "dev").items():
        if check == "streams":
            continue
        for stream in _list(cfg.get("streams")):
            out += _ref(p, f"dev.{check}.streams", stream, "dev.streams", "stream")
        if types.get(check) is Ch6PullConfig:  # a ch. 6 recheck runs trial planners
            for planner in _list(cfg.get("planners")):
                out += unknown_name(f"dev.{check}.planners", planner, planners, "planner")
    out += _model_ref(p, "dev.ch4_piles.model", _at(p, "dev.ch4_piles.model"))
    return out + _model_ref(p, "dev.ch4_sensing.model", _at(p, "dev.ch4_sensing.model"))


def check_experiments(params: Path = Path("params.yaml"), dev: Path = PARAMS) -> list[str]:
    """Every problem of `dev`'s section `dev` beside the project's params file `params`."""
    raw = yaml.safe_load(dev.read_text()) or {}
    if set(raw) != {"dev"}:
        return [f"{dev}: holds one section, dev (found: {', '.join(map(str, raw)) or 'none'})"]
    return check_params(params, {"dev": (DevConfig, check_dev)}, {"dev": raw["dev"]})


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    params = Path(args[0]) if args else Path("params.yaml")
    problems = check_experiments(params)
    for line in problems:
        print(f"error: {line}", file=sys.stderr)
    if problems:
        return 2
    print(f"ok: experiments/params.yaml beside {params} (scales {', '.join(SCALES)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

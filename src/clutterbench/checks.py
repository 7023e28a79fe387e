"""params.yaml checked for every problem at once (`clutterbench check`), where config.parse
stops at the first: the same coercions, ranges and one-line messages, collected.

A module of its own, not part of config.py: every stage depends on config.py (dvc.yaml), so
an edit there reruns the whole pipeline, and no stage imports this one.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import re
import typing
from collections.abc import Iterable, Mapping
from typing import Any, get_args, get_origin

# config's own field coercion and range check (module-private there), so that a value the
# check passes is one that parse takes, message for message
from clutterbench.config import SCALES, _check_range, _coerce, parse, resolve_cores
from clutterbench.errors import ClutterbenchError


@dataclasses.dataclass(frozen=True)
class BenchmarkParams:
    """params.yaml `benchmark`: its readers (sim/benchmark.py, `clutterbench benchmark-scenes`)
    take it as a plain mapping, so its schema, for the check, is here."""

    manifest_sha256: str | None = None
    """sha256 of data/benchmark/manifest.json (null: every start drawn live)."""

    def __post_init__(self) -> None:
        digest = self.manifest_sha256
        if digest is not None and not re.fullmatch(r"[0-9a-f]{64}", digest):
            raise ValueError(f"manifest_sha256: {digest!r} is not a sha256 (64 hex digits) or null")


def unknown_name(
    key: str, value: Any, known: Iterable[str], what: str, where: str = ""
) -> list[str]:
    """[one line naming `key`] when `value` names no entry of `known` (the keys of params
    `where`, e.g. a condition's stream), with the likeliest meant one; [] when it does."""
    known = [str(k) for k in known]
    if not isinstance(value, str) or value in known:
        return []
    close = difflib.get_close_matches(value, known, n=1)
    hint = f"did you mean '{close[0]}'?" if close else f"known: {', '.join(known) or 'none'}"
    where = f"not in {where}; " if where else ""
    return [f"{key}: unknown {what} '{value}' ({where}{hint})"]


def resolve_scale_collecting(value: Any, scale: str, key: str, problems: list[str]) -> Any:
    """config.resolve_scale that appends each missing scale entry's one-line problem to
    `problems` instead of raising, and goes on with the `default` entry there, so that what
    lies below it is checked too."""
    if isinstance(value, Mapping):
        keys = set(value)
        if keys and keys <= set(SCALES) and "default" in keys:
            if scale not in value:
                problems.append(f"{key}: no value for scale '{scale}'")
            chosen = value.get(scale, value["default"])
            return resolve_scale_collecting(chosen, scale, key, problems)
        return {
            k: resolve_scale_collecting(v, scale, f"{key}.{k}", problems) for k, v in value.items()
        }
    if isinstance(value, list):
        return [
            resolve_scale_collecting(v, scale, f"{key}[{i}]", problems) for i, v in enumerate(value)
        ]
    return value


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    # a config class's annotations never change; evaluating them is most of a check's time
    return typing.get_type_hints(cls)


def parse_problems(
    cls: type, data: Any, key: str, cores: int | None = None, construct: bool = True
) -> list[str]:
    """Every problem config.parse would stop at the first of, one line each: each unknown
    key, each missing or bad field, and below it every nested dataclass and every entry of a
    mapping of dataclasses (a dataset, a condition) checked on its own. Only when the fields
    hold does it parse the whole (`construct`), so that its __post_init__ checks across its
    fields run as a stage meets them; a caller that checks those itself passes False."""
    if not isinstance(data, Mapping):
        return [f"{key}: expected a mapping, got {type(data).__name__}"]
    prepare = getattr(cls, "prepare_params", None)
    if prepare is not None:  # as config.parse: a section's defaults of its entries
        data = prepare(data)
    hints = _type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    allowed = ", ".join(fields)
    problems = [
        f"{key}.{k}: unknown key (allowed: {allowed})"
        for k in sorted(set(data) - set(fields), key=str)
    ]
    for name, f in fields.items():
        sub = f"{key}.{name}"
        if name in data:
            problems += _field_problems(f, hints[name], data[name], sub, cores)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            problems.append(f"{sub}: missing required key")
    # a class without __post_init__ checks nothing its fields' checks above did not
    if construct and not problems and hasattr(cls, "__post_init__"):
        try:
            parse(cls, data, key, cores)
        except ClutterbenchError as exc:
            problems.append(str(exc))
    return problems


def _field_problems(
    f: dataclasses.Field, tp: Any, value: Any, key: str, cores: int | None
) -> list[str]:
    if dataclasses.is_dataclass(tp):
        return parse_problems(tp, value, key, cores)
    args = get_args(tp)
    if get_origin(tp) in (dict, Mapping) and dataclasses.is_dataclass(args[1]):
        if not isinstance(value, Mapping):
            return [f"{key}: expected a mapping, got {value!r}"]
        return [
            p for k, v in value.items() for p in parse_problems(args[1], v, f"{key}.{k}", cores)
        ]
    try:  # a leaf, as config.parse takes it
        if f.metadata.get("cores"):
            value = resolve_cores(value, cores, key)
        else:
            value = _coerce(tp, value, key, cores)
        _check_range(f, value, key)
    except ClutterbenchError as exc:
        return [str(exc)]
    return []

"""params.yaml -> frozen dataclasses, with one-line errors that name the offending key.

Any value in params.yaml may be written as a mapping keyed by scale, e.g.
``n_scenes: {tiny: 8, default: 600, paper: 50000}``; ``base.scale`` picks the entry. So a
whole run switches scale with one override: ``dvc exp run -S base.scale=paper``.
"""

from __future__ import annotations

import dataclasses
import os
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

import yaml

from clutterbench.errors import ClutterbenchError, yaml_problem

SCALES = ("tiny", "default", "paper")
T = TypeVar("T")


def bounded(
    default: Any = dataclasses.MISSING,
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
) -> Any:
    """A dataclass field with an allowed numeric range, checked when params are parsed."""
    kwargs: dict[str, Any] = {"metadata": {"ge": ge, "gt": gt, "le": le}}
    if isinstance(default, list | dict):
        kwargs["default_factory"] = lambda: default
    elif default is not dataclasses.MISSING:
        kwargs["default"] = default
    return dataclasses.field(**kwargs)


AUTO = "auto"
"""A core count (base.cores, base.torch_threads, a stage's `workers`) written as this means:
base.cores, and base.cores itself means this machine's count (machine_cores)."""


def machine_cores() -> int:
    """The CPUs this process may run on: its affinity mask's count where the OS has one (a
    container or taskset may allow fewer than the machine has), else os.cpu_count()."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def resolve_cores(value: Any, cores: int | None = None, key: str = "base.cores") -> int:
    """A core-count parameter as an int: `auto` -> `cores` (base.cores; None: the machine's
    count), an integer >= 1 as it is; anything else is a one-line error naming `key`."""
    if value == AUTO:
        return machine_cores() if cores is None else cores
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ClutterbenchError(f"{key}: {value!r} is not {AUTO} or an integer >= 1")
    return value


def cores_field(default: int | str) -> Any:
    """A dataclass field of a core count (annotated int): params may write it as an integer
    >= 1 or `auto` (base.cores), resolved to an int when params are parsed (resolve_cores)."""
    return dataclasses.field(default=default, metadata={"cores": True})


@dataclasses.dataclass(frozen=True)
class BaseConfig:
    seed: int = bounded(0, ge=0)
    """Base random seed; every scene and every training run derives its seed from it."""
    cores: int = cores_field(AUTO)
    """CPU cores the pipeline may use: an integer >= 1, or auto (this machine's: the CPUs
    this process may run on). Every other core count written `auto` (torch_threads, the
    simulation stages' `workers`) means this."""
    torch_threads: int = cores_field(2)
    """Threads torch may use (intra-op); auto: `cores`."""
    scale: Literal["tiny", "default", "paper"] = "default"
    """Scale profile: tiny (the tests; a stage in seconds), default (the whole pipeline on 2
    CPU cores: docs/run-times.md), paper (thesis sizes, bigger hardware)."""

    def __post_init__(self) -> None:
        # `auto` here also where BaseConfig is built directly rather than parsed
        cores = resolve_cores(self.cores, None, "base.cores")
        object.__setattr__(self, "cores", cores)
        object.__setattr__(
            self, "torch_threads", resolve_cores(self.torch_threads, cores, "base.torch_threads")
        )


YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""PyYAML's safe loader, libyaml's C parser where the wheel has it: the same values as
yaml.safe_load, ~10x sooner (every stage reads params.yaml)."""


def load_params(path: Path | str = "params.yaml") -> dict[str, Any]:
    """Read params.yaml; a missing or unparsable file is a one-line error."""
    path = Path(path)
    if not path.exists():
        raise ClutterbenchError(f"params file not found: {path}")
    try:
        raw = yaml.load(path.read_text(), Loader=YAML_LOADER) or {}
    except yaml.YAMLError as exc:
        raise ClutterbenchError(
            f"params file {path} is not valid YAML: {yaml_problem(exc)}"
        ) from None
    if not isinstance(raw, dict):
        raise ClutterbenchError(f"params file {path} must be a mapping of sections")
    return raw


PACKAGE_REPO = Path(__file__).resolve().parents[2]
"""The repository the package lives in when installed editable (src/clutterbench/)."""


def project_params_path() -> Path:
    """The project's params.yaml: the nearest at or above the working directory holding a
    dvc.yaml beside it, else the package's own repository's."""
    cwd = Path.cwd().resolve()
    for d in (cwd, *cwd.parents):
        if (d / "dvc.yaml").is_file() and (d / "params.yaml").is_file():
            return d / "params.yaml"
    if (PACKAGE_REPO / "params.yaml").is_file():
        return PACKAGE_REPO / "params.yaml"
    raise ClutterbenchError(
        "no params.yaml found (run inside the clutterbench project, or pass spec= to the env)"
    )


def resolve_scale(value: Any, scale: str, key: str) -> Any:
    """Replace every {tiny:, default:, paper:} mapping below `value` by its `scale` entry."""
    if isinstance(value, Mapping):
        keys = set(value)
        if keys and keys <= set(SCALES) and "default" in keys:
            if scale not in value:
                raise ClutterbenchError(f"{key}: no value for scale '{scale}'")
            return resolve_scale(value[scale], scale, key)
        return {k: resolve_scale(v, scale, f"{key}.{k}") for k, v in value.items()}
    if isinstance(value, list):
        return [resolve_scale(v, scale, f"{key}[{i}]") for i, v in enumerate(value)]
    return value


def parse(cls: type[T], data: Any, key: str, cores: int | None = None) -> T:
    """Build dataclass `cls` from `data`, rejecting unknown keys, wrong types, bad ranges.
    A core-count field (cores_field) written `auto` becomes `cores` (base.cores; None: this
    machine's count)."""
    if not isinstance(data, Mapping):
        raise ClutterbenchError(f"{key}: expected a mapping, got {type(data).__name__}")
    prepare = getattr(cls, "prepare_params", None)
    if prepare is not None:  # a section's defaults of its entries (TrialsConfig's episodes)
        data = prepare(data)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ClutterbenchError(f"{key}.{unknown[0]}: unknown key (allowed: {', '.join(fields)})")
    kwargs = {}
    for name, f in fields.items():
        sub = f"{key}.{name}"
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ClutterbenchError(f"{sub}: missing required key")
            continue
        if f.metadata.get("cores"):
            value = resolve_cores(data[name], cores, sub)
        else:
            value = _coerce(hints[name], data[name], sub, cores)
        _check_range(f, value, sub)
        kwargs[name] = value
    try:
        obj = cls(**kwargs)
    except ValueError as exc:  # __post_init__ cross-field checks
        raise ClutterbenchError(f"{key}: {exc}") from None
    return obj


def _check_range(f: dataclasses.Field, value: Any, key: str) -> None:
    meta = f.metadata
    values = value if isinstance(value, tuple) else (value,)
    for v in values:
        if not isinstance(v, int | float) or isinstance(v, bool):
            continue
        if meta.get("ge") is not None and v < meta["ge"]:
            raise ClutterbenchError(f"{key}: {v} is out of range (must be >= {meta['ge']})")
        if meta.get("gt") is not None and v <= meta["gt"]:
            raise ClutterbenchError(f"{key}: {v} is out of range (must be > {meta['gt']})")
        if meta.get("le") is not None and v > meta["le"]:
            raise ClutterbenchError(f"{key}: {v} is out of range (must be <= {meta['le']})")


def _coerce(tp: Any, value: Any, key: str, cores: int | None = None) -> Any:
    origin, args = get_origin(tp), get_args(tp)
    if tp is Any:  # parsed later by whoever knows its type (e.g. a network's own config)
        return value
    if dataclasses.is_dataclass(tp):
        return parse(tp, value, key, cores)
    if origin is Literal:
        if value not in args:
            raise ClutterbenchError(f"{key}: {value!r} is not one of {', '.join(map(str, args))}")
        return value
    if origin in (types.UnionType, typing.Union):
        for option in args:
            try:
                return _coerce(option, value, key, cores)
            except ClutterbenchError:
                continue
        raise ClutterbenchError(f"{key}: {value!r} has the wrong type (expected {tp})")
    if tp is type(None):
        if value is not None:
            raise ClutterbenchError(f"{key}: expected null")
        return None
    if tp is bool:
        if not isinstance(value, bool):
            raise ClutterbenchError(f"{key}: expected true/false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ClutterbenchError(f"{key}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ClutterbenchError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ClutterbenchError(f"{key}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ClutterbenchError(f"{key}: expected a list, got {value!r}")
        item_types = (
            args if not (len(args) == 2 and args[1] is Ellipsis) else (args[0],) * len(value)
        )
        if len(value) != len(item_types):
            raise ClutterbenchError(f"{key}: expected {len(item_types)} items, got {len(value)}")
        return tuple(
            _coerce(t, v, f"{key}[{i}]", cores) for i, (t, v) in enumerate(zip(item_types, value))
        )
    if origin in (dict, Mapping):
        if not isinstance(value, Mapping):
            raise ClutterbenchError(f"{key}: expected a mapping, got {value!r}")
        kt, vt = args
        return {
            _coerce(kt, k, key, cores): _coerce(vt, v, f"{key}.{k}", cores)
            for k, v in value.items()
        }
    raise TypeError(f"unsupported config type {tp} at {key}")


def load_section(
    cls: type[T],
    section: str,
    params: Mapping[str, Any] | None = None,
    path: Path | str = "params.yaml",
) -> T:
    """Load `params[section]` as `cls`, after choosing scale-dependent values by base.scale.
    A dotted name ("yamakuzushi.pile") loads a subsection, so a stage depends on only the
    params (and modules) it reads."""
    params = load_params(path) if params is None else params
    base = load_base(params)
    raw: Any = params
    for part in section.split("."):
        if not isinstance(raw, Mapping) or part not in raw:
            raise ClutterbenchError(f"{section}: section missing from params")
        raw = raw[part]
    return parse(cls, resolve_scale(raw, base.scale, section), section, base.cores)


def load_base(params: Mapping[str, Any]) -> BaseConfig:
    if "base" not in params:
        raise ClutterbenchError("base: section missing from params")
    raw = params["base"]
    scale = raw.get("scale", "default") if isinstance(raw, Mapping) else "default"
    if scale not in SCALES:
        raise ClutterbenchError(f"base.scale: {scale!r} is not one of {', '.join(SCALES)}")
    raw = resolve_scale(raw, scale, "base")
    cores = raw.get("cores", AUTO) if isinstance(raw, Mapping) else AUTO
    return parse(BaseConfig, raw, "base", resolve_cores(cores, None, "base.cores"))


def as_dict(cfg: Any) -> Any:
    """A JSON-able plain copy of a parsed config (for hashing and for checkpoints)."""
    if dataclasses.is_dataclass(cfg):
        return {f.name: as_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    if isinstance(cfg, Mapping):
        return {k: as_dict(v) for k, v in cfg.items()}
    if isinstance(cfg, tuple | list):
        return [as_dict(v) for v in cfg]
    return cfg

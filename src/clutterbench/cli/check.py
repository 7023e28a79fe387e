"""`clutterbench check [PARAMS] [--spec FILE ...]`: params.yaml and scene specs checked
before anything runs, where a typo used to surface only in the stage that reads it (`dvc repro
--dry` on a fresh clone stops at the missing data first).

Every section a stage or command reads (`sections()`) is parsed as its stage parses it, at
every scale profile, collecting every problem instead of the first (each entry of a mapping,
a dataset or a condition, on its own); then what the stages check against other sections when
they start (`CROSS`: a condition's planner and stream, a run's model and datasets, a report
row's condition), and top-level keys nothing reads. No data, model or report is read: it runs
on a fresh clone in a second or two (the section classes import torch, not SAPIEN).
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any

import typer

from clutterbench.checks import (
    BenchmarkParams,
    parse_problems,
    resolve_scale_collecting,
    unknown_name,
)
from clutterbench.cli.common import (
    EXIT_USER_ERROR,
    app,
    default_path,
    print_error,
    project_root,
    user_errors,
)
from clutterbench.config import SCALES, BaseConfig, as_dict, load_base, load_params, parse
from clutterbench.errors import ClutterbenchError
from clutterbench.trials.condition_sets import SENSED_GROUPS, opt_in_lines, thesis_row_lines

Resolved = Mapping[str, Any]
"""params.yaml's sections at one scale profile (scale mappings resolved), as read."""


def sections() -> dict[str, type]:
    """params.yaml's top-level sections -> the dataclass their readers parse them with. Every
    load_section call in stages/ and src/ names one of these (or a field below one), which
    tests/unit/test_check.py asserts, so a new stage's section is checked from the start.
    Imported here, not at module level: the classes import torch, and `--help` stays fast."""
    from clutterbench.collapse.config import EvaluateConfig, TrainConfig
    from clutterbench.collapse.designs import DesignsConfig
    from clutterbench.collapse.detector import DetectorParams
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.split import SplitConfig
    from clutterbench.parallel import ParallelConfig
    from clutterbench.precision import InferenceConfig
    from clutterbench.report.config import ReportConfig
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.trials.ch3.config import Ch3Config
    from clutterbench.trials.config import TrialsConfig
    from clutterbench.trials.noise.config import NoiseConfig

    return {
        "benchmark": BenchmarkParams,  # every stage and environment (sim/benchmark.py)
        "base": BaseConfig,  # every stage (stage.run_stage)
        "sim": SimConfig,
        "parallel": ParallelConfig,
        "generate": GenerateConfig,
        "split": SplitConfig,
        "support": SupportEvalConfig,  # support, box_head, testset
        "trials": TrialsConfig,  # every trials stage, noise, generate, testset
        "noise": NoiseConfig,
        "yamakuzushi": Ch3Config,  # slides, train_slide, trials_ch3
        "report": ReportConfig,
        "train": TrainConfig,
        "inference": InferenceConfig,  # evaluate, support, every trials stage
        "evaluate": EvaluateConfig,
        "detector": DetectorParams,
        "designs": DesignsConfig,  # make designs
    }


# -- lookups in the resolved params, safe on whatever a typo left there ------------------------
def _at(p: Resolved, dotted: str) -> Any:
    value: Any = p
    for part in dotted.split("."):
        value = value.get(part) if isinstance(value, Mapping) else None
    return value


def _mapping(p: Resolved, dotted: str) -> Mapping[Any, Any]:
    value = _at(p, dotted)
    return value if isinstance(value, Mapping) else {}


def _entries(p: Resolved, dotted: str) -> dict[str, Mapping[str, Any]]:
    """The mapping entries at `dotted` (a dataset, a condition), {} where there is none."""
    return {str(k): v for k, v in _mapping(p, dotted).items() if isinstance(v, Mapping)}


def _keys(p: Resolved, dotted: str) -> list[str]:
    return [str(k) for k in _mapping(p, dotted)]


def _list(value: Any) -> list[Any]:
    return value if isinstance(value, list) else []


def _refused(call: Callable[..., Any], *args: Any) -> list[str]:
    """[the one line of the ClutterbenchError `call(*args)` raises], or [] when it runs."""
    try:
        call(*args)
    except ClutterbenchError as exc:
        return [str(exc)]
    return []


def _ref(p: Resolved, key: str, name: Any, where: str, what: str) -> list[str]:
    """[one line] when `name` (params `key`) is no entry of params `where`."""
    return unknown_name(key, name, _keys(p, where), what, where)


def _dataset_refs(p: Resolved, key: str, name: Any, split: bool = True) -> list[str]:
    """A dataset a stage reads: generated and, where it reads its split file, split."""
    out = _ref(p, key, name, "generate.datasets", "dataset")
    return out or (_ref(p, key, name, "split.datasets", "dataset") if split else [])


def _model_ref(p: Resolved, key: str, name: Any) -> list[str]:
    return _ref(p, key, name, "train.models", "model")


# -- what the stages check across sections when they start --------------------------------------
def check_split(p: Resolved) -> list[str]:
    from clutterbench.data.split import Fractions, split_scenes

    out = []
    for name, fractions in _entries(p, "split.datasets").items():
        key = f"split.datasets.{name}"
        out += _dataset_refs(p, key, name, split=False)
        n_scenes = _at(p, f"generate.datasets.{name}.n_scenes")
        bad = not isinstance(n_scenes, int) or n_scenes < 1  # generate's own check names it
        if out or bad or _refused(parse, Fractions, fractions, key):  # ... and split's
            continue
        out += _refused(split_scenes, n_scenes, parse(Fractions, fractions, key), 0, name)
    return out


def net_params(model: Mapping[str, Any]) -> Any:
    """A train.models entry's `net` as TrainConfig parses it: with more than one head
    (labels), n_classes one channel each unless given."""
    net, labels = model.get("net", {}), model.get("labels")
    if isinstance(net, Mapping) and "n_classes" not in net and isinstance(labels, list):
        return {**net, "n_classes": len(labels)} if len(labels) > 1 else net
    return net


def check_train(p: Resolved) -> list[str]:
    from clutterbench.collapse.config import TrainConfig, TrainModelConfig
    from clutterbench.models import ARCHS

    # the checks TrainConfig makes of its own fields (precision); of its models: below
    own = {k: v for k, v in _mapping(p, "train").items() if k != "models"}
    out = _refused(parse, TrainConfig, own, "train")
    for name, model in _entries(p, "train.models").items():
        key = f"train.models.{name}"
        out += _dataset_refs(p, f"{key}.dataset", model.get("dataset"))
        arch = model.get("arch")
        if arch not in ARCHS:
            out += unknown_name(f"{key}.arch", arch, ARCHS, "arch")
            continue
        problems = parse_problems(ARCHS[arch][0], net_params(model), f"{key}.net")
        if not problems and not parse_problems(TrainModelConfig, model, key):
            # the model's labels, loss and network together (TrainConfig's own check)
            problems = _refused(parse, TrainConfig, {"models": {name: model}}, "train")
        out += problems
    return out


def check_yamakuzushi(p: Resolved) -> list[str]:
    size, crop = _at(p, "yamakuzushi.convnet.net.input_size"), _at(p, "yamakuzushi.scan.crop_px")
    if isinstance(size, int) and isinstance(crop, int) and size != crop:  # Ch3Config's check
        return [f"yamakuzushi.convnet.net.input_size: {size} must equal scan.crop_px {crop}"]
    return []


def check_evaluate(p: Resolved) -> list[str]:
    from clutterbench.collapse.evaluate import SplitRef, check_val_split

    out = []
    models = _entries(p, "train.models")
    for name, run in _entries(p, "evaluate.runs").items():
        key = f"evaluate.runs.{name}"
        refs = _model_ref(p, f"{key}.model", run.get("model"))
        for field in ("dataset", "val_dataset"):
            refs += _dataset_refs(p, f"{key}.{field}", run.get(field))
        out += refs
        if refs:
            continue
        model, head = models.get(run["model"], {}), run.get("head", "deletion")
        labels, where = model.get("labels", ["deletion"]), f"train.models.{run['model']}.labels"
        out += unknown_name(f"{key}.head", head, labels, "head", where)
        for field in ("dataset", "val_dataset") if head != "deletion" else ():
            if not _at(p, f"generate.datasets.{run[field]}.pull_outcomes"):
                out.append(f"{key}.{field}: head {head} needs a dataset with pull_outcomes: true")
        test = SplitRef(run["dataset"], Path(), run.get("split", "test"), 0.0)
        val = SplitRef(run["val_dataset"], Path(), "val", 0.0)
        out += _refused(check_val_split, test, val, model.get("dataset"), f"{key}.val_dataset")
    return out


def check_support(p: Resolved) -> list[str]:
    test = "support.box_head.test_dataset"  # read whole (testset), never split
    return [
        *_model_ref(p, "support.model", _at(p, "support.model")),
        *_dataset_refs(p, "support.val_dataset", _at(p, "support.val_dataset")),
        *_dataset_refs(p, test, _at(p, test), split=False),
    ]


def ch6_planners(p: Resolved) -> tuple[list[str], list[str]]:
    """(the ch. 6 planners a condition may name, problems importing trials.planner_modules):
    the built-in ones, and with planner_modules those their import registers (as the trials
    stage does it)."""
    from clutterbench.trials.ch6.planners import PLANNERS as REGISTERED

    modules = _at(p, "trials.planner_modules")
    if not modules or not isinstance(modules, list):
        return list(REGISTERED), []
    out = []
    for module in modules:
        try:
            importlib.import_module(str(module))
        except ImportError as exc:
            out.append(f"trials.planner_modules: cannot import {module} ({exc})")
    return list(REGISTERED), out


def check_trials(p: Resolved) -> list[str]:
    from clutterbench.trials.config import DEV_PREFIX

    planners, out = ch6_planners(p)
    streams = _keys(p, "trials.streams")
    out += [
        f"trials.streams.{s}: a table stream may not be named like a dev stream ('{DEV_PREFIX}*')"
        for s in streams
        if s.startswith(DEV_PREFIX)
    ]
    for group in ("conditions", "ch4_conditions", "ch5_conditions"):
        for name, cond in _entries(p, f"trials.{group}").items():
            key = f"trials.{group}.{name}"
            out += _ref(p, f"{key}.stream", cond.get("stream"), "trials.streams", "stream")
            if group == "conditions":
                out += unknown_name(f"{key}.planner", cond.get("planner"), planners, "planner")
            if group == "ch4_conditions" and cond.get("model") is not None:
                out += _model_ref(p, f"{key}.model", cond.get("model"))
    for field in ("ch6.model", "ch6.ch4_model", "ch5.model"):
        out += _model_ref(p, f"trials.{field}", _at(p, f"trials.{field}"))
    for key in SENSED_GROUPS.values():  # the networks the sensed twins read instead
        for name, twin in _mapping(p, f"trials.{key}.models").items():
            out += _model_ref(p, f"trials.{key}.models.{name}", twin)
    role = {name: _role(name) for name in planners}
    return out + check_arm_conditions(p) + opt_in_lines(_mapping(p, "trials"), role.get)


def check_arm_conditions(p: Resolved) -> list[str]:
    ch6, ch4 = _entries(p, "trials.conditions"), _entries(p, "trials.ch4_conditions")
    out = []
    for name, arm in _entries(p, "trials.arm_conditions").items():
        key, of = f"trials.arm_conditions.{name}", arm.get("of")
        if of in ch6 and of in ch4:
            out.append(f"{key}.of: '{of}' names a ch. 6 and a ch. 4 condition")
            continue
        found = unknown_name(
            f"{key}.of", of, [*ch6, *ch4], "condition", "trials.conditions, ch4_conditions"
        )
        out += found
        kinematic = {**ch6, **ch4}.get(of, {})
        chapter = "ch4" if of in ch4 else "ch6"  # a condition naming none has its chapter's
        most = kinematic.get("episodes", _at(p, f"trials.{chapter}.episodes"))
        episodes = arm.get("episodes")
        if not found and isinstance(episodes, int) and isinstance(most, int) and episodes > most:
            out.append(
                f"{key}.episodes: {episodes} is more than the {most} episodes of '{of}' it is "
                "compared with"
            )
    return out


def _role(planner: str) -> str:
    from clutterbench.trials.ch6.planners import planner_info

    return planner_info(planner).role


def _is_oracle(planner: str) -> bool:
    return _role(planner) == "oracle"


def check_noise(p: Resolved) -> list[str]:
    conditions = _entries(p, "trials.conditions")
    planners, _ = ch6_planners(p)
    skipped = [] if _at(p, "trials.opt_in.run") else _list(_at(p, "trials.opt_in.conditions"))
    out = []
    for name in _list(_at(p, "noise.conditions")):
        found = _ref(p, "noise.conditions", name, "trials.conditions", "condition")
        if not found and name in skipped:
            found.append(f"noise.conditions: '{name}' is opt-in and not run (trials.opt_in.run)")
        executor = conditions.get(name, {}).get("executor", "kinematic")
        if not found and executor != "kinematic":
            found.append(
                f"noise.conditions: '{name}' runs on the {executor} executor; replays run on "
                "the kinematic one"
            )
        out += found
    for name, of in _mapping(p, "noise.robust").items():
        key = f"noise.robust.{name}"
        found = _ref(p, key, of, "trials.conditions", "condition")
        planner = conditions.get(of, {}).get("planner")
        if planner in planners and not _is_oracle(planner):
            found.append(f"{key}: '{of}' is not a search oracle's")
        if name in conditions:
            found.append(f"{key}: the name is a trials condition")
        out += found
    return out


REPORT_TABLES = {
    "evaluate.runs": ("table_5_1", "table_6_1", "table_4_2"),
    "trials.conditions": ("table_6_3",),
    "trials.ch4_conditions": ("table_4_1", "table_4_1_target"),
    "trials.ch5_conditions": ("table_5_2",),
}
"""Where the rows' names of the report's tables must be -> those tables (null: not run)."""


def check_report(p: Resolved, root: Path) -> list[str]:
    out = []
    for where, tables in REPORT_TABLES.items():
        for table in tables:
            for row, name in _mapping(p, f"report.{table}").items():
                out += _ref(p, f"report.{table}.{row}", name, where, "name")
    figures = _at(p, "report.thesis_figures")
    if isinstance(figures, str) and not (root / figures).is_file():
        out.append(f"report.thesis_figures: {figures} not found (a path in the repository)")
    elif isinstance(figures, str):  # no opt-in condition runs a thesis row of Table 6.3
        from clutterbench.report.tables import load_thesis_figures

        try:
            rows = _list(_at(load_thesis_figures(root / figures), "table_6_3.rows"))
        except ClutterbenchError as exc:
            return [*out, str(exc)]
        opt_in = _list(_at(p, "trials.opt_in.conditions"))
        out += thesis_row_lines(opt_in, _mapping(p, "report.table_6_3"), rows)
    return out


def check_designs(p: Resolved) -> list[str]:
    from clutterbench.models import ARCHS, parse_net_config

    model = _at(p, "designs.model")
    out = _model_ref(p, "designs.model", model)
    designs = _entries(p, "designs.designs")
    if not _at(p, "designs.designs"):
        out.append("designs.designs: no design to compare")
    model_cfg = _entries(p, "train.models").get(model, {})
    arch, net = model_cfg.get("arch"), net_params(model_cfg)
    if out or arch not in ARCHS or parse_problems(ARCHS[arch][0], net, "net"):
        return out  # train's own check names what is wrong with the model
    base = as_dict(parse_net_config(arch, net, "net"))  # as collapse.designs.design_net
    for name, changes in designs.items():
        out += parse_problems(ARCHS[arch][0], {**base, **changes}, f"designs.designs.{name}")
    return out


CROSS: dict[str, Callable[[Resolved], list[str]]] = {
    "split": check_split,
    "train": check_train,
    "evaluate": check_evaluate,
    "support": check_support,
    "detector": lambda p: _dataset_refs(p, "detector.dataset", _at(p, "detector.dataset")),
    "trials": check_trials,
    "noise": check_noise,
    "designs": check_designs,
    "yamakuzushi": check_yamakuzushi,
}
"""Section -> what its readers check against other sections (and check_report)."""


OPTIONAL = ("benchmark",)
"""Sections whose readers take their absence as their defaults (params.get)."""


# -- the whole file --------------------------------------------------------------------------
Extra = Mapping[str, tuple[type, Callable[[Resolved], list[str]]]]
"""Sections a caller adds to the check: name -> (dataclass, cross-section check)."""


def check_scale(
    params: Mapping[str, Any], scale: str, root: Path, extra: Extra | None = None
) -> list[str]:
    """Every problem of the sections at scale profile `scale`: each section's own, its
    cross-section ones, and, where neither found any, whatever the section's full parse
    still refuses (the checks its __post_init__ makes across its fields)."""
    base = params.get("base")
    try:
        raw_base = {**base, "scale": scale} if isinstance(base, Mapping) else base
        cores: int | None = load_base({**params, "base": raw_base}).cores
    except ClutterbenchError:
        cores = None  # base's own check names the problem
    known = {**sections(), **{k: cls for k, (cls, _) in (extra or {}).items()}}
    cross = {**CROSS, **{k: check for k, (_, check) in (extra or {}).items()}}
    out: list[str] = []
    resolved = {}
    for name in known:
        if name in params:
            resolved[name] = resolve_scale_collecting(params[name], scale, name, out)
    for name, cls in known.items():
        if name not in resolved:
            continue
        mine = parse_problems(cls, resolved[name], name, cores, construct=False)
        mine += cross.get(name, lambda p: [])(resolved)
        mine += check_report(resolved, root) if name == "report" else []
        if not mine and hasattr(cls, "__post_init__"):  # its checks across its fields
            mine = _refused(parse, cls, resolved[name], name, cores)
        out += mine
    return out


def check_params(
    path: Path, extra: Extra | None = None, more: Mapping[str, Any] | None = None
) -> list[str]:
    """One line per problem of params file `path`, at every scale profile: a problem of some
    profiles only says which. `more`: sections read from elsewhere, checked as `extra` says
    (experiments/check.py adds the rechecks' `dev` section)."""
    try:
        params = {**load_params(path), **(more or {})}
    except ClutterbenchError as exc:
        return [str(exc)]
    known = {**sections(), **{k: cls for k, (cls, _) in (extra or {}).items()}}
    out = []
    for name in params:
        if name not in known:
            close = difflib.get_close_matches(str(name), known, n=1)
            hint = f"did you mean '{close[0]}'?" if close else f"known: {', '.join(known)}"
            out.append(f"{name}: unknown section; no stage or command reads it ({hint})")
    out += [
        f"{name}: section missing from params"
        for name in known
        if name not in params and name not in OPTIONAL
    ]
    seen: dict[str, list[str]] = {}  # problem -> the scales it is found at
    for scale in SCALES:
        for line in check_scale(params, scale, project_dir(path), extra):
            if scale not in seen.setdefault(line, []):
                seen[line].append(scale)
    for line, scales in seen.items():
        named = len(scales) == 1 and f"scale '{scales[0]}'" in line  # a missing scale entry
        every = len(scales) == len(SCALES)
        out.append(line if every or named else f"{line} (scale {', '.join(scales)})")
    return out


def project_dir(params: Path) -> Path:
    """Where the stages run (the paths in params are relative to it): the params file's
    directory when dvc.yaml is beside it, else the project's."""
    here = params.resolve().parent
    return here if (here / "dvc.yaml").is_file() else (project_root() or here)


def check_specs(paths: Iterable[Path]) -> list[str]:
    """One line per scene spec the project's loader refuses (its first problem)."""
    from clutterbench.sim.spec import SceneSpec

    return [line for path in paths for line in _refused(SceneSpec.load, path)]


PARAMS_HELP = "Params file (default: the project's params.yaml)."
SPEC_HELP = "A scene spec (JSON) to check; repeatable."


@app.command("check")
def check(
    params: Annotated[Path | None, typer.Argument(metavar="[PARAMS]", help=PARAMS_HELP)] = None,
    spec: Annotated[list[Path] | None, typer.Option(metavar="FILE", help=SPEC_HELP)] = None,
) -> None:
    """Check params.yaml (every section at every scale profile, and what the stages check
    across sections) and scene specs, reading no data: one line per problem and exit 2, or
    one line `ok`."""
    with user_errors():
        path = default_path(params, "params.yaml")
        problems = check_params(path) + check_specs(spec or [])
    for line in problems:
        print_error(line)
    if problems:
        raise typer.Exit(EXIT_USER_ERROR)
    shown = params if params is not None else "the project's params.yaml"
    specs = f" and {len(spec)} scene spec{'s' * (len(spec) != 1)}" if spec else ""
    typer.echo(f"ok: {shown}{specs} (every section at scales {', '.join(SCALES)})")

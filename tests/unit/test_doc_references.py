"""The reference docs name only what exists. In README.md, docs/ and the READMEs under
reports/ and experiments/, every

- repository path, in backticks or as a Markdown link, is a file or folder of the tree, or an
  output that a fresh clone does not have yet: under one of dvc.yaml's outputs, metrics or
  plots, or ignored by .gitignore (data/, models/, reports/timing/, ...);
- `make <target>` names a target the Makefile (or a file it includes) defines;
- dvc stage named in backticks (`train@cp_focal`, `dvc repro trials_ch4`, "stage `support`",
  "the `noise` stage") is one of dvc.yaml's, a foreach stage's key one of the params.yaml list
  it runs over.

What counts as a path: a backticked word with a slash whose first folder is at the repository
root (`reports/...`), or is a subpackage of src/clutterbench/ (`trials/core/`, written with a
closing slash or a file suffix), or is beside the doc. A path with a placeholder
(`<model>`, `*`, `chN`, `NAME`) is checked up to the folder before its first placeholder.
A word like `trials/core/protocol.moved_others` is checked as the module it names, and so is
`clutterbench.trials.core.stats` in a code span, an import or a `python -m` line.

A planted doc shows that each kind is found, so a passing tree means something."""

from __future__ import annotations

import fnmatch
import posixpath
import re
import shutil
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "src/clutterbench"
SUFFIXES = {
    "py", "md", "json", "jsonl", "yaml", "yml", "csv", "png", "mcap", "npz", "pt", "txt",
    "sh", "toml", "lock", "gz", "html", "cfg", "ini",
}  # fmt: skip
"""File suffixes that make a package-relative word (`sim/pull.py`) a path."""


def markdown_files(root: Path = ROOT) -> list[Path]:
    """The docs checked: README.md, docs/**/*.md and every README.md under reports/ and
    experiments/ (the rechecks' index and their reports')."""
    files = [
        root / "README.md",
        *root.glob("docs/**/*.md"),
        *root.glob("reports/**/README.md"),
        *root.glob("experiments/**/README.md"),
    ]
    return sorted(p for p in files if p.is_file())


# --- what the repository defines -----------------------------------------------------------

_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


@dataclass(frozen=True)
class Facts:
    root: Path
    targets: frozenset[str]
    stages: dict[str, frozenset[str] | None]
    """Every stage of dvc.yaml; a foreach stage's value is the set of its keys."""
    foreach: dict[str, str]
    """A foreach stage's params list (train: train.models)."""
    outs: tuple[str, ...]
    """dvc.yaml's outputs, metrics and plots as glob patterns (${...} as *)."""
    ignore: tuple[tuple[bool, str], ...]
    """.gitignore's rules as (negated, pattern)."""
    tops: frozenset[str]
    """Names at the repository root, and the first folder of every dvc output."""
    packages: frozenset[str]
    """The subpackages of src/clutterbench/ (and `clutterbench`)."""


def make_targets(makefile: str) -> set[str]:
    """Every target a rule or .PHONY names (not $(VAR) or pattern rules)."""
    out: set[str] = set()
    for line in makefile.splitlines():
        m = re.match(r"([^\s#:=][^:=#]*?)\s*::?(?!=)(.*)", line)
        if not m:
            continue
        names = m.group(2).split("#")[0].split() if m.group(1) == ".PHONY" else []
        names += m.group(1).split() if m.group(1) != ".PHONY" else []
        out.update(n for n in names if "$" not in n and "%" not in n)
    return out


def makefile_text(root: Path) -> str:
    """The Makefile with the files it includes (`include experiments/Makefile`)."""
    text = (root / "Makefile").read_text()
    included = re.findall(r"^-?include\s+(.+)$", text, re.M)
    return "\n".join([text, *((root / name).read_text() for name in " ".join(included).split())])


def _dotted(params: dict, ref: str):
    value = params
    for part in ref.split("."):
        value = value[part]
    return value


def foreach_params(dvc: dict) -> dict[str, str]:
    """Each foreach stage's params list, as its dotted key (train: train.models)."""
    out = {}
    for name, stage in dvc["stages"].items():
        m = re.fullmatch(r"\$\{\s*([\w.]+)\s*\}", str(stage.get("foreach", "")))
        if m:
            out[name] = m.group(1)
    return out


def dvc_stages(dvc: dict, params: dict) -> dict[str, frozenset[str] | None]:
    """dvc.yaml's stages; a foreach stage with the keys of the list it runs over."""
    refs = foreach_params(dvc)
    out: dict[str, frozenset[str] | None] = {}
    for name, stage in dvc["stages"].items():
        items = _dotted(params, refs[name]) if name in refs else stage.get("foreach")
        out[name] = None if items is None else frozenset(str(k) for k in items)
    return out


def dvc_outputs(dvc: dict) -> tuple[str, ...]:
    """Every output, metric and plot path of dvc.yaml, ${...} written as *."""
    out = []
    for stage in dvc["stages"].values():
        body = stage.get("do", stage)
        for kind in ("outs", "metrics", "plots"):
            for entry in body.get(kind, []):
                path = entry if isinstance(entry, str) else next(iter(entry))
                out.append(re.sub(r"\$\{[^}]*\}", "*", path).rstrip("/"))
    return tuple(out)


def gitignore_rules(text: str) -> tuple[tuple[bool, str], ...]:
    rules = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            negated = line.startswith("!")
            rules.append((negated, line.lstrip("!")))
    return tuple(rules)


def _glob(pattern: str) -> re.Pattern:
    """git's glob: `*` and `?` stop at a slash, `**` does not."""
    body = re.escape(pattern).replace(r"\*\*", ".*").replace(r"\*", "[^/]*")
    return re.compile(body.replace(r"\?", "[^/]"))


def _rule_matches(pattern: str, path: str) -> bool:
    body = pattern.rstrip("/")
    if "/" in body:  # anchored at the root
        return bool(_glob(body.lstrip("/")).fullmatch(path))
    return bool(_glob(body).fullmatch(posixpath.basename(path)))


def ignored(path: str, rules: tuple[tuple[bool, str], ...]) -> bool:
    """Whether git ignores `path` (or a folder above it) under the root .gitignore's rules."""
    parts = path.split("/")
    for n in range(1, len(parts) + 1):
        prefix = "/".join(parts[:n])
        hit = False
        for negated, pattern in rules:
            if _rule_matches(pattern, prefix):
                hit = not negated
        if hit:
            return True
    return False


@cache
def facts(root: Path = ROOT) -> Facts:
    dvc = yaml.load((root / "dvc.yaml").read_text(), Loader=_LOADER)
    params = yaml.load((root / "params.yaml").read_text(), Loader=_LOADER)
    outs = dvc_outputs(dvc)
    package = root / PACKAGE
    return Facts(
        root=root,
        targets=frozenset(make_targets(makefile_text(root))),
        stages=dvc_stages(dvc, params),
        foreach=foreach_params(dvc),
        outs=outs,
        ignore=gitignore_rules((root / ".gitignore").read_text()),
        tops=frozenset({p.name for p in root.iterdir()} | {o.split("/")[0] for o in outs}),
        packages=frozenset({p.name for p in package.iterdir() if p.is_dir()} | {"clutterbench"}),
    )


# --- paths ---------------------------------------------------------------------------------

_PLACEHOLDER = re.compile(
    r"<[^>]*>|[*?\[]|\$\{|\.\.\.|chN(?![A-Za-z])"
    r"|(?<![A-Za-z0-9])(?!README)[A-Z][A-Z0-9_]*(?![a-z0-9])"  # NAME, STAGE, X_Y
)


def _alternatives(ref: str) -> list[str]:
    """`a.{md,csv}` -> a.md, a.csv (one brace group is enough here)."""
    m = re.search(r"\{([^{}]*,[^{}]*)\}", ref)
    if not m:
        return [ref]
    return [ref[: m.start()] + alt + ref[m.end() :] for alt in m.group(1).split(",")]


def _checked_part(path: str) -> str:
    """The path up to the folder before its first placeholder."""
    parts = path.split("/")
    for i, part in enumerate(parts):
        if _PLACEHOLDER.search(part):
            return "/".join(parts[:i])
    return path


def generated(path: str, f: Facts) -> bool:
    """Made by a stage (under a dvc output) or ignored by git: a fresh clone lacks it."""
    outputs = any(
        fnmatch.fnmatchcase(path, o) or fnmatch.fnmatchcase(path, o + "/*") for o in f.outs
    )
    return outputs or ignored(path, f.ignore)


def path_is_live(ref: str, bases: list[str], f: Facts) -> bool:
    for alternative in _alternatives(ref):
        for base in bases:
            path = posixpath.normpath(posixpath.join(base, alternative.strip("/")))
            if path.startswith("../"):
                continue
            path = _checked_part(path)
            if path in ("", ".") or (f.root / path).exists() or generated(path, f):
                return True
    return False


def path_bases(word: str, doc_dir: str, f: Facts) -> list[str]:
    """Where a backticked word with a slash may live (none: it is no repository path)."""
    first = word.lstrip("./").split("/")[0]
    suffix = word.rsplit(".", 1)[-1] if "." in word.rsplit("/", 1)[-1] else ""
    bases = [""] if first in f.tops else []
    if first in f.packages and (word.endswith("/") or suffix in SUFFIXES):
        bases += [PACKAGE, "src"]
    if first and (f.root / doc_dir / first).exists():
        bases.append(doc_dir)
    return bases


_WORD = re.compile(r"^[\w.@+<>*?{},$\-]*/[\w.@+<>*?{},$/\-]*$")


def stale_path(word: str, doc_dir: str, f: Facts) -> bool:
    word = word.split("::")[0].strip("(),;:'\"")
    if not _WORD.match(word) or word.startswith("//") or "=" in word:
        return False
    module = re.fullmatch(r"(\w+/[\w/]*?\w+)\.([A-Za-z_]\w*)", word)
    if module and module.group(2) not in SUFFIXES:  # trials/core/protocol.moved_others
        word = module.group(1) + ".py"
    bases = path_bases(word, doc_dir, f)
    return bool(bases) and not path_is_live(word, bases, f)


def stale_link(target: str, doc_dir: str, f: Facts) -> bool:
    if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
        return False
    file_part = target.split("#")[0].split("?")[0]
    if not file_part:
        return False
    base = "" if file_part.startswith("/") else doc_dir
    return not path_is_live(file_part, [base], f)


_MODULE = re.compile(r"\bclutterbench(?:\.\w+)+")


def stale_module(dotted: str, f: Facts) -> bool:
    """clutterbench.a.b.name: a.b must be a package or module of src/clutterbench/ (what
    follows a module is an attribute; one named in a package's __init__.py counts)."""
    here = f.root / PACKAGE
    for part in dotted.split(".")[1:]:
        if (here / part).is_dir():
            here = here / part
            continue
        init = here / "__init__.py"
        return not (here / f"{part}.py").is_file() and not (
            init.is_file() and re.search(rf"\b{part}\b", init.read_text())
        )
    return False


# --- make targets and dvc stages ---------------------------------------------------------

_MAKE = re.compile(r"(?:^|[;&|(]\s*)make\s+([^;&|#)]*)")
_DVC_REPRO = re.compile(r"(?:^|[;&|(]\s*)dvc\s+(?:repro|status|dag)\b([^;&|#)]*)")
_STAGE_WORD = re.compile(r"[a-z][a-z0-9_]*(?:@[\w<>.-]+)?")


def stale_targets(command: str, f: Facts) -> list[str]:
    """The words of `make ...` that name no target (options and VAR=value skipped)."""
    out = []
    for m in _MAKE.finditer(command):
        for word in m.group(1).split():
            if word.startswith("-") or "=" in word or "$" in word or "<" in word:
                continue
            if not any(fnmatch.fnmatchcase(t, word) for t in f.targets):
                out.append(word)
    return out


def doc_keys(text: str, f: Facts) -> dict[str, set[str]]:
    """Foreach keys a doc adds itself: its ```yaml blocks of params (a worked example that
    adds a run to evaluate.runs may name evaluate@<that run>)."""
    out: dict[str, set[str]] = {}
    for block in re.findall(r"^```ya?ml\n(.*?)^```", text, re.M | re.S):
        try:
            snippet = yaml.load(block, Loader=_LOADER)
        except yaml.YAMLError:
            continue
        for stage, ref in f.foreach.items():
            try:
                out.setdefault(stage, set()).update(map(str, _dotted(snippet, ref)))
            except (KeyError, TypeError):
                pass
    return out


def stage_is_live(name: str, f: Facts, local: dict[str, set[str]] | None = None) -> bool:
    stage, _, key = name.partition("@")
    if stage not in f.stages:
        return False
    keys = f.stages[stage]
    if not key:  # `train` names a foreach stage as a whole
        return True
    if keys is None:
        return False
    return bool(_PLACEHOLDER.search(key)) or key in keys | (local or {}).get(stage, set())


def stage_words(span: str) -> list[str]:
    """The stage names a code span gives: `name@key` alone, or dvc repro/status/dag's args."""
    span = span.strip()
    if re.fullmatch(r"[a-z][a-z0-9_]*@[\w<>.-]+", span):
        return [span]
    return [
        w
        for m in _DVC_REPRO.finditer(span)
        for w in m.group(1).split()
        if not w.startswith("-") and "=" not in w and _STAGE_WORD.fullmatch(w)
    ]


# --- one doc -------------------------------------------------------------------------------

_FENCE = re.compile(r"^```.*?^```", re.M | re.S)
_SPAN = re.compile(r"`([^`]+)`")
_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
_NAMED_STAGE = re.compile(r"\bstages?\s+`([^`]+)`|`([^`]+)`\s+stages?\b")


def _blank(m: re.Match) -> str:
    return re.sub(r"[^\n]", " ", m.group(0))


def _fenced_commands(text: str) -> list[tuple[int, str]]:
    """(offset, line) of every line inside a fenced code block, continued lines joined."""
    out = []
    for block in _FENCE.finditer(text):
        offset, joined = block.start(), ""
        for line in block.group(0).splitlines(keepends=True):
            joined += line.split(" #")[0].rstrip()
            offset += len(line)
            if joined.endswith("\\"):  # a command continued on the next line
                joined = joined[:-1] + " "
                continue
            out.append((offset - len(line), joined))
            joined = ""
    return out


def stale_references(text: str, doc: str, f: Facts) -> list[str]:
    """'line N: kind `name`' for every stale reference in Markdown `text`, the doc at
    repository-relative path `doc` (relative paths resolve against its folder)."""
    doc_dir = posixpath.dirname(doc)
    prose = _FENCE.sub(_blank, text)
    local = doc_keys(text, f)
    hits: list[tuple[int, str]] = []
    for m in _SPAN.finditer(prose):
        span = " ".join(m.group(1).split())
        hits += [(m.start(), f"path `{w}`") for w in span.split() if stale_path(w, doc_dir, f)]
        mods = _MODULE.findall(span)
        hits += [(m.start(), f"module `{w}`") for w in mods if stale_module(w, f)]
        hits += [(m.start(), f"make target `{t}`") for t in stale_targets(span, f)]
        words = stage_words(span)
        hits += [(m.start(), f"stage `{w}`") for w in words if not stage_is_live(w, f, local)]
    for m in _NAMED_STAGE.finditer(prose):
        name = (m.group(1) or m.group(2)).strip()
        if _STAGE_WORD.fullmatch(name) and not stage_is_live(name, f, local):
            hits.append((m.start(), f"stage `{name}`"))
    for m in _LINK.finditer(prose):
        if stale_link(m.group(1), doc_dir, f):
            hits.append((m.start(), f"link `{m.group(1)}`"))
    for offset, line in _fenced_commands(text):
        hits += [(offset, f"make target `{t}`") for t in stale_targets(line.strip(), f)]
        code = re.match(r"\s*(?:from|import)\s|.*\bpython3? -m\s", line)  # not params
        mods = _MODULE.findall(line) if code else []
        hits += [(offset, f"module `{w}`") for w in mods if stale_module(w, f)]
        hits += [
            (offset, f"stage `{w}`") for w in stage_words(line) if not stage_is_live(w, f, local)
        ]
    return sorted({f"line {text.count(chr(10), 0, at) + 1}: {what}" for at, what in hits})


# --- tests ---------------------------------------------------------------------------------


def test_the_repository_facts_are_read() -> None:
    f = facts()
    assert {"repro", "test", "run-times", "shell", ".dvc/config"} <= f.targets
    assert "$(STAMP)" not in f.targets
    assert f.stages["report"] is None and "cp_focal" in f.stages["train"]
    assert "data/generate/*" in f.outs and "reports/evaluate/*/metrics.json" in f.outs
    assert ignored("models/cp_focal/best.pt", f.ignore)
    assert ignored("data/dev/ch4_piles", f.ignore)
    assert not ignored("data/benchmark/manifest.json", f.ignore)
    assert not ignored("src/clutterbench/io.py", f.ignore)


PLANTED = """
Planted: `src/clutterbench/no_such_module.py`, [a page](no-such-page.md),
`trials/physics_model.EstimatedWorldModel` (moved to trials/ch6/), `clutterbench.no_such`,
`make no-such-target`, `train@no_such_model` and the `no_such_stage` stage.

```bash
make repro no-such-fenced-target
dvc repro evaluate@fcn8s_ch5 \\
  evaluate@no_such_run   # a continued line
```
"""
PLANTED_HITS = {
    "path `src/clutterbench/no_such_module.py`",
    "link `no-such-page.md`",
    "path `trials/physics_model.EstimatedWorldModel`",
    "module `clutterbench.no_such`",
    "make target `no-such-target`",
    "stage `train@no_such_model`",
    "stage `no_such_stage`",
    "make target `no-such-fenced-target`",
    "stage `evaluate@no_such_run`",
}


def test_planted_stale_references_are_found(tmp_path: Path) -> None:
    """A copy of docs/running.md with one stale reference of each kind appended: exactly
    those are reported (the copy stands where the original does)."""
    copy = tmp_path / "running.md"
    shutil.copy(ROOT / "docs/running.md", copy)
    copy.write_text(copy.read_text() + PLANTED)
    hits = stale_references(copy.read_text(), "docs/running.md", facts())
    assert {h.split(": ", 1)[1] for h in hits} == PLANTED_HITS


@pytest.mark.parametrize(
    "line",
    [
        "`data/generate/<dataset>/shard-*.npz` and `models/<model>/best.pt`",
        "`reports/evaluate/<run>/metrics.json`, `reports/timing/stages/`",
        "`reports/run_times/<scale>_<cpu>.{json,md}`, `reports/tables/datasets*.md`",
        "`sim/pull.py`, `trials/core/`, `trials/support` (a stream), `/camera/depth`",
        "`examples/plain_cnn.py`, [run times](run-times.md), [top](/README.md#documentation)",
        "`make TORCH_SPEC=torch==2.13.0 repro`, `make dev-*`, `make score PREDICTOR=x.py`",
        "`train@<model>`, `evaluate@cp_focal_pull_ch6_test`, the `report` stage, `dvc repro`",
        "stage `generate@ch6`; `dvc repro -s support trials`",
    ],
)
def test_live_references_pass(line: str) -> None:
    assert stale_references(line, "docs/running.md", facts()) == []


def test_docs_name_only_what_exists() -> None:
    f = facts()
    hits = [
        f"{p.relative_to(ROOT).as_posix()} {hit}"
        for p in markdown_files()
        for hit in stale_references(p.read_text(), p.relative_to(ROOT).as_posix(), f)
    ]
    assert not hits, "stale references (fix the doc):\n" + "\n".join(hits)

"""One direction of imports in src/ (docs/architecture.md): every module imports only its own
layer or those below it (LAYERS), no module imports another that imports it back, however long
the loop, the planners never import the simulator, and the chapters' trials and planning
subpackages stand on a shared core without importing each other. Imports inside functions
count: a lazy import is still a dependency that can break. So do imports made through a
string: a string literal that is a dotted clutterbench module path (`clutterbench.a.b`, or
`clutterbench.a.b:name` as an entry point names it) imports that module, and
`importlib.import_module(f"clutterbench.a.{x}")` imports the package `clutterbench.a`.

The stage scripts (stages/*.py) stand between report and the entry points: each may import
any layer of src/ but the entry points (LAYERS' last), and only stage report imports report/:
every other stage writes what report reads, so what it draws is drawn by code below report."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx
import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGE = SRC / "clutterbench"
STAGES = SRC.parent / "stages"
MANISKILL_MUST_NOT_IMPORT = ("clutterbench.trials", "clutterbench.planning", "clutterbench.report")

LAYERS: tuple[frozenset[str], ...] = tuple(
    frozenset(names.split())
    for names in (
        # the ground floor: plumbing every layer may use
        "errors io config checks progress platform_info precision denormals stage observation"
        " shogi_piece",
        "sim",  # the SAPIEN world, scene families, rendering, actions
        "criteria parallel logs maniskill",  # judged motion, workers, logs, the arm level
        "data",  # datasets, labels, splits
        "models",  # networks
        "perception",  # masks and boxes from an observation
        "collapse",  # training, evaluation and prediction of every network
        "planning",  # planners: functions of what a robot sees
        "support",  # the offline per-box work: box head, test set, Table 6.2 (the trials read it)
        "trials",  # the world and the planner together
        "report",  # tables and figures from records
        "envs cli bench crosscheck readme",  # entry points over everything
    )
)
"""src/clutterbench's top-level modules and packages, lowest first: a module may import its own
layer and the ones below it, never one above (docs/architecture.md draws the same order)."""
CHAPTERS = ("ch3", "ch4", "ch5", "ch6")
ENTRY_POINTS = LAYERS[-1]
REPORT_STAGE = "report"
"""The one stage that imports report/ (it reads every other stage's outputs)."""
MODULE_PATH = re.compile(r"clutterbench(\.[A-Za-z_]\w*)+(:[A-Za-z_][\w.]*)?")
"""A string naming a clutterbench module, alone or with a name in it ("module:function")."""


def module_name(path: Path, src: Path) -> str:
    parts = path.relative_to(src).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_names(tree: ast.AST, package: str) -> set[str]:
    """Every clutterbench module a file names in an import statement (`from a import b` names
    `a.b` too, in case b is a module)."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative import
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return {m for m in out if m.split(".")[0] == "clutterbench"}


def named_by_strings(tree: ast.AST, package: str, module: str) -> set[str]:
    """The dotted names a file imports through strings: each string literal that is a module
    path (MODULE_PATH, its `:name` dropped), and the package of each
    `importlib.import_module(f"...")` (the f-string's text up to its first replacement field
    but `__name__` / `__package__`, which are the file's own module / package, cut at its last
    dot). A dotted name may run past the module into its attributes: `imported_modules`
    keeps the longest prefix that is a module."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if MODULE_PATH.fullmatch(node.value):
                out.add(node.value.split(":")[0])
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.JoinedStr):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name == "import_module":
                out.add(_fstring_prefix(node.args[0], package, module).rpartition(".")[0])
    return out


def _fstring_prefix(text: ast.JoinedStr, package: str, module: str) -> str:
    """The f-string's literal start, `{__name__}` and `{__package__}` filled in."""
    own = {"__name__": module, "__package__": package}
    prefix = ""
    for part in text.values:
        if isinstance(part, ast.Constant):
            prefix += str(part.value)
        elif isinstance(part.value, ast.Name) and part.value.id in own and module:
            prefix += own[part.value.id]
        else:
            break
    return prefix


def imported_modules(path: Path, module: str, files: dict[str, Path]) -> set[str]:
    """The modules of `files` a file imports: by import statements, and through strings (the
    longest prefix of each name that is a module below the package itself)."""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text())
    out = {name for name in imported_names(tree, package) if name in files}
    for name in named_by_strings(tree, package, module):
        parts = name.split(".")
        found = [".".join(parts[:n]) for n in range(len(parts), 1, -1)]
        out.update([m for m in found if m in files][:1])
    return out - {module}


def import_graph(root: Path = PACKAGE) -> nx.DiGraph:
    """module -> the clutterbench modules it imports (only names that are modules)."""
    files = {module_name(p, root.parent): p for p in root.rglob("*.py")}
    graph = nx.DiGraph()
    for mod, path in files.items():
        graph.add_node(mod)
        for name in imported_modules(path, mod, files):
            graph.add_edge(mod, name)
    return graph


def loops(graph: nx.DiGraph) -> list[list[str]]:
    """The import loops: each strongly connected set of more than one module. A package's
    __init__ that hands on its submodules' names is not a loop with them unless a submodule
    imports the package back."""
    return [sorted(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]


def layer_of(module: str) -> int | None:
    """The index in LAYERS of a clutterbench module (None: the package itself)."""
    parts = module.split(".")
    if len(parts) == 1:
        return None
    found = [i for i, names in enumerate(LAYERS) if parts[1] in names]
    assert found, f"{parts[1]} is in no layer of LAYERS: give it one"
    return found[0]


def upward_imports(graph: nx.DiGraph) -> list[tuple[str, str]]:
    """Every import of a module by one of a lower layer."""
    out = []
    for a, b in graph.edges:
        la, lb = layer_of(a), layer_of(b)
        if la is not None and lb is not None and lb > la:
            out.append((a, b))
    return sorted(out)


def test_every_module_has_a_layer():
    for mod in import_graph().nodes:
        layer_of(mod)


def test_no_module_imports_a_higher_layer():
    found = upward_imports(import_graph())
    assert not found, f"imports of a higher layer (LAYERS): {found}"


def test_a_higher_layer_import_is_found(tmp_path):
    """The check itself: a learning module importing the trials (as collapse/designs.py once
    imported the trials' criteria) is reported."""
    root = tmp_path / "clutterbench"
    for pkg in ("collapse", "trials"):
        (root / pkg).mkdir(parents=True)
        (root / pkg / "__init__.py").write_text("")
    (root / "__init__.py").write_text("")
    (root / "trials" / "criteria.py").write_text("x = 1\n")
    (root / "collapse" / "designs.py").write_text("from clutterbench.trials.criteria import x\n")
    assert upward_imports(import_graph(root)) == [
        ("clutterbench.collapse.designs", "clutterbench.trials.criteria")
    ]


def test_the_planners_never_import_the_simulator():
    bad = [
        (a, b)
        for a, b in import_graph().edges
        if a.startswith("clutterbench.planning") and b.startswith("clutterbench.sim")
    ]
    assert not bad, f"planning/ imports sim/ (a planner sees only what a robot sees): {bad}"


def chapter_of(module: str, package: str) -> str | None:
    """'ch6' for clutterbench.<package>.ch6.*, 'core' for trials.core.*, else None."""
    parts = module.split(".")
    if len(parts) > 2 and parts[1] == package and parts[2] in (*CHAPTERS, "core", "arm"):
        return parts[2]
    return None


@pytest.mark.parametrize("package", ["trials", "planning"])
def test_chapters_stand_on_the_core_and_not_on_each_other(package):
    """trials/core imports no chapter; a chapter's trials or planning import no other chapter's
    of the same package (the arm-level trials run ch. 4's and ch. 6's steps, so they may)."""
    bad = []
    for a, b in import_graph().edges:
        ca, cb = chapter_of(a, package), chapter_of(b, package)
        if ca is None or cb is None or ca == cb or cb == "core":
            continue
        if ca == "arm" and cb in ("ch4", "ch6"):
            continue
        bad.append((a, b))
    assert not bad, f"{package}/ chapters import each other or the core imports one: {bad}"


def test_no_import_loop_in_src():
    found = loops(import_graph())
    assert not found, f"import loops in src/: {found}"


def test_the_arm_level_imports_nothing_above_it():
    graph = import_graph()
    bad = [
        (a, b)
        for a, b in graph.edges
        if a.startswith("clutterbench.maniskill") and b.startswith(MANISKILL_MUST_NOT_IMPORT)
    ]
    assert not bad, f"maniskill/ imports the trials, planners or report: {bad}"


@pytest.mark.parametrize(
    "files",
    [
        {
            "a.py": "from clutterbench.pkg import b\n",
            "b.py": "def f():\n    import clutterbench.pkg.a\n",
        },
        {
            "a.py": "from clutterbench.pkg.b import x\n",
            "b.py": "from clutterbench.pkg.c import y\nx = 1\n",
            "c.py": "from clutterbench.pkg import a\ny = 2\n",
        },
    ],
    ids=["lazy-two", "three"],
)
def test_a_loop_is_found(tmp_path, files):
    pkg = tmp_path / "clutterbench" / "pkg"
    pkg.mkdir(parents=True)
    (pkg.parent / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    for name, text in files.items():
        (pkg / name).write_text(text)
    found = loops(import_graph(pkg.parent))
    assert found and set(found[0]) == {f"clutterbench.pkg.{n[:-3]}" for n in files}


def test_the_architecture_page_lists_the_layers_in_order():
    """docs/architecture.md's layer table names LAYERS' packages, top layer first."""
    text = (SRC.parent / "docs" / "architecture.md").read_text()
    table = text.split("<!-- layers:begin -->")[1].split("<!-- layers:end -->")[0]
    rows = [r.split("|")[2] for r in table.strip().splitlines()[2:]]
    named = [
        {n.strip("`/ ").removesuffix(".py") for n in row.split(",") if "`" in n} for row in rows
    ]
    listed = [names & set().union(*LAYERS) for names in named]
    listed = [names for names in listed if names]
    assert listed[:-1] == [set(layer) for layer in reversed(LAYERS[1:])], listed
    assert listed[-1] <= LAYERS[0], listed[-1]


def stage_imports(stages: Path = STAGES, root: Path = PACKAGE) -> dict[str, set[str]]:
    """Each stage script (stages/<stage>.py) -> the src modules it imports, lazily or through a
    string included."""
    files = {module_name(p, root.parent): p for p in root.rglob("*.py")}
    return {
        path.stem: imported_modules(path, f"stages.{path.stem}", files)
        for path in sorted(stages.glob("*.py"))
    }


def stage_violations(stages: Path = STAGES, root: Path = PACKAGE) -> list[tuple[str, str]]:
    """(stage, module) for each import of an entry point by a stage script, and of report/ by
    a stage other than REPORT_STAGE."""
    bad = []
    for stage, modules in stage_imports(stages, root).items():
        for mod in sorted(modules):
            top = mod.split(".")[1]
            if top in ENTRY_POINTS or (top == "report" and stage != REPORT_STAGE):
                bad.append((stage, mod))
    return bad


def test_every_stage_imports_no_entry_point_and_only_report_imports_report():
    assert stage_imports(), "no stage scripts found"
    found = stage_violations()
    assert not found, (
        f"stage scripts importing an entry point, or report/ outside stage report: {found}"
    )


def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    """A clutterbench package under tmp_path of `files` (path -> text), every folder a
    package."""
    root = tmp_path / "clutterbench"
    for name, text in {"__init__.py": "", **files}.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        for folder in [path.parent, *path.parent.parents]:
            if folder == root.parent:
                break
            (folder / "__init__.py").touch()
        path.write_text(text)
    return root


def test_an_import_through_a_string_is_found(tmp_path):
    """The arm level naming the trials' source as an entry point ("module:function"), a
    module path running into an attribute, and import_module of an f-string under a package
    are imports; a string that names no module below the package is not."""
    root = _package(
        tmp_path,
        {
            "trials/sources.py": "def stream_source(): ...\n",
            "planning/ch6/planners.py": "x = 1\n",
            "maniskill/tasks.py": 'DEFAULT = "clutterbench.trials.sources:stream_source"\n',
            "maniskill/executor.py": 'NAME = "clutterbench.trials.sources.stream_source"\n',
            "data/loader.py": (
                "import importlib\n"
                "def load(n):\n"
                '    return importlib.import_module(f"clutterbench.planning.ch6.{n}")\n'
            ),
            "models/__init__.py": (
                "import importlib\n"
                "def load(n):\n"
                '    return importlib.import_module(f"{__name__}.{n}")\n'
            ),
            "logs/schema.py": 'SCHEMA = "clutterbench.JsonObject"\n',
        },
    )
    assert upward_imports(import_graph(root)) == [
        ("clutterbench.data.loader", "clutterbench.planning.ch6"),
        ("clutterbench.maniskill.executor", "clutterbench.trials.sources"),
        ("clutterbench.maniskill.tasks", "clutterbench.trials.sources"),
    ]
    assert not loops(import_graph(root))


def test_a_stage_importing_report_or_an_entry_point_is_found(tmp_path):
    """A trials stage drawing its figure with report/'s code, a stage reaching the CLI, lazily,
    are found; the report stage importing report/ is not."""
    root = _package(
        tmp_path,
        {"report/figure.py": "x = 1\n", "cli/main.py": "y = 2\n", "trials/run.py": "z = 3\n"},
    )
    stages = tmp_path / "stages"
    stages.mkdir()
    (stages / "trials.py").write_text(
        "from clutterbench.trials.run import z\n"
        "def main():\n"
        "    from clutterbench.report.figure import x\n"
    )
    (stages / "noise.py").write_text('ENTRY = "clutterbench.cli.main:y"\n')
    (stages / "report.py").write_text("from clutterbench.report import figure\n")
    assert stage_violations(stages, root) == [
        ("noise", "clutterbench.cli.main"),
        ("trials", "clutterbench.report.figure"),
    ]

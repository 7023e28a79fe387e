"""One direction of imports in src/ (docs/architecture.md): every module imports only its own
layer or those below it (LAYERS), no module imports another that imports it back, however long
the loop, the planners never import the simulator, and the chapters' trials and planning
subpackages stand on a shared core without importing each other. Imports inside functions
count: a lazy import is still a dependency that can break."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGE = SRC / "clutterbench"
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
        "trials support",  # the world and the planner together; Table 6.2 offline
        "report",  # tables and figures from records
        "envs cli bench dev crosscheck readme",  # entry points over everything
    )
)
"""src/clutterbench's top-level modules and packages, lowest first: a module may import its own
layer and the ones below it, never one above (docs/architecture.md draws the same order)."""
CHAPTERS = ("ch3", "ch4", "ch5", "ch6")


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


def import_graph(root: Path = PACKAGE) -> nx.DiGraph:
    """module -> the clutterbench modules it imports (only names that are modules)."""
    files = {module_name(p, root.parent): p for p in root.rglob("*.py")}
    graph = nx.DiGraph()
    for mod, path in files.items():
        graph.add_node(mod)
        package = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
        for name in imported_names(ast.parse(path.read_text()), package):
            if name in files and name != mod:
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

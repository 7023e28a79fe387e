"""One direction of imports in src/ (docs/architecture.md): no module imports another that
imports it back, however long the loop, and the arm level (maniskill/) stands below the
trials, the planners and the report. Imports inside functions count: a lazy import is still a
dependency that can break."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGE = SRC / "clutterbench"
MANISKILL_MUST_NOT_IMPORT = ("clutterbench.trials", "clutterbench.planning", "clutterbench.report")


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

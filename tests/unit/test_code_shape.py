"""The shape a maintainer can find their way in: no function in src/, stages/ or experiments/
over 80 lines, no module over 500 unless it is one concept (named below, with why), and stages
thin (their logic in src/)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 500
MAX_STAGE_LINES = 110
ONE_CONCEPT = {
    "src/clutterbench/maniskill/tasks.py": "the ManiSkill tasks built from a spec, one registry",
    "src/clutterbench/planning/ch5/replenish.py": "the replenishment planner of thesis 5.2.3",
    "src/clutterbench/sim/labelling.py": "one labelled scene: place, settle, render, act",
    "src/clutterbench/report/table_6_3.py": "Table 6.3 and its per-family companion",
    "src/clutterbench/sim/pile.py": "the chapter 3 pile world: pieces, slide, judge, cameras",
}
"""Modules over MAX_MODULE_LINES that hold one concept, and which."""


def python_files() -> list[Path]:
    return sorted(
        [*(ROOT / "src").rglob("*.py"), *(ROOT / "stages").glob("*.py"), *experiment_files()]
    )


def experiment_files() -> list[Path]:
    """The rechecks' modules (experiments/*.py), not their reports' scripts."""
    return sorted((ROOT / "experiments").glob("*.py"))


def long_functions(text: str, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """(name, lines) of every function or method longer than `limit` lines."""
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            lines = node.end_lineno - node.lineno + 1
            if lines > limit:
                out.append((node.name, lines))
    return out


def test_a_long_function_is_found():
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    assert long_functions(f"def f():\n{body}") == [("f", MAX_FUNCTION_LINES + 1)]
    assert long_functions(f"def f():\n{body[: body.rindex('    x')]}") == []


def test_no_function_is_over_80_lines():
    found = [
        f"{p.relative_to(ROOT)}:{name} ({n})"
        for p in python_files()
        for name, n in long_functions(p.read_text())
    ]
    assert not found, f"functions over {MAX_FUNCTION_LINES} lines: {found}"


def test_no_module_is_over_500_lines_unless_one_concept():
    found = {
        str(p.relative_to(ROOT)): n
        for p in python_files()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    }
    unexplained = {k: v for k, v in found.items() if k not in ONE_CONCEPT}
    assert not unexplained, f"modules over {MAX_MODULE_LINES} lines: {unexplained}"
    stale = sorted(set(ONE_CONCEPT) - set(found))
    assert not stale, f"ONE_CONCEPT names modules now under {MAX_MODULE_LINES} lines: {stale}"


@pytest.mark.parametrize("stage", sorted(p.name for p in (ROOT / "stages").glob("*.py")))
def test_stages_are_thin(stage):
    n = len((ROOT / "stages" / stage).read_text().splitlines())
    assert n <= MAX_STAGE_LINES, f"stages/{stage}: {n} lines; move its logic into src/"

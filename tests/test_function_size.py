"""No function is too long or too branched to read without a stated reason (docs/design.md §2.3).

A function of the packages ends at most :data:`MAX_LINES` lines (its docstring not
counted) and has a cyclomatic complexity of at most :data:`MAX_COMPLEXITY` (ruff's
mccabe rule, C901), unless its docstring says why it is longer ("long because ...").
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hasa_env", "estimators", "advisor_tasks", "benchmarks", "hasa_cli")
MAX_LINES = 80
MAX_COMPLEXITY = 25
REASON = "long because"


def _functions(tree: ast.AST) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]


def _says_why(node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    return REASON in (ast.get_docstring(node) or "").lower()


def body_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines from ``def`` to the function's end, its docstring not counted."""
    assert node.end_lineno is not None
    length = node.end_lineno - node.lineno + 1
    first = node.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
        if isinstance(first.value.value, str):
            assert first.end_lineno is not None
            length -= first.end_lineno - first.lineno + 1
    return length


def long_functions(paths: list[Path]) -> list[str]:
    """``path:line name: N lines`` of every function over the limit without a reason."""
    found = []
    for path in paths:
        for node in _functions(ast.parse(path.read_text(encoding="utf-8"))):
            n = body_lines(node)
            if n > MAX_LINES and not _says_why(node):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {n} lines")
    return found


def complex_functions(paths: list[Path]) -> list[str]:
    """ruff's C901 findings above :data:`MAX_COMPLEXITY` of functions without a reason."""
    result = subprocess.run(
        ["ruff", "check", "--no-cache", "--select", "C901", "--output-format", "concise",
         "--config", f"lint.mccabe.max-complexity={MAX_COMPLEXITY}", *map(str, paths)],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    found = []
    for line in result.stdout.splitlines():
        match = re.match(r"(.+?):(\d+):\d+: C901 `(\w+)` is too complex \((\d+) > \d+\)", line)
        if not match:
            continue
        file, lineno, name, complexity = match.groups()
        path = Path(file) if Path(file).is_absolute() else ROOT / file
        tree = ast.parse(path.read_text(encoding="utf-8"))
        node = next(n for n in _functions(tree) if n.lineno == int(lineno))
        if not _says_why(node):
            found.append(f"{path.relative_to(ROOT)}:{lineno} {name}: complexity {complexity}")
    return found


def _sources() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def test_no_function_over_the_line_limit_without_a_reason():
    found = long_functions(_sources())
    assert not found, (
        f"functions over {MAX_LINES} lines (docstring excluded); split them, or say "
        f'"{REASON} ..." in the docstring:\n' + "\n".join(found)
    )


@pytest.mark.skipif(shutil.which("ruff") is None, reason="ruff not installed")
def test_no_function_over_the_complexity_limit_without_a_reason():
    found = complex_functions(_sources())
    assert not found, (
        f"functions over cyclomatic complexity {MAX_COMPLEXITY}; split them, or say "
        f'"{REASON} ..." in the docstring:\n' + "\n".join(found)
    )


@pytest.mark.skipif(shutil.which("ruff") is None, reason="ruff not installed")
def test_the_checks_can_fail(tmp_path):
    """A long, branched function without a reason is found; with one it is not."""
    branches = "".join(f"    if x == {i}:\n        return {i}\n" for i in range(45))
    plain = tmp_path / "plain.py"
    plain.write_text(f'def f(x):\n    """Pick."""\n{branches}    return -1\n', encoding="utf-8")
    excused = tmp_path / "excused.py"
    excused.write_text(
        f'def f(x):\n    """Pick; long because it is a table.\n\n    More.\n    """\n'
        f"{branches}    return -1\n",
        encoding="utf-8",
    )
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert long_functions([plain]) == ["plain.py:1 f: 92 lines"]
        assert long_functions([excused]) == []
        assert complex_functions([plain]) == ["plain.py:1 f: complexity 46"]
        assert complex_functions([excused]) == []
    finally:
        ROOT = saved

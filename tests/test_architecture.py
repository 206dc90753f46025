"""The architecture of docs/design.md §2, checked: layers, no cycles, no hidden imports.

- import-linter's contracts in pyproject.toml (layers between and inside the
  packages, no cycles between sibling modules or packages) hold;
- independently of it, no module of ``hasa_env`` imports ``estimators``,
  ``advisor_tasks``, ``benchmarks`` or ``hasa_cli``, at module level or inside a function;
- imports inside functions are kept for optional or heavy dependencies
  (pygame on paths that must stay headless, the optional extras), each with a
  one-line reason on the import's line;
- no module imports another module's private (``_name``) names: what is shared
  is public and documented (a private *module* such as ``hasa_env._lazy`` may be
  imported whole).
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hasa_env", "estimators", "advisor_tasks", "benchmarks", "hasa_cli")
ABOVE_HASA_ENV = ("estimators", "advisor_tasks", "benchmarks", "hasa_cli")
"""The packages above hasa_env (docs/design.md §2)."""

LOCAL_IMPORTS_ALLOWED = {
    "pygame": "SDL: never loaded on headless paths",
    "evdev": "optional: force feedback on Linux",
    "minari": "optional extra 'minari'",
    "pyarrow": "optional extras 'parquet' / 'minari'",
    "imageio": "optional: videos",
    "stable_baselines3": "optional extra 'rl' (torch)",
    "torch": "optional extra 'rl'",
    "distributed": "optional extra 'dask'",
    "highway_env": "optional extra 'compare'",
}
"""Top-level modules that may be imported inside a function, and why."""
START_UP = "# start-up"
"""In :mod:`hasa_cli` anything may be imported inside the function that needs it when the line
says ``# start-up: ...``: a program's ``--help``, a usage error and a light subcommand must not
wait seconds for the benchmark's or the estimators' imports (issue 21)."""


def _modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _imports(tree: ast.AST) -> list[tuple[ast.Import | ast.ImportFrom, bool]]:
    """Every import statement of a module and whether it sits inside a function."""
    found: list[tuple[ast.Import | ast.ImportFrom, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import | ast.ImportFrom):
                found.append((child, in_function))
            inside = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            visit(child, inside)

    visit(tree, False)
    return found


def _imported_names(node: ast.Import | ast.ImportFrom) -> list[str]:
    if isinstance(node, ast.ImportFrom):
        return [node.module or ""] if node.level == 0 else []
    return [alias.name for alias in node.names]


@pytest.mark.skipif(shutil.which("lint-imports") is None, reason="import-linter not installed")
def test_import_linter_contracts_hold():
    result = subprocess.run(
        ["lint-imports", "--no-cache", "--config", str(ROOT / "pyproject.toml")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "BROKEN" not in result.stdout and "0 broken" in result.stdout


@pytest.mark.parametrize("path", _modules("hasa_env"), ids=lambda p: str(p.relative_to(ROOT)))
def test_hasa_env_never_imports_the_layers_above_it(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    above = [
        (node.lineno, name)
        for node, _ in _imports(tree)
        for name in _imported_names(node)
        if name.split(".")[0] in ABOVE_HASA_ENV
    ]
    assert not above, f"{path.relative_to(ROOT)} imports an upper layer: {above}"


def test_hasa_env_names_no_package_above_it():
    """Not even in a string, a docstring or an entry point: the bottom layer knows nothing
    of the layers above (the advisor task registers its own ids)."""
    pattern = re.compile(r"\b(" + "|".join(ABOVE_HASA_ENV) + r")\b")
    naming = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for path in _modules("hasa_env")
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not naming, "hasa_env names a package above it:\n" + "\n".join(naming)


def test_function_level_imports_are_few_and_say_why():
    offenders = []
    for package in PACKAGES:
        for path in _modules(package):
            text = path.read_text(encoding="utf-8")
            lines = text.splitlines()
            for node, in_function in _imports(ast.parse(text)):
                if not in_function:
                    continue
                names = _imported_names(node)
                where = f"{path.relative_to(ROOT)}:{node.lineno}"
                if package == "hasa_cli" and START_UP in lines[node.lineno - 1]:
                    continue
                if not names or any(n.split(".")[0] not in LOCAL_IMPORTS_ALLOWED for n in names):
                    offenders.append(f"{where}: {lines[node.lineno - 1].strip()} (not optional)")
                elif "#" not in lines[node.lineno - 1]:
                    offenders.append(f"{where}: {lines[node.lineno - 1].strip()} (no reason)")
    assert not offenders, "function-level imports:\n" + "\n".join(offenders)


def test_the_checks_above_can_fail(tmp_path):
    """The AST scan sees an import of an upper layer inside a function."""
    module = "def f():\n    from estimators import base  # sneaky\n    return base\n"
    tree = ast.parse(module)
    ((node, in_function),) = _imports(tree)
    assert in_function and _imported_names(node) == ["estimators"]


def _private_names_imported(tree: ast.AST, package_dir: Path) -> list[tuple[int, str]]:
    """(line, "module._name") of each ``from module import _name`` that takes a private
    name: not ``__future__``, not a dunder, not a private module (``from pkg import _lazy``
    where ``pkg/_lazy.py`` exists). ``package_dir``: the directory of the importing module,
    for relative imports."""
    found = []
    for node, _ in _imports(tree):
        if not isinstance(node, ast.ImportFrom) or node.module == "__future__":
            continue
        if node.level:
            base = package_dir
            for _ in range(node.level - 1):
                base = base.parent
        else:
            base = ROOT
        source = base.joinpath(*(node.module or "").split(".")) if node.module else base
        for alias in node.names:
            name = alias.name
            if not name.startswith("_") or (name.startswith("__") and name.endswith("__")):
                continue
            if (source / f"{name}.py").is_file() or (source / name / "__init__.py").is_file():
                continue  # a private module of the package, imported whole
            found.append((node.lineno, f"{'.' * node.level}{node.module or ''}.{name}"))
    return found


def test_no_module_imports_a_private_name_of_another():
    """``from x import _y`` is an error in every package: share public, documented names."""
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for package in PACKAGES
        for path in _modules(package)
        for line, name in _private_names_imported(
            ast.parse(path.read_text(encoding="utf-8")), path.parent
        )
    ]
    assert not offenders, "private names imported across modules:\n" + "\n".join(offenders)


def test_the_private_import_check_can_fail():
    """It flags a private function and allows a private module, dunders and __future__."""
    module = (
        "from __future__ import annotations\n"
        "from hasa_env import _lazy\n"
        "from hasa_env.recording.format import __all__, _versions\n"
        "def f():\n    from .format import _json_default  # hidden\n"
    )
    found = _private_names_imported(ast.parse(module), ROOT / "hasa_env" / "recording")
    assert found == [(3, "hasa_env.recording.format._versions"), (5, ".format._json_default")]


def test_long_modules_say_why():
    """No module over about 600 lines without a stated reason in its docstring."""
    long = []
    for package in PACKAGES:
        for path in _modules(package):
            text = path.read_text(encoding="utf-8")
            if text.count("\n") > 620:
                doc = ast.get_docstring(ast.parse(text)) or ""
                if "Why this module is long" not in doc:
                    long.append(f"{path.relative_to(ROOT)} ({text.count(chr(10))} lines)")
    assert not long, "long modules without a reason: " + ", ".join(long)


def test_no_module_cites_a_design_document_outside_the_repository():
    """Docstrings cite docs/design.md (in the repository), never a DESIGN.md."""
    citing = [
        str(path.relative_to(ROOT))
        for package in PACKAGES
        for path in _modules(package)
        if "DESIGN.md" in path.read_text(encoding="utf-8")
    ]
    assert not citing, f"cite docs/design.md instead of DESIGN.md in: {citing}"


def _design_section_numbers(text: str) -> list[str]:
    """The number of every ``## N.`` / ``### N.M`` heading of ``text``, in order."""
    numbers = []
    for line in text.splitlines():
        match = re.match(r"#{2,3} (\d+(?:\.\d+)?)[. ]", line)
        if match:
            numbers.append(match.group(1))
    return numbers


def _duplicated(numbers: list[str]) -> list[str]:
    return sorted({n for n in numbers if numbers.count(n) > 1})


def test_the_duplicate_section_check_can_fail():
    text = "## 9. Bench\n### 9.7 Bad input\n### 9.8 Safety\n### 9.7 Studies\n#### 9.7.1 x\n"
    assert _design_section_numbers(text) == ["9", "9.7", "9.8", "9.7"]
    assert _duplicated(_design_section_numbers(text)) == ["9.7"]


def test_every_design_citation_resolves_to_a_section():
    """Each ``docs/design.md §N`` / ``§N.M`` (ranges and lists too) names a section that exists,
    and no two sections share a number (a citation must name one section)."""
    numbers = _design_section_numbers((ROOT / "docs" / "design.md").read_text(encoding="utf-8"))
    assert not _duplicated(numbers), f"section numbers used twice: {_duplicated(numbers)}"
    sections = set(numbers)
    assert {"2", "3", "5.7", "8.5", "10", "11"} <= sections
    citation = re.compile(r"docs/design\.md((?:[ ,;]*(?:and )?§\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)?)+)")
    files = [p for package in PACKAGES for p in _modules(package)]
    files += sorted((ROOT / "tests").glob("*.py")) + sorted((ROOT / "examples").glob("*.py"))
    files += [ROOT / "README.md", ROOT / "recordings" / "README.md"]
    bad, cited = [], 0
    for path in files:
        text = path.read_text(encoding="utf-8")
        for match in citation.finditer(text):
            for number in re.findall(r"\d+(?:\.\d+)?", match.group(1)):
                cited += 1
                if number not in sections:
                    bad.append(f"{path.relative_to(ROOT)}: §{number}")
    assert cited > 20, "found almost no citations: is the pattern right?"
    assert not bad, "citations of sections that do not exist: " + ", ".join(bad)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__]))

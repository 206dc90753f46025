"""The JSON Schemas of a hasa-bench result folder, and checks against them.

``results.schema.json`` describes ``results.json`` (every field with its unit and
meaning; docs/results.md is rendered from it by :func:`markdown_fields`);
``tables.schema.json`` describes the CSV tables as lists of rows whose columns are
the fields of the matching list in ``results.json``. Both ship with the package:
``importlib.resources.files("benchmarks.schema")``.

``hasa-bench`` checks its own ``results.json`` against the schema when it writes it
(:func:`benchmarks.report.write_outputs`), so a field that changes without the schema
is caught where it is made. ``python -m benchmarks.schema FOLDER`` checks a folder;
``python -m benchmarks.schema --markdown`` prints docs/results.md's field tables.
"""

from __future__ import annotations

import csv
import json
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from jsonschema import Draft202012Validator
from referencing import Registry, Resource

__all__ = [
    "RESULTS_SCHEMA",
    "TABLES_SCHEMA",
    "ResultsSchemaError",
    "folder_problems",
    "load_schema",
    "markdown_fields",
    "read_table",
    "results_problems",
    "table_problems",
]

RESULTS_SCHEMA = "results.schema.json"
TABLES_SCHEMA = "tables.schema.json"


class ResultsSchemaError(ValueError):
    """A result that does not follow the shipped schema (``problems``: one line each)."""

    def __init__(self, problems: list[str]) -> None:
        shown = "; ".join(problems[:3]) + (
            f"; and {len(problems) - 3} more" if len(problems) > 3 else ""
        )
        super().__init__(f"does not follow the shipped schema: {shown}")
        self.problems = problems


@cache
def load_schema(name: str = RESULTS_SCHEMA) -> dict[str, Any]:
    """The shipped schema ``name`` (``results.schema.json`` or ``tables.schema.json``)."""
    text = resources.files(__name__).joinpath(name).read_text(encoding="utf-8")
    return dict(json.loads(text))


@cache
def _validator(name: str) -> Any:
    registry: Registry = Registry().with_resources(
        (load_schema(n)["$id"], Resource.from_contents(load_schema(n)))
        for n in (RESULTS_SCHEMA, TABLES_SCHEMA)
    )
    return Draft202012Validator(load_schema(name), registry=registry)


def _problems(name: str, instance: Any, where: str, skip: int = 0) -> list[str]:
    """One line per schema violation: ``where``, the path in ``instance`` (its first ``skip``
    parts left out; with ``skip``, a CSV table's row index as its line number) and what is
    wrong."""
    errors = sorted(_validator(name).iter_errors(instance), key=lambda e: list(map(str, e.path)))
    out = []
    for e in errors:
        parts = list(e.absolute_path)[skip:]
        if skip and parts:
            line = f" line {int(parts[0]) + 2}"  # the header is line 1
            path = line + (f", column {parts[1]}" if len(parts) > 1 else "")
        else:
            path = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in parts)
        out.append(f"{where}{path or ' (top level)'}: {e.message}")
    return out


def results_problems(doc: Any, where: str = "results.json") -> list[str]:
    """Every place where ``doc`` (a parsed results.json) breaks the schema, one line each
    (``results.json.summary[2].lateral_rmse: 'x' is not of type 'number', 'null'``)."""
    return _problems(RESULTS_SCHEMA, doc, where)


def _row_schema(table: str) -> dict[str, Any]:
    ref = load_schema(TABLES_SCHEMA)["properties"][table]["items"]["$ref"]
    return dict(load_schema(RESULTS_SCHEMA)["$defs"][ref.rsplit("/", 1)[1]])


def table_problems(table: str, rows: list[dict[str, Any]], where: str | None = None) -> list[str]:
    """Every place where the rows of CSV table ``table`` (e.g. ``"summary.csv"``) break the
    schema; ``where`` names them in the messages (default: the table)."""
    if table not in load_schema(TABLES_SCHEMA)["properties"]:
        return [f"{where or table}: not a table of a hasa-bench result"]
    return _problems(TABLES_SCHEMA, {table: rows}, where or table, skip=1)


def _typed(value: str, types: Any) -> Any:
    """A CSV cell as the JSON value its column's schema type says (empty: null)."""
    kinds = types if isinstance(types, list) else [types]
    if value == "":
        return None
    if "array" in kinds and value.startswith("["):
        try:
            return json.loads(value)
        except ValueError:
            return value
    if "boolean" in kinds and value in ("True", "False"):
        return value == "True"
    if "integer" in kinds or "number" in kinds:
        try:
            number = float(value)
        except ValueError:
            return value
        return int(number) if "number" not in kinds and number.is_integer() else number
    return value


def read_table(path: str | Path) -> list[dict[str, Any]]:
    """The rows of a hasa-bench CSV table, each cell typed by its column's schema (an empty
    cell is null; a column the schema does not know stays text)."""
    path = Path(path)
    properties = _row_schema(path.name)["properties"]
    with path.open(newline="", encoding="utf-8") as fh:
        return [
            {k: _typed(v, properties.get(k, {}).get("type", "string")) for k, v in row.items()}
            for row in csv.DictReader(fh)
        ]


def folder_problems(folder: str | Path) -> list[str]:
    """Every place where ``folder``'s results.json and CSV tables break the schemas."""
    folder = Path(folder)
    problems: list[str] = []
    doc_path = folder / "results.json"
    if doc_path.is_file():
        try:
            doc = json.loads(doc_path.read_text(encoding="utf-8"))
        except ValueError as exc:
            return [f"{doc_path}: not JSON ({exc})"]
        problems += results_problems(doc, str(doc_path))
    else:
        problems.append(f"{doc_path}: no such file (not a hasa-bench result folder)")
    for table in load_schema(TABLES_SCHEMA)["properties"]:
        if (folder / table).is_file():
            problems += table_problems(table, read_table(folder / table), str(folder / table))
    return problems


def markdown_fields() -> str:
    """docs/results.md's field lists, rendered from the schema's descriptions."""
    schema = load_schema(RESULTS_SCHEMA)
    lines = ["## results.json", "", schema["description"], ""]
    lines += _field_list(schema["properties"])
    nested = {k: v for k, v in schema["properties"].items() if "properties" in v}
    for name, part in [*nested.items(), *schema["$defs"].items()]:
        title = part.get("title") or part.get("description", name).capitalize()
        lines += ["", f"### `{name}`", "", title + ".", ""]
        lines += _field_list(part.get("properties", {}))
    return "\n".join(lines) + "\n"


def _field_list(properties: dict[str, Any]) -> list[str]:
    lines = ["| field | type | meaning [unit] |", "|:---|:---|:---|"]
    for key, spec in properties.items():
        kind = spec.get("type") or (
            "constant " + json.dumps(spec["const"]) if "const" in spec else ""
        )
        items = spec.get("items", {})
        if "$ref" in items:
            kind = f"list of `{items['$ref'].rsplit('/', 1)[1]}`"
        elif "type" in items:
            kind = f"list of {items['type']}"
        kind = " or ".join(kind) if isinstance(kind, list) else kind
        meaning = spec.get("description", "").replace("|", "\\|")
        lines.append(f"| `{key}` | {kind} | {meaning} |")
    return lines

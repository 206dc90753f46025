"""The one table renderer of the benchmarks: plain text for the terminal, Markdown and HTML
for reports.

A table is a list of row dicts and a list of :class:`Column` (which key,
which header, how to format, left or right aligned). ``hasa-bench paper``'s
tables and ``hasa-bench perf``'s table both go through :func:`render_text` /
:func:`render_markdown`. (pandas' ``to_string`` aligns every column the same
way and ``to_markdown`` needs the tabulate package; the renderer is the
twenty lines below.)
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "Column",
    "count_share",
    "fixed",
    "interval",
    "markdown_cell",
    "missing",
    "percent",
    "render_html",
    "render_markdown",
    "render_text",
    "scientific",
    "text",
]


def missing(value: Any) -> bool:
    """None or a non-finite float: shown as "-"."""
    return value is None or (isinstance(value, float) and not math.isfinite(value))


def scientific(value: Any) -> str:
    return "-" if missing(value) else f"{value:.2e}"


def fixed(digits: int) -> Callable[[Any], str]:
    return lambda v: "-" if missing(v) else f"{v:.{digits}f}"


def percent(value: Any) -> str:
    return "-" if missing(value) else f"{100 * value:.0f}%"


def text(value: Any) -> str:
    return "-" if value is None else str(value)


def interval(fmt: Callable[[Any], str], key: str) -> Callable[[dict[str, Any]], str]:
    """A cell ``mean [low, high]`` from a row's ``key``, ``key_ci_low``, ``key_ci_high``."""

    def cell(row: dict[str, Any]) -> str:
        mean, low, high = row.get(key), row.get(f"{key}_ci_low"), row.get(f"{key}_ci_high")
        if missing(mean):
            return "-"
        if missing(low) or missing(high):
            return fmt(mean)
        return f"{fmt(mean)} [{fmt(low)}, {fmt(high)}]"

    return cell


def count_share(count: str, total: str) -> Callable[[dict[str, Any]], str]:
    """A cell ``k/n [low%, high%]`` from a row's ``count``, ``total`` and the share's interval
    ``{count}_share_ci_low`` / ``{count}_share_ci_high`` (``k/n`` alone without them)."""

    def cell(row: dict[str, Any]) -> str:
        k: Any = row.get(count)
        n: Any = row.get(total)
        if missing(k) or missing(n):
            return "-"
        low: Any = row.get(f"{count}_share_ci_low")
        high: Any = row.get(f"{count}_share_ci_high")
        if missing(low) or missing(high):
            return f"{int(k)}/{int(n)}"
        return f"{int(k)}/{int(n)} [{100 * low:.1f}%, {100 * high:.1f}%]"

    return cell


@dataclass(frozen=True)
class Column:
    """One column: ``key`` (a row key, or a function of the row), header, cell format."""

    key: str | Callable[[dict[str, Any]], Any]
    header: str
    fmt: Callable[[Any], str] = text
    left: bool = False

    def cell(self, row: dict[str, Any]) -> str:
        value = self.key(row) if callable(self.key) else row.get(self.key)
        return self.fmt(value)


def render_text(
    rows: Sequence[dict[str, Any]], columns: Sequence[Column], group: str | None = None
) -> str:
    """Aligned plain text; a blank line between rows whose ``group`` key changes."""
    cells = [[c.cell(r) for c in columns] for r in rows]
    widths = [
        max([len(c.header)] + [len(line[i]) for line in cells]) for i, c in enumerate(columns)
    ]

    def line(values: Sequence[str]) -> str:
        parts = [
            v.ljust(w) if c.left else v.rjust(w)
            for v, w, c in zip(values, widths, columns, strict=True)
        ]
        return "  ".join(parts).rstrip()

    out = [line([c.header for c in columns]), "  ".join("-" * w for w in widths)]
    previous = None
    for row, values in zip(rows, cells, strict=True):
        if group is not None:
            if previous is not None and row.get(group) != previous:
                out.append("")
            previous = row.get(group)
        out.append(line(values))
    return "\n".join(out)


def markdown_cell(value: str) -> str:
    """``value`` as the text of a pipe-table cell: ``|`` escaped as ``\\|`` (GitHub Flavored
    Markdown's escape, so it stays in its cell), a line break as a space (it would end the row)."""
    return " ".join(value.replace("|", "\\|").splitlines())


def render_markdown(rows: Sequence[dict[str, Any]], columns: Sequence[Column]) -> str:
    """A Markdown (pipe) table; every header and cell through :func:`markdown_cell`."""
    head = "| " + " | ".join(markdown_cell(c.header) for c in columns) + " |"
    rule = "|" + "|".join(":---" if c.left else "---:" for c in columns) + "|"
    body = [
        "| " + " | ".join(markdown_cell(c.cell(r)) or " " for c in columns) + " |" for r in rows
    ]
    return "\n".join([head, rule, *body])


def render_html(
    rows: Sequence[dict[str, Any]], columns: Sequence[Column], caption: str | None = None
) -> str:
    """An HTML ``<table>`` of the same cells as :func:`render_markdown` (every text escaped);
    right-aligned columns get ``class="num"``."""

    def attr(c: Column) -> str:
        return "" if c.left else ' class="num"'

    head = "".join(f"<th{attr(c)}>{html.escape(c.header)}</th>" for c in columns)
    body = [
        "<tr>" + "".join(f"<td{attr(c)}>{html.escape(c.cell(r))}</td>" for c in columns) + "</tr>"
        for r in rows
    ]
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return "\n".join(
        [f"<table>{cap}", f"<thead><tr>{head}</tr></thead>", "<tbody>", *body, "</tbody></table>"]
    )

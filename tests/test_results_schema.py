"""The shipped schemas of a hasa-bench result, its documentation, and the HTML report.

One tiny ``hasa-bench paper`` run, as a user starts it (a subprocess in a fresh working
directory, default output folder), is checked against the schemas, and its report.html is
checked for self-containment and loaded in a real headless browser (Chromium).
"""

from __future__ import annotations

import base64
import copy
import dataclasses
import json
import os
import re
import shutil
import struct
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest
from _programs import run_program
from jsonschema import Draft202012Validator

import benchmarks.protocol
from benchmarks.figures import FIGURES
from benchmarks.protocol import BenchmarkResult
from benchmarks.report import CSV_TABLES, write_outputs
from benchmarks.scenario_suite import html_suite
from benchmarks.schema import (
    RESULTS_SCHEMA,
    TABLES_SCHEMA,
    folder_problems,
    load_schema,
    markdown_fields,
    read_table,
    results_problems,
    table_problems,
)
from benchmarks.tables import Column, fixed, render_html, render_markdown
from hasa_cli import bench

ROOT = Path(__file__).resolve().parent.parent
TINY = ["--seeds", "0", "--population", "paper-pi", "--drivers", "1", "--runs", "1",
        "--ill-runs", "2", "--duration", "2", "--curved-runs", "1", "--workers", "1"]  # fmt: skip


def _figures(folder: Path) -> list[str]:
    """The figure files of a result folder, in the report's order."""
    return [name for name in FIGURES.values() if (folder / name).is_file()]


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``hasa-bench paper`` with tiny inputs, run as a user would, in a fresh folder (about
    10 s of CPU: the tests that use it are marked slow)."""
    cwd = tmp_path_factory.mktemp("user")
    done = run_program("hasa-bench", "paper", *TINY, "--quiet", cwd=cwd, timeout=300)
    assert done.returncode == 0, done.stderr
    return cwd / "hasa-bench-results"


# ---------------------------------------------------------------------- schemas
def test_the_shipped_schemas_are_valid_and_every_csv_table_has_one() -> None:
    for name in (RESULTS_SCHEMA, TABLES_SCHEMA):
        Draft202012Validator.check_schema(load_schema(name))
    tables = set(load_schema(TABLES_SCHEMA)["properties"])
    assert set(CSV_TABLES.values()) | {"scenarios.csv"} == tables
    assert load_schema()["properties"]["format_version"]["const"] == 3
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert '"benchmarks.schema" = ["*.json"]' in pyproject and '"jsonschema' in pyproject


def test_every_field_has_a_meaning_and_the_docs_are_generated_from_the_schema() -> None:
    schema = load_schema()
    parts = [schema["properties"], schema["properties"]["config"]["properties"]]
    parts += [d.get("properties", {}) for d in schema["$defs"].values()]
    undocumented = [k for part in parts for k, v in part.items() if not v.get("description")]
    assert not undocumented
    docs = (ROOT / "docs" / "results.md").read_text()
    assert docs.endswith(markdown_fields()), "run: python -m benchmarks.schema --markdown"
    assert "docs/results.md" in (ROOT / "README.md").read_text()


@pytest.mark.slow
def test_a_tiny_run_follows_the_schemas_and_writes_the_html_report(run_folder: Path) -> None:
    assert folder_problems(run_folder) == []
    for name in ("results.json", "report.md", "report.html", *CSV_TABLES.values()):
        assert (run_folder / name).is_file(), name
    summary = read_table(run_folder / "summary.csv")
    doc = json.loads((run_folder / "results.json").read_text())
    assert [r["model"] for r in summary] == [r["model"] for r in doc["summary"]]
    assert summary[0]["rmse"] == pytest.approx(doc["summary"][0]["rmse"], rel=1e-12)


@pytest.mark.slow
def test_what_breaks_the_schema_is_named(run_folder: Path, tmp_path: Path) -> None:
    doc = json.loads((run_folder / "results.json").read_text())
    bad = copy.deepcopy(doc)
    bad["summary"][1]["lateral_rmse"] = "small"
    bad["steering"][0]["new_column"] = 1.0
    del bad["runs_estimation"][2]["final_decision"]
    bad["runs_estimation"][3]["final_decision"] = "maybe"
    problems = results_problems(bad)
    assert len(problems) == 4
    assert any(p.startswith("results.json.summary[1].lateral_rmse: 'small'") for p in problems)
    assert any("steering[0]" in p and "'new_column' was unexpected" in p for p in problems)
    assert any(
        "runs_estimation[2]" in p and "'final_decision' is a required" in p for p in problems
    )
    assert any("runs_estimation[3].final_decision: 'maybe'" in p for p in problems)
    # a CSV cell: named by file, line and column
    rows = read_table(run_folder / "steering.csv")
    rows[1]["n_runs"] = "two"
    assert table_problems("steering.csv", rows) == [
        "steering.csv line 3, column n_runs: 'two' is not of type 'integer'"
    ]
    folder = tmp_path / "copy"
    shutil.copytree(run_folder, folder)
    (folder / "results.json").write_text(json.dumps(bad))
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.schema", str(folder)],
        env=os.environ | {"PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
        timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 1
    assert done.stderr.count("benchmarks.schema: error: ") == 4


# ------------------------------------------------------------------ HTML report
class _Page(HTMLParser):
    """Tables (header row, body rows of cell texts), images and links of an HTML page."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self.images: list[dict[str, str | None]] = []
        self.links: list[str] = []
        self.tags: set[str] = set()
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.add(tag)
        values = dict(attrs)
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "img":
            self.images.append(values)
        for key in ("href", "src", "action", "srcset", "poster", "data"):
            if values.get(key) and tag != "img":
                self.links.append(str(values[key]))

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append("".join(self._cell))
            self._cell = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def _parse(text: str) -> _Page:
    page = _Page()
    page.feed(text)
    return page


def _markdown_tables(text: str) -> list[list[list[str]]]:
    """The pipe tables of report.md as rows of cells (the rule line left out)."""
    tables, current = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("| "):  # cells split at the pipes not escaped as \|
            cells = re.split(r"(?<!\\)\|", line.strip()[1:-1])
            current.append([c.strip().replace("\\|", "|") for c in cells])
        elif line.startswith("|:---") or line.startswith("|---"):
            continue
        elif current:
            tables.append(current)
            current = []
    return tables


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


@pytest.mark.slow
def test_the_html_report_shows_the_markdown_reports_cells_and_needs_nothing_outside(
    run_folder: Path,
) -> None:
    text = (run_folder / "report.html").read_text(encoding="utf-8")
    page = _parse(text)
    # the same table cells as report.md (the same Column objects render both)
    assert page.tables == _markdown_tables((run_folder / "report.md").read_text())
    assert len(page.tables) >= 7
    # self-contained: no script, no stylesheet or frame to fetch, no URL anywhere
    assert not page.tags & {"script", "link", "iframe", "object", "embed", "base"}
    outside = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", text)
    assert not re.search(r"https?:|ftp:|file:|//", outside, re.IGNORECASE)
    assert not page.links and "@import" not in text and "url(" not in text
    # every figure embedded as a PNG that decodes, as the figure file itself
    assert len(_figures(run_folder)) == len(FIGURES)  # the tiny run draws every figure
    for image, name in zip(page.images, _figures(run_folder), strict=True):
        src = str(image["src"])
        assert src.startswith("data:image/png;base64,")
        data = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert data == (run_folder / name).read_bytes()
        assert min(_png_size(data)) > 100
        assert image["alt"]


def _chromium() -> str | None:
    return next((p for n in ("chromium", "chromium-browser") if (p := shutil.which(n))), None)


@pytest.mark.slow
def test_a_headless_browser_shows_the_tables_and_the_figures(
    run_folder: Path, tmp_path: Path
) -> None:
    """The report opened in Chromium: the DOM it builds has the tables with their headers and
    values, and every figure decoded (naturalWidth > 0; the test's copy of the page gets a
    one-line script that writes it into the DOM: the report itself has none)."""
    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium binary on PATH (apt-get install chromium)")
    probe = "<script>for (const i of document.images) i.dataset.w = i.naturalWidth;</script>"
    page_path = tmp_path / "report.html"
    page_path.write_text(
        (run_folder / "report.html").read_text().replace("</body>", probe + "</body>")
    )
    done = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         f"--user-data-dir={tmp_path / 'profile'}", "--dump-dom", page_path.as_uri()],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    dom = _parse(done.stdout)
    expected = _markdown_tables((run_folder / "report.md").read_text())
    assert dom.tables == expected
    header = dom.tables[0][0]
    assert header[:2] == ["Model", "kind"] and "lat. RMSE (m) [95% CI]" in header
    models = [row[0] for row in dom.tables[0][1:]]
    doc = json.loads((run_folder / "results.json").read_text())
    assert models == [r["model"] for r in doc["summary"]]
    widths = [int(str(image.get("data-w"))) for image in dom.images]
    assert len(widths) == len(_figures(run_folder)) and min(widths) > 100


def _result_from(doc: dict) -> BenchmarkResult:
    """A BenchmarkResult with the tables of a results.json (no figure data)."""
    fields = {f.name for f in dataclasses.fields(BenchmarkResult)}
    kept = {k: v for k, v in doc.items() if k in fields}
    return BenchmarkResult(**kept, timing=doc["timing_seconds"], plots={})


@pytest.mark.slow
def test_a_result_that_breaks_the_schema_is_one_error_line_and_every_file_is_kept(
    run_folder: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    doc = json.loads((run_folder / "results.json").read_text())
    good = _result_from(doc)
    out = tmp_path / "out"
    write_outputs(good, out, figures=False)  # the same rows written again: no problem
    assert folder_problems(out) == []
    bad = _result_from(doc)
    bad.summary[0]["surprise"] = 1.0  # a column the schema does not know
    # hasa-bench imports run_protocol from benchmarks.protocol when a command runs
    monkeypatch.setattr(benchmarks.protocol, "run_protocol", lambda *args, **kwargs: bad)
    code = bench.main(["paper", *TINY, "--no-plots", "--quiet", "--out", str(out), "--overwrite"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.count("hasa-bench: error: ") == 1
    assert "results.json does not follow the shipped schema: results.json.summary[0]" in err
    assert "'surprise' was unexpected" in err
    # written all the same, the previous result replaced, no half-written folder left over
    assert json.loads((out / "results.json").read_text())["summary"][0]["surprise"] == 1.0
    assert (out / "report.html").is_file() and (out / "summary.csv").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_html_tables_have_the_markdown_tables_cells_escaped() -> None:
    columns = [Column("model", "Model <name>", left=True), Column("x", "x & y", fixed(2))]
    rows = [{"model": "<script>alert(1)</script>", "x": 0.5}, {"model": "a|b", "x": None}]
    page = render_html(rows, columns, caption="Caption <i>")
    assert "<script>" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "<caption>Caption &lt;i&gt;</caption>" in page
    parsed = _parse(page)
    assert parsed.tables == [
        [["Model <name>", "x & y"], ["<script>alert(1)</script>", "0.50"], ["a|b", "-"]]
    ]
    assert _markdown_tables(render_markdown(rows, columns))[0][1:] == parsed.tables[0][1:]
    assert '<td class="num">0.50</td>' in page and "<td>a|b</td>" in page


def test_markdown_tables_escape_a_pipe_inside_a_cell() -> None:
    columns = [Column("model", "Model | name", left=True), Column("x", "x", fixed(2))]
    rows = [{"model": "a|b||c", "x": 0.5}, {"model": "two\nlines", "x": None}]
    text = render_markdown(rows, columns)
    assert text.splitlines() == [
        "| Model \\| name | x |",
        "|:---|---:|",
        "| a\\|b\\|\\|c | 0.50 |",
        "| two lines | - |",
    ]
    assert _markdown_tables(text) == [
        [["Model | name", "x"], ["a|b||c", "0.50"], ["two lines", "-"]]
    ]


def test_the_scenario_suite_page_links_each_scenarios_report() -> None:
    row = {"scenario": "lane_shift", "model": "gen<eralized>", "kind": "builtin",
           "estimated_runs": 4, "lateral_rmse": 0.1234}  # fmt: skip
    page = html_suite([row])
    assert '<a href="lane_shift/report.html">report</a>' in page
    assert "gen&lt;eralized&gt;" in page and "0.123" in page
    assert "<script" not in page and "http" not in page

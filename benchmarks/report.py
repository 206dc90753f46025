"""Tables, CSV files and the Markdown and HTML reports of a benchmark result.

:func:`format_tables` renders the tables for the terminal and
:func:`markdown_report` the report (the tables' columns and captions are
:mod:`benchmarks.report_sections`), both with the paper's published values
beside ours; :func:`write_outputs` writes ``results.json``, the CSV tables
(every per-seed row), ``report.md``, ``report.html`` (the same cells, one self-contained
page with the figures embedded: :func:`html_report`) and the figures
(:mod:`benchmarks.figures`).

The tables, in order:

1. the verdict over population seeds (or over the participants of recordings):
   per model, the mean of the per-seed values with its 95 % hierarchical
   percentile-bootstrap interval, the shares of runs counted with their exact
   (Clopper-Pearson) intervals, ranks among every ranked model and how often a
   model holds its rank (:func:`benchmarks.protocol.aggregate.verdict`,
   :mod:`benchmarks.protocol.intervals`);
2. the fits' checks per seed (ridge penalty, condition number, largest AR
   pole, stability, identifiability);
3. per driver, means over the seeds: steering prediction (paper table 1; the
   paper's RMSE converted from steering-wheel to road-wheel radians by the
   steering ratio 15), the curved track, lateral estimation (paper table 2).
"""

from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.documents import json_clean
from benchmarks.figures import write_figures
from benchmarks.protocol import BenchmarkResult
from benchmarks.report_sections import checks_rows, pooled, report_sections
from benchmarks.schema import ResultsSchemaError, results_problems
from benchmarks.tables import (
    fixed,
    interval,
    percent,
    render_html,
    render_markdown,
    render_text,
)
from hasa_env.steering.loading import PAPER_STEERING_RATIO

__all__ = [
    "CSV_TABLES",
    "format_tables",
    "html_report",
    "markdown_report",
    "pooled",
    "write_outputs",
]

CSV_TABLES = {
    "steering": "steering.csv",
    "curved": "curved.csv",
    "estimation": "estimation.csv",
    "curved_estimation": "curved_estimation.csv",
    "seed_summary": "seed_summary.csv",
    "summary": "summary.csv",
    "runs_steering": "runs_steering.csv",
    "runs_estimation": "runs_estimation.csv",
}
"""results attribute -> CSV file name."""


def _source(cfg: dict[str, Any]) -> str:
    if cfg.get("recordings"):
        return f"recordings in {cfg['recordings']} (scenario {cfg.get('scenario', 'paper')!r})"
    scenario = cfg.get("scenario") or "paper"
    return (
        f"synthetic population {cfg['population']!r}, scenario {scenario!r}, "
        f"seeds {cfg['seeds']}: "
        f"{cfg['drivers']} drivers x {cfg['runs']} runs of {cfg['duration']:g} s on the "
        f"{cfg['track']} track ({cfg['illustrative']}: {cfg['ill_runs']}), "
        f"{cfg['curved_runs']} curved"
    )


def _training_runs(cfg: dict[str, Any]) -> str:
    """What trained the models: "run 0 of Ill (each seed's)", "runs 0-2 of Ill (each seed's)",
    "the recording F" (recordings, ``training_file``), "run 0 of P01" (recordings), then the
    extra runs at other start speeds and of other drivers, if any."""
    if cfg.get("training_file"):
        return f"the recording {cfg['training_file']}"
    first, count = cfg["training_run"], int(cfg.get("training_runs") or 1)
    text = f"run {first}" if count == 1 or first is None else f"runs {first}-{first + count - 1}"
    text += f" of {cfg.get('illustrative')}" + ("" if cfg.get("recordings") else " (each seed's)")
    speeds = cfg.get("training_speeds") or ()
    if speeds:
        text += f" and its runs started at {', '.join(f'{v:g}' for v in speeds)} m/s"
    others = int(cfg.get("training_drivers") or 0)
    if others:
        text += f" and one run each of {others} more drivers of the population"
    return text


def _generalized_orders(result: BenchmarkResult) -> str:
    """The built-in generalized model's orders per seed when BIC selected them:
    "; generalized orders (na, nb, nc, nd) by BIC on them: (4, 6, 1, 0) on seeds 0, 2; ..."
    ("" with the paper's orders, or when no generalized model was fitted)."""
    if result.config.get("generalized_orders") != "bic":
        return ""
    chosen: dict[tuple[int, ...], list[str]] = {}
    for m in result.models:
        if m.get("name") == "generalized" and m.get("kind") == "builtin" and m.get("structure"):
            orders = tuple(int(m["structure"][k]) for k in ("na", "nb", "nc", "nd"))
            chosen.setdefault(orders, []).append(str(m.get("seed")))
    if not chosen:
        return ""
    parts = [
        f"({', '.join(map(str, orders))}) on seed{'s' if len(seeds) > 1 else ''} {', '.join(seeds)}"
        for orders, seeds in chosen.items()
    ]
    return f"; generalized orders (na, nb, nc, nd) by BIC on them: {'; '.join(parts)}"


def format_tables(result: BenchmarkResult) -> str:
    """The result's tables as plain text (ours beside the paper's published values)."""
    cfg = result.config
    parts = [
        f"hasa-bench: {_source(cfg)}; models fitted on {_training_runs(cfg)}"
        + _generalized_orders(result)
    ]
    for _, title, rows, columns, group in report_sections(result):
        parts.append("")
        parts.append(title)
        parts.append(render_text(rows, columns, group) if rows else "(no rows)")
    parts.extend(_findings(result, markdown=False))
    notes = _model_notes(result)
    if notes:
        parts.append("")
        parts.append("Notes on the models:")
        parts.extend(f"  {name}: {note}" for name, note in notes)
    if result.notes:
        parts.append("")
        parts.append("Notes on the runs:")
        parts.extend(f"  {note}" for note in result.notes)
    if result.errors:
        parts.append("")
        parts.append("ERRORS (these models are left out of the tables):")
        parts.extend(f"  {e['message']}" for e in result.errors)
    return "\n".join(parts)


def _model_notes(result: BenchmarkResult) -> list[tuple[str, str]]:
    """(model, note) once per model with a note (e.g. why it has no estimation rows)."""
    seen: dict[str, str] = {}
    for m in result.models:
        if m.get("note") and not m.get("error"):
            seen.setdefault(str(m["name"]), str(m["note"]))
    return list(seen.items())


UNSAFE_SHARE = 0.01
"""An estimator that ends more than this share of its runs (straight and curved) with more than
0.95 on a wrong lane is named in the findings (the bound of docs/design.md §8.11)."""


def _unsafe_estimators(result: BenchmarkResult) -> list[str]:
    """ "name a/b (x %)" of every estimator above :data:`UNSAFE_SHARE`, in summary order."""
    out = []
    for row in result.summary:
        wrong = row.get("wrong_lane_confident_runs")
        runs = row.get("estimated_runs")
        if wrong is None or not runs or not math.isfinite(float(runs)):
            continue
        wrong = float(wrong) + float(row.get("curved_wrong_lane_confident_runs") or 0.0)
        runs = float(runs) + float(row.get("curved_estimated_runs") or 0.0)
        if wrong > UNSAFE_SHARE * runs:
            out.append(f"{row['model']} {wrong:.0f}/{runs:.0f} ({wrong / runs:.1%})")
    return out


def _finding_items(result: BenchmarkResult) -> list[str]:
    """Headline numbers next to the paper's claims (means over seeds, with intervals), one
    plain-text item each (none without both built-in models)."""
    by = {r["model"]: r for r in result.summary}
    gen, tp = by.get("generalized"), by.get("two_point")
    if not (gen and tp):
        return []
    dec = interval(percent, "rmse_decrease_vs_two_point")(gen)
    items = [
        f"steering RMSE decrease of the generalized model vs two-point: {dec} (paper: 85 %)",
        f"one-step steering RMSE / the paper's (median over drivers): two-point "
        f"{interval(fixed(2), 'rmse_over_paper_median')(tp)}, generalized "
        f"{interval(fixed(2), 'rmse_over_paper_median')(gen)}",
        f"road information (1 - SSE / SSE of the road-blind AR(2) baseline; 0: the steering's "
        f"own past predicts as well): two-point {interval(fixed(3), 'road_information')(tp)}, "
        f"generalized {interval(fixed(3), 'road_information')(gen)}",
        f"lateral RMSE: generalized {interval(fixed(3), 'lateral_rmse')(gen)} m "
        f"(paper: under 0.25), two-point {interval(fixed(3), 'lateral_rmse')(tp)} m "
        "(paper: 0.93-1.0)",
    ]
    base, oracle = by.get("no_steering"), by.get("oracle")
    if base and oracle:
        items.append(
            f"baselines: no steering {interval(fixed(3), 'lateral_rmse')(base)} m "
            f"(paper: 0.9), oracle {interval(fixed(3), 'lateral_rmse')(oracle)} m"
        )
    unsafe = _unsafe_estimators(result)
    if unsafe:
        items.append(
            f"confidently in the wrong lane (> 0.95) in more than "
            f"{UNSAFE_SHARE:.0%} of runs: " + ", ".join(unsafe)
        )
    flagged = [r for r in checks_rows(result) if r.get("flags") and r.get("kind") != "baseline"]
    if flagged:
        shown = ", ".join(f"{r['name']} seed {r['seed']}: {', '.join(r['flags'])}" for r in flagged)
        items.append(f"flagged fits: {shown}")
    return items


def _findings(result: BenchmarkResult, markdown: bool) -> list[str]:
    """:func:`_finding_items` under a "Headline" line, as Markdown or terminal bullets."""
    items = _finding_items(result)
    if not items:
        return []
    bullet = "- " if markdown else "  "
    return ["", "Headline (ours vs the paper):", *(bullet + item for item in items)]


# --------------------------------------------------------------------- markdown
def markdown_report(result: BenchmarkResult, figures: dict[str, str]) -> str:
    """The Markdown report: configuration, tables, findings, figures, errors, versions."""
    lines = _markdown_head(result.config, _generalized_orders(result))
    for key, title, rows, columns, _ in report_sections(result):
        lines.append(f"## {key.replace('_', ' ').capitalize()}")
        lines.append("")
        lines.append(title + ".")
        lines.append("")
        lines.append(render_markdown(rows, columns) if rows else "(no rows)")
        lines.append("")
    findings = _findings(result, markdown=True)
    if findings:
        lines.append("## Findings")
        lines.append("")
        lines.extend(findings[2:])
        lines.append("")
    if result.errors:
        lines.append("## Errors")
        lines.append("")
        lines.append("These models failed and are left out of the tables:")
        lines.append("")
        lines.extend(f"- `{e['model']}` ({e['stage']}): {e['message']}" for e in result.errors)
        lines.append("")
    lines.extend(_markdown_models(result))
    lines.extend(_markdown_figures(result.config, figures))
    if result.notes:
        lines.append("## Notes")
        lines.append("")
        lines.extend(f"- {n}" for n in result.notes)
        lines.append("")
    lines.extend(_markdown_run(result))
    return "\n".join(lines)


_TITLE = "hasa-bench: the human-as-advisor benchmark"
_INTRO = (
    "Protocol of Mai et al. (sections 3.3 and 4.3; docs/design.md §9). Our numbers are "
    "what the code measured; the paper's published values are printed beside them for "
    "comparison, nothing is tuned toward them. The paper's steering RMSEs are steering-"
    f"wheel angles; beside ours they are divided by the steering ratio "
    f"{PAPER_STEERING_RATIO:g} (road-wheel rad)."
)


def _markdown_head(cfg: dict[str, Any], orders: str = "") -> list[str]:
    """The report's title, what it compares, the data (``orders``: :func:`_generalized_orders`)
    and the configuration."""
    lines = [f"# {_TITLE}", "", _INTRO, ""]
    lines.append(f"Data: {_source(cfg)}; models fitted on {_training_runs(cfg)}{orders}.")
    lines.append("")
    lines.append("## Configuration")
    lines.append("")
    lines.append("```json")
    lines.append(json.dumps(json_clean(cfg), indent=2))
    lines.append("```")
    lines.append("")
    return lines


def _model_items(result: BenchmarkResult) -> list[tuple[str, str, list[str]]]:
    """Per fitted model: (name, "(kind, seed): parameters", its sub-items: identifiability,
    residual std, note, warnings), plain text."""
    items = []
    for m in result.models:
        if m.get("error"):
            continue
        params = m.get("parameters") or {}
        shown = ", ".join(f"{k} = {v:.4g}" for k, v in params.items())
        seed = "" if m.get("seed") is None else f", seed {m['seed']}"
        sub = []
        ident = m.get("identifiability")
        if ident:
            sub.append(str(ident["message"]))
        if m.get("filter_residual_std") is not None:
            sub.append(
                f"filter steering-residual std (training run): {m['filter_residual_std']:.3g} rad"
            )
        by_speed = m.get("residual_by_speed") or []
        if by_speed:
            sub.append(
                "steering residual by speed (training runs; m/s: RMS rad, lag-1 "
                "autocorrelation): "
                + "; ".join(
                    f"{b['speed_low']:g}-{b['speed_high']:g}: {b['residual_rms']:.2g}, "
                    f"{b['lag1_autocorrelation']:.2f}"
                    for b in by_speed
                )
            )
        if m.get("note"):
            sub.append(str(m["note"]))
        sub.extend(f"warning: {w}" for w in m.get("warnings") or [])
        items.append((str(m["name"]), f"({m['kind']}{seed}): {shown}", sub))
    return items


def _markdown_models(result: BenchmarkResult) -> list[str]:
    """One item per fitted model: parameters, identifiability, residual std, notes, warnings."""
    lines = ["## Models", ""]
    for name, head, sub in _model_items(result):
        lines.append(f"- **{name}** {head}")
        lines.extend(f"  - {item}" for item in sub)
    lines.append("")
    return lines


_FIGURE_CAPTIONS = {
    "steering_prediction": "Steering prediction vs measured on one validation run "
    "(paper Fig. 4) and the prediction error",
    "residual_acf": "Autocorrelation of the one-step residuals, training run and mean "
    "over the illustrative driver's validation runs (paper Fig. 5)",
    "lateral_estimate": "Lateral estimate vs truth and the true lane's weight on one "
    "validation run (paper Fig. 8)",
    "lateral_error": "Lateral error over the first seconds, mean and std over the "
    "illustrative driver's validation runs (paper Fig. 9)",
    "curved_steering": "Steering prediction on the curved track (paper Fig. 7)",
    "reliability": "Reliability diagram of the lane probabilities, main track, every seed "
    "(the reliability table drawn): per bin of the probability given to a hypothesis, the "
    "share of those (step, hypothesis) pairs whose hypothesis was the true lane; on the "
    "diagonal calibrated, above it underconfident; marker area by the pairs in the bin",
}


def _seed_sentence(first: Any, figures: dict[str, str]) -> str:
    """Which seeds the figures show."""
    every = "; the reliability diagram shows every seed" if "reliability" in figures else ""
    return f"The figures show population seed {first}{every}."


def _markdown_figures(cfg: dict[str, Any], figures: dict[str, str]) -> list[str]:
    """The figures with their captions (nothing without figures)."""
    if not figures:
        return []
    lines = ["## Figures", ""]
    first = (cfg.get("seeds") or [None])[0]
    if first is not None:
        lines.append(_seed_sentence(first, figures))
        lines.append("")
    for key, name in figures.items():
        lines.append(f"### {_FIGURE_CAPTIONS.get(key, key)}")
        lines.append("")
        lines.append(f"![{key}]({name})")
        lines.append("")
    return lines


def _run_paragraphs(result: BenchmarkResult) -> list[str]:
    """How the protocol ran (executor, wall time) and the versions, one paragraph each."""
    ex = result.executor
    return [
        f"Executor: {ex['kind']}"
        + (f", {ex['workers']} workers" if ex.get("workers") else "")
        + (f", scheduler {ex['scheduler']}" if ex.get("scheduler") else "")
        + f", {ex['tasks']} tasks of up to {ex.get('batch_size')} runs. Protocol wall time "
        f"{result.timing.get('total', float('nan')):.1f} s (writing files and figures excluded).",
        "Versions: " + ", ".join(f"{k} {v}" for k, v in result.versions.items() if k != "platform"),
    ]


def _markdown_run(result: BenchmarkResult) -> list[str]:
    """How the protocol ran (executor, wall time) and the versions."""
    first, second = _run_paragraphs(result)
    return ["## Run", "", first, "", second, ""]


# ------------------------------------------------------------------------- html
_CSS = """
body { font-family: sans-serif; margin: 2em auto; max-width: 75em; padding: 0 1em;
       color: #222; line-height: 1.4; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
caption { text-align: left; font-style: italic; padding-bottom: 0.3em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: left; vertical-align: top; }
th { background: #eee; }
.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.scroll { overflow-x: auto; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
figure { margin: 1em 0 2em; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
.error { color: #a00; }
"""


def _esc(value: Any) -> str:
    return html.escape(str(value))


def _html_list(items: list[str], css: str = "") -> list[str]:
    """A <ul> of escaped plain-text items."""
    attr = f' class="{css}"' if css else ""
    return [f"<ul{attr}>", *(f"<li>{_esc(item)}</li>" for item in items), "</ul>"]


def _data_uri(path: Path) -> str:
    """The PNG at ``path`` as a ``data:`` URI (the report needs no other file)."""
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _html_body(result: BenchmarkResult) -> list[str]:
    """The configuration, the tables (the cells of :func:`report_sections`) and the findings."""
    cfg = result.config
    parts = [
        f"<h1>{_esc(_TITLE)}</h1>",
        f"<p>{_esc(_INTRO)}</p>",
        f"<p>Data: {_esc(_source(cfg))}; models fitted on "
        f"{_esc(_training_runs(cfg) + _generalized_orders(result))}.</p>",
    ]
    for key, title, rows, columns, _ in report_sections(result):
        parts.append(f'<h2 id="{_esc(key)}">{_esc(key.replace("_", " ").capitalize())}</h2>')
        table = render_html(rows, columns, caption=title + ".") if rows else "<p>(no rows)</p>"
        parts.append(f'<div class="scroll">{table}</div>')
    items = _finding_items(result)
    if items:
        parts += ['<h2 id="findings">Findings</h2>', *_html_list(items)]
    if result.errors:
        parts += [
            '<h2 id="errors">Errors</h2>',
            "<p>These models failed and are left out of the tables:</p>",
            *_html_list(
                [f"{e['model']} ({e['stage']}): {e['message']}" for e in result.errors], "error"
            ),
        ]
    parts.append('<h2 id="models">Models</h2>')
    parts.append("<ul>")
    for name, head, sub in _model_items(result):
        nested = "".join(_html_list(sub)) if sub else ""
        parts.append(f"<li><strong>{_esc(name)}</strong> {_esc(head)}{nested}</li>")
    parts.append("</ul>")
    return parts


def _html_figures(cfg: dict[str, Any], figures: dict[str, str], folder: Path) -> list[str]:
    """The figures, embedded as base64 PNG data, with their captions (nothing without figures)."""
    if not figures:
        return []
    parts = ['<h2 id="figures">Figures</h2>']
    first = (cfg.get("seeds") or [None])[0]
    if first is not None:
        parts.append(f"<p>{_esc(_seed_sentence(first, figures))}</p>")
    for key, name in figures.items():
        caption = _FIGURE_CAPTIONS.get(key, key)
        parts += [
            f'<figure id="{_esc(key)}">',
            f'<img src="{_data_uri(folder / name)}" alt="{_esc(caption)}">',
            f"<figcaption>{_esc(caption)} ({_esc(name)})</figcaption>",
            "</figure>",
        ]
    return parts


def html_report(result: BenchmarkResult, figures: dict[str, str], folder: str | Path) -> str:
    """The report as one self-contained HTML page: the same sections and cells as
    :func:`markdown_report`, the figures (PNG files in ``folder``) embedded as ``data:`` URIs;
    no script, no link to anything outside the file."""
    parts = _html_body(result)
    parts += _html_figures(result.config, figures, Path(folder))
    if result.notes:
        parts += ['<h2 id="notes">Notes</h2>', *_html_list(list(result.notes))]
    parts += ['<h2 id="configuration">Configuration</h2>']
    parts.append(f"<pre>{_esc(json.dumps(json_clean(result.config), indent=2))}</pre>")
    parts += ['<h2 id="run">Run</h2>', *(f"<p>{_esc(p)}</p>" for p in _run_paragraphs(result))]
    head = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>{_esc(_TITLE)}</title>",
        f"<style>{_CSS}</style>",
        "</head>",
        "<body>",
    ]
    return "\n".join([*head, *parts, "</body>", "</html>"]) + "\n"


# ----------------------------------------------------------------------- output
def write_outputs(
    result: BenchmarkResult, out_dir: str | Path, *, figures: bool = True
) -> dict[str, Path]:
    """Write results.json, the CSV tables, report.md, report.html and (optionally) the figures.

    results.json is checked against the shipped schema (:mod:`benchmarks.schema`); every file
    is written either way, so nothing measured is lost.

    Returns:
        {name: path} of every file written.

    Raises:
        ResultsSchemaError: after writing, if results.json breaks the schema (a bug to report).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    doc = result.to_json_dict()
    problems = results_problems(doc)  # checked here, raised once every file is written
    path = out / "results.json"
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    written["results.json"] = path
    for attribute, name in CSV_TABLES.items():
        frame = pd.DataFrame(list(doc[attribute]))
        for column in frame.columns:  # list cells (reliability bins) as JSON text
            if frame[column].map(lambda v: isinstance(v, list)).any():
                frame[column] = frame[column].map(
                    lambda v: json.dumps(v) if isinstance(v, list) else v
                )
        if attribute in ("steering", "curved", "estimation", "summary") or not frame.empty:
            frame.to_csv(out / name, index=False)
            written[name] = out / name
    figure_names = write_figures(result, out) if figures else {}
    for name in figure_names.values():
        written[name] = out / name
    report = out / "report.md"
    report.write_text(markdown_report(result, figure_names), encoding="utf-8")
    written["report.md"] = report
    page = out / "report.html"
    page.write_text(html_report(result, figure_names, out), encoding="utf-8")
    written["report.html"] = page
    if problems:
        raise ResultsSchemaError(problems)
    return written

"""Tables, CSV files, the Markdown report and the figures of a benchmark result.

:func:`format_tables` renders the tables for the terminal (the paper's
published values beside ours); :func:`write_outputs` writes ``results.json``,
the CSV tables, ``report.md`` and the PNG figures (matplotlib, Agg) into a
directory.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from benchmarks.protocol import BASELINES, BenchmarkResult

__all__ = ["format_tables", "write_outputs", "markdown_report", "FIGURES", "CSV_TABLES"]

FIGURES = {
    "steering_prediction": "steering_prediction.png",
    "residual_acf": "residual_acf.png",
    "lateral_estimate": "lateral_estimate.png",
    "lateral_error": "lateral_error.png",
    "curved_steering": "curved_steering.png",
}
"""Figure key -> file name."""

CSV_TABLES = {
    "steering": "steering.csv",
    "curved": "curved.csv",
    "estimation": "estimation.csv",
    "summary": "summary.csv",
    "runs_steering": "runs_steering.csv",
    "runs_estimation": "runs_estimation.csv",
}
"""results attribute -> CSV file name."""


# ----------------------------------------------------------------------- tables
@dataclass(frozen=True)
class _Column:
    key: str | Callable[[dict[str, Any]], Any]
    header: str
    fmt: Callable[[Any], str]
    left: bool = False

    def cell(self, row: dict[str, Any]) -> str:
        value = self.key(row) if callable(self.key) else row.get(self.key)
        return self.fmt(value)


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and not math.isfinite(value))


def _sci(value: Any) -> str:
    return "-" if _missing(value) else f"{value:.2e}"


def _fixed(digits: int) -> Callable[[Any], str]:
    return lambda v: "-" if _missing(v) else f"{v:.{digits}f}"


def _pct(value: Any) -> str:
    return "-" if _missing(value) else f"{100 * value:.0f}%"


def _text(value: Any) -> str:
    return "-" if value is None else str(value)


def _paper_num(value: Any) -> str:
    if _missing(value):
        return ""
    return f"{value:.2g}" if abs(value) < 1e-2 else f"{value:g}"


def _paper_pct(value: Any) -> str:
    return "" if _missing(value) else f"{100 * value:.0f}%"


def _render_text(rows: Sequence[dict[str, Any]], columns: Sequence[_Column]) -> str:
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
        driver = row.get("driver")
        if previous is not None and driver != previous:
            out.append("")
        previous = driver
        out.append(line(values))
    return "\n".join(out)


def _render_markdown(rows: Sequence[dict[str, Any]], columns: Sequence[_Column]) -> str:
    head = "| " + " | ".join(c.header for c in columns) + " |"
    rule = "|" + "|".join(":---" if c.left else "---:" for c in columns) + "|"
    body = ["| " + " | ".join(c.cell(r) or " " for c in columns) + " |" for r in rows]
    return "\n".join([head, rule, *body])


def _white(row: dict[str, Any]) -> str:
    return f"{row['white_runs']}/{row['n_runs']}"


def _decided(row: dict[str, Any]) -> str:
    return f"{row['decided_runs']}/{row['n_runs']}"


def _final(row: dict[str, Any]) -> str:
    return f"{row['true_lane_final_runs']}/{row['n_runs']}"


_STEERING_COLUMNS = [
    _Column("driver", "Driver", _text, left=True),
    _Column("model", "Model", _text, left=True),
    _Column("rmse", "RMSE (rad)", _sci),
    _Column("r2", "R^2", _fixed(5)),
    _Column("r2_increments", "R^2 inc", _fixed(3)),
    _Column("rmse_decrease_vs_two_point", "RMSE dec.", _pct),
    _Column(_white, "white (LB)", _text),
    _Column("ljung_box_p_median", "LB p (median)", _sci),
    _Column("paper_rmse", "paper RMSE", _paper_num),
    _Column("paper_r2", "paper R^2 Acc", _paper_num),
    _Column("paper_rmse_decrease", "paper dec.", _paper_pct),
]

_CURVED_COLUMNS = [
    c if c.key != "paper_r2" else _Column("paper_r2", "paper R^2", _paper_num)
    for c in _STEERING_COLUMNS
]

_ESTIMATION_COLUMNS = [
    _Column("driver", "Driver", _text, left=True),
    _Column("model", "Model", _text, left=True),
    _Column("lateral_rmse_mean", "lat. RMSE mean (m)", _fixed(3)),
    _Column("lateral_rmse_std", "std (m)", _fixed(3)),
    _Column("lateral_rmse_max", "max (m)", _fixed(3)),
    _Column("steps_to_decide_median", "steps to w>0.95", _fixed(0)),
    _Column(_decided, "decided", _text),
    _Column(_final, "true lane at end", _text),
    _Column("paper_lateral_rmse_mean", "paper mean (m)", _paper_num),
    _Column("paper_lateral_rmse_std", "paper std (m)", _paper_num),
]

_SUMMARY_COLUMNS = [
    _Column("model", "Model", _text, left=True),
    _Column("kind", "kind", _text, left=True),
    _Column("rmse", "steering RMSE (rad)", _sci),
    _Column("r2_increments", "R^2 inc", _fixed(3)),
    _Column("rmse_decrease_vs_two_point", "RMSE dec.", _pct),
    _Column("lateral_rmse", "lat. RMSE (m)", _fixed(3)),
    _Column(
        lambda r: (
            None if r["decided_runs"] is None else f"{r['decided_runs']}/{r['estimated_runs']}"
        ),
        "decided",
        _text,
    ),
    _Column("rank_lateral", "rank (lat.)", _text),
    _Column("rank_steering", "rank (steer.)", _text),
]


def _estimation_columns(threshold: float) -> list[_Column]:
    label = f"steps to w>{threshold:g}"
    return [
        c if c.header != "steps to w>0.95" else _Column(c.key, label, c.fmt)
        for c in _ESTIMATION_COLUMNS
    ]


def _sections(result: BenchmarkResult) -> list[tuple[str, str, list[dict], list[_Column]]]:
    """(key, title, rows, columns) of each table."""
    cfg = result.config
    threshold = float(cfg.get("weight_threshold", 0.95))
    sections = [
        (
            "steering",
            "Steering prediction (paper table 1): one step ahead with the measured past "
            "steering, mean over each driver's validation runs; R^2 inc = R^2 on "
            "delta(k) - delta(k-1) (compare with the paper's 'R^2 Acc'); white (LB) = runs whose "
            f"residuals pass Ljung-Box at 5 % ({cfg.get('ljung_box_lags', 20)} lags)",
            result.steering,
            _STEERING_COLUMNS,
        )
    ]
    if result.curved:
        sections.append(
            (
                "curved",
                f"Curved track, driver {cfg.get('illustrative', 'Ill')} (paper section 3.3.2; "
                "the paper gives R^2 on delta and RMSE)",
                result.curved,
                _CURVED_COLUMNS,
            )
        )
    sections.append(
        (
            "estimation",
            "Lateral estimation (paper table 2): RMSE of the mixture's lateral-offset estimate "
            "over each run, mean and std over the driver's validation runs; steps until the "
            f"true lane's weight stays above {threshold:g} (median over decided runs)",
            result.estimation,
            _estimation_columns(threshold),
        )
    )
    sections.append(
        (
            "summary",
            "Summary over drivers (means of the per-driver values) and ranking",
            result.summary,
            _SUMMARY_COLUMNS,
        )
    )
    return sections


def format_tables(result: BenchmarkResult) -> str:
    """The result's tables as plain text (ours beside the paper's published values)."""
    cfg = result.config
    if cfg.get("recordings"):
        source = f"recordings in {cfg['recordings']}"
    else:
        source = (
            f"synthetic population {cfg['population']!r} (seed {cfg['population_seed']}), "
            f"{cfg['drivers']} drivers x {cfg['runs']} runs of {cfg['duration']:g} s on the "
            f"{cfg['track']} track ({cfg['illustrative']}: {cfg['ill_runs']}), "
            f"{cfg['curved_runs']} curved, run seed {cfg['seed']}"
        )
    parts = [
        f"hasa-bench: {source}; models fitted on run {cfg['training_run']} of {cfg['illustrative']}"
    ]
    for _, title, rows, columns in _sections(result):
        parts.append("")
        parts.append(title)
        parts.append(_render_text(rows, columns) if rows else "(no rows)")
    parts.extend(_findings(result, markdown=False))
    if result.errors:
        parts.append("")
        parts.append("ERRORS (these models are left out of the tables):")
        parts.extend(f"  {e['message']}" for e in result.errors)
    return "\n".join(parts)


def _findings(result: BenchmarkResult, markdown: bool) -> list[str]:
    """Headline numbers next to the paper's claims."""
    lines = []
    by = {r["model"]: r for r in result.summary}
    gen, tp = by.get("generalized"), by.get("two_point")
    bullet = "- " if markdown else "  "
    if gen and tp:
        lines.append("")
        lines.append("Headline (ours vs the paper):")
        if gen["rmse_decrease_vs_two_point"] is not None:
            lines.append(
                f"{bullet}steering RMSE decrease of the generalized model vs two-point, mean over "
                f"drivers: {_pct(gen['rmse_decrease_vs_two_point'])} (paper: 85 %)"
            )
        if gen["lateral_rmse"] is not None and tp["lateral_rmse"] is not None:
            lines.append(
                f"{bullet}lateral RMSE, mean over drivers: generalized "
                f"{_fixed(3)(gen['lateral_rmse'])} m (paper: under 0.25), two-point "
                f"{_fixed(3)(tp['lateral_rmse'])} m (paper: 0.93-1.0)"
            )
        base = by.get("no_steering")
        oracle = by.get("oracle")
        if base and oracle:
            lines.append(
                f"{bullet}baselines: no steering {_fixed(3)(base['lateral_rmse'])} m (paper: 0.9), "
                f"oracle {_fixed(3)(oracle['lateral_rmse'])} m"
            )
    return lines


def _table_frame(rows: Sequence[dict[str, Any]]) -> pd.DataFrame:
    return pd.DataFrame(list(rows))


# --------------------------------------------------------------------- markdown
def markdown_report(result: BenchmarkResult, figures: dict[str, str]) -> str:
    """The Markdown report: configuration, tables, findings, figures, errors, versions."""
    cfg = result.config
    lines = ["# hasa-bench: the human-as-advisor benchmark", ""]
    lines.append(
        "Protocol of Mai et al. (sections 3.3 and 4.3; docs/design.md §9). Our numbers are "
        "what the code measured; the paper's published values are printed beside them for "
        "comparison, nothing is tuned toward them."
    )
    lines.append("")
    lines.append("## Configuration")
    lines.append("")
    lines.append("```json")
    lines.append(json.dumps(_clean(cfg), indent=2))
    lines.append("```")
    lines.append("")
    for key, title, rows, columns in _sections(result):
        lines.append(f"## {key.capitalize()}")
        lines.append("")
        lines.append(title + ".")
        lines.append("")
        lines.append(_render_markdown(rows, columns) if rows else "(no rows)")
        lines.append("")
    findings = _findings(result, markdown=True)
    if findings:
        lines.extend(findings[1:])
        lines.append("")
    if result.errors:
        lines.append("## Errors")
        lines.append("")
        lines.append("These models failed and are left out of the tables:")
        lines.append("")
        lines.extend(f"- `{e['model']}` ({e['stage']}): {e['message']}" for e in result.errors)
        lines.append("")
    lines.append("## Models")
    lines.append("")
    for m in result.models:
        if m.get("error"):
            continue
        params = m.get("parameters") or {}
        shown = ", ".join(f"{k} = {v:.4g}" for k, v in params.items())
        lines.append(f"- **{m['name']}** ({m['kind']}): {shown}")
        ident = m.get("identifiability")
        if ident:
            lines.append(f"  - {ident['message']}")
        if m.get("filter_residual_std") is not None:
            lines.append(
                f"  - filter steering-residual std (training run): "
                f"{m['filter_residual_std']:.3g} rad"
            )
        if m.get("note"):
            lines.append(f"  - {m['note']}")
        for w in m.get("warnings") or []:
            lines.append(f"  - warning: {w}")
    lines.append("")
    if figures:
        lines.append("## Figures")
        lines.append("")
        captions = {
            "steering_prediction": "Steering prediction vs measured on one validation run "
            "(paper Fig. 4) and the prediction error",
            "residual_acf": "Autocorrelation of the one-step residuals, training run and mean "
            "over the illustrative driver's validation runs (paper Fig. 5)",
            "lateral_estimate": "Lateral estimate vs truth and the true lane's weight on one "
            "validation run (paper Fig. 8)",
            "lateral_error": "Lateral error over the first seconds, mean and std over the "
            "illustrative driver's validation runs (paper Fig. 9)",
            "curved_steering": "Steering prediction on the curved track (paper Fig. 7)",
        }
        for key, name in figures.items():
            lines.append(f"### {captions.get(key, key)}")
            lines.append("")
            lines.append(f"![{key}]({name})")
            lines.append("")
    if result.notes:
        lines.append("## Notes")
        lines.append("")
        lines.extend(f"- {n}" for n in result.notes)
        lines.append("")
    lines.append("## Run")
    lines.append("")
    ex = result.executor
    lines.append(
        f"Executor: {ex['kind']}"
        + (f", {ex['workers']} workers" if ex.get("workers") else "")
        + (f", scheduler {ex['scheduler']}" if ex.get("scheduler") else "")
        + f", {ex['tasks']} tasks of up to {ex.get('batch_size')} runs. Protocol wall time "
        f"{result.timing.get('total', float('nan')):.1f} s (writing files and figures excluded)."
    )
    lines.append("")
    lines.append(
        "Versions: " + ", ".join(f"{k} {v}" for k, v in result.versions.items() if k != "platform")
    )
    lines.append("")
    return "\n".join(lines)


def _clean(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


# ---------------------------------------------------------------------- figures
_COLORS = {
    "two_point": "tab:orange",
    "generalized": "tab:blue",
    "no_steering": "tab:gray",
    "oracle": "tab:green",
}
_USER_COLORS = ["tab:purple", "tab:red", "tab:brown", "tab:pink", "tab:olive", "tab:cyan"]


def _color(name: str, users: list[str]) -> str:
    if name in _COLORS:
        return _COLORS[name]
    if name not in users:
        users.append(name)
    return _USER_COLORS[users.index(name) % len(_USER_COLORS)]


def _subplots(*args: Any, figsize: tuple[float, float], **kwargs: Any) -> tuple[Figure, Any]:
    """``pyplot.subplots`` without pyplot: a stand-alone :class:`~matplotlib.figure.Figure`
    (no GUI backend, nothing global to close)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


def write_figures(result: BenchmarkResult, out: Path) -> dict[str, str]:
    """Write the PNG figures; returns {key: file name} of those written."""
    plots = result.plots
    users: list[str] = []
    written: dict[str, str] = {}
    trace = plots.get("trace") or {}
    run = plots.get("plot_run") or {}
    run_label = f"driver {run.get('driver')}, {run.get('track')} run {run.get('run')}"

    def save(fig: Any, key: str) -> None:
        fig.tight_layout()
        fig.savefig(out / FIGURES[key], dpi=110)
        written[key] = FIGURES[key]

    if trace.get("predictions"):
        save(_steering_figure(trace, run_label, users), "steering_prediction")
    if plots.get("training_acf") or plots.get("validation_acf"):
        fig = _acf_figure(plots, users)
        if fig is not None:
            save(fig, "residual_acf")
    if trace.get("estimates"):
        save(_estimate_figure(trace, run_label, users, plots), "lateral_estimate")
    if plots.get("early_error"):
        save(_error_figure(plots, result, users), "lateral_error")
    curved = plots.get("curved_trace") or {}
    if curved.get("predictions"):
        c = plots.get("curved_run") or {}
        label = f"driver {c.get('driver')}, curved run {c.get('run')}"
        save(_steering_figure(curved, label, users), "curved_steering")
    return written


def _steering_figure(trace: dict, label: str, users: list[str]) -> Any:
    t = trace["time"]
    fig, (top, bottom) = _subplots(2, 1, figsize=(9, 6), sharex=True)
    top.plot(t, trace["steering"], color="black", lw=2.2, label="measured")
    for name, pred in trace["predictions"].items():
        top.plot(t, pred, lw=1.0, ls="--", color=_color(name, users), label=f"{name} (one step)")
        bottom.plot(t, trace["steering"] - pred, lw=0.8, color=_color(name, users), label=name)
    top.set_ylabel("steering angle delta (rad)")
    top.set_title(f"Steering: measured vs one-step prediction ({label})")
    top.legend(fontsize=8)
    bottom.set_ylabel("measured - predicted (rad)")
    bottom.set_xlabel("time (s)")
    bottom.set_yscale("symlog", linthresh=1e-6)
    bottom.legend(fontsize=8)
    return fig


def _acf_figure(plots: dict, users: list[str]) -> Any:
    names = list(dict.fromkeys([*plots.get("training_acf", {}), *plots.get("validation_acf", {})]))
    if not names:
        return None
    fig, axes = _subplots(1, len(names), figsize=(4.2 * len(names), 3.6), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        training = plots.get("training_acf", {}).get(name)
        validation = plots.get("validation_acf", {}).get(name)
        if training is not None:
            acf = np.asarray(training["acf"])
            ax.stem(np.arange(acf.size), acf, linefmt="C7-", markerfmt="C7o", basefmt=" ",
                    label="training run")  # fmt: skip
            band = training["band"]
            if band is not None and np.isfinite(band):
                ax.axhspan(-band, band, color="tab:blue", alpha=0.15, label="95 % band (white)")
        if validation is not None:
            acf = np.asarray(validation)
            ax.plot(np.arange(acf.size), acf, color=_color(name, users), lw=1.5,
                    label=f"validation mean ({plots.get('detail_driver')})")  # fmt: skip
        ax.set_title(f"{name}: residual autocorrelation")
        ax.set_xlabel("lag (samples)")
        ax.set_ylim(-1.05, 1.05)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("autocorrelation")
    return fig


def _estimate_figure(trace: dict, label: str, users: list[str], plots: dict) -> Any:
    truth = trace["truth_lateral"]
    dt = plots.get("dt", 0.01)
    t = np.arange(truth.size) * dt
    fig, axes = _subplots(2, 2, figsize=(11, 6.5), sharex="col",
                             gridspec_kw={"width_ratios": [2, 1]})  # fmt: skip
    zoom = min(float(t[-1]), 2.0)
    for col, limit in enumerate((float(t[-1]), zoom)):
        top, bottom = axes[0][col], axes[1][col]
        top.plot(t, truth, color="black", lw=2.2, label="truth")
        for name, est in trace["estimates"].items():
            top.plot(t, est["lateral"], lw=1.1, color=_color(name, users), label=name)
            if len(est["hypotheses"]) > 1:
                bottom.plot(t, est["true_weight"], lw=1.1, color=_color(name, users), label=name)
        top.set_xlim(0, limit)
        bottom.set_xlim(0, limit)
        bottom.set_ylim(-0.03, 1.03)
        bottom.axhline(0.95, color="black", lw=0.6, ls=":")
        bottom.set_xlabel("time (s)")
    axes[0][0].set_ylabel("lateral offset y (m)")
    axes[1][0].set_ylabel("weight of the true lane")
    axes[0][0].set_title(
        f"Lateral estimate vs truth ({label}; true bias {trace.get('bias', float('nan')):g} m)"
    )
    axes[0][1].set_title(f"first {zoom:g} s")
    axes[0][0].legend(fontsize=8)
    return fig


def _error_figure(plots: dict, result: BenchmarkResult, users: list[str]) -> Any:
    dt = plots.get("dt", 0.01)
    fig, ax = _subplots(figsize=(8, 4.5))
    order = [m for m in result.model_names if m in plots["early_error"]]
    order += [b for b in BASELINES if b in plots["early_error"]]
    runs = 0
    for name in order:
        stats = plots["early_error"][name]
        mean, std = np.asarray(stats["mean"]), np.asarray(stats["std"])
        t = np.arange(mean.size) * dt
        color = _color(name, users)
        ax.plot(t, mean, color=color, lw=1.5, label=name)
        ax.fill_between(t, np.maximum(mean - std, 1e-4), mean + std, color=color, alpha=0.15)
        runs = stats["runs"]
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|lateral error| (m)")
    ax.set_title(
        f"Lateral error, mean and std over {runs} validation runs of driver "
        f"{plots.get('detail_driver')}"
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


# ----------------------------------------------------------------------- output
def write_outputs(
    result: BenchmarkResult, out_dir: str | Path, *, figures: bool = True
) -> dict[str, Path]:
    """Write results.json, the CSV tables, report.md and (optionally) the figures.

    Returns:
        {name: path} of every file written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    doc = result.to_json_dict()
    path = out / "results.json"
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    written["results.json"] = path
    for attribute, name in CSV_TABLES.items():
        rows = doc[attribute]
        frame = _table_frame(rows)
        if attribute in ("steering", "curved", "estimation", "summary") or not frame.empty:
            frame.to_csv(out / name, index=False)
            written[name] = out / name
    figure_names = write_figures(result, out) if figures else {}
    for name in figure_names.values():
        written[name] = out / name
    report = out / "report.md"
    report.write_text(markdown_report(result, figure_names), encoding="utf-8")
    written["report.md"] = report
    return written

"""The figures of a benchmark result (matplotlib's object-oriented API, no pyplot).

The figures of the paper, on our data: steering prediction on one validation
run (paper Fig. 4), residual autocorrelation (Fig. 5), the lateral estimate
and the true lane's weight (Fig. 8), the lateral error over the first
seconds (Fig. 9), steering on the curved track (Fig. 7). They show the
first population seed. Beside them, the reliability diagram of the lane probabilities over
every seed (issue 25; the report's reliability table drawn).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from benchmarks.protocol import BASELINES, BenchmarkResult

__all__ = ["FIGURES", "write_figures"]

FIGURES = {
    "steering_prediction": "steering_prediction.png",
    "residual_acf": "residual_acf.png",
    "lateral_estimate": "lateral_estimate.png",
    "lateral_error": "lateral_error.png",
    "curved_steering": "curved_steering.png",
    "reliability": "reliability.png",
}
"""Figure key -> file name."""


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
    rows = [r for r in result.summary if r.get("reliability") and r.get("kind") != "stress"]
    if rows:
        save(_reliability_figure(rows, users), "reliability")
    return written


def _reliability_figure(rows: list[dict[str, Any]], users: list[str]) -> Any:
    """Per estimator (the stress set's left to the table), the share of the (step,
    hypothesis) pairs of each probability bin whose hypothesis was the true lane against the
    mean probability given there; marker area by the bin's share of the pairs."""
    fig, ax = _subplots(figsize=(6.5, 6))
    ax.plot([0, 1], [0, 1], color="black", lw=0.8, ls="--", label="calibrated")
    for row in rows:
        bins = [b for b in row["reliability"] if b is not None]
        predicted, observed, count = (np.array(v, dtype=float) for v in zip(*bins, strict=True))
        color = _color(row["model"], users)
        ece = row.get("lane_ece")
        label = row["model"] if ece is None else f"{row['model']} (ECE {ece:.3f})"
        ax.plot(predicted, observed, color=color, lw=1.0, alpha=0.7)
        area = 10.0 + 400.0 * count / count.sum()
        ax.scatter(predicted, observed, s=area, color=color, alpha=0.7, label=label)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    ax.set_xlabel("probability given to a lane hypothesis (bin mean)")
    ax.set_ylabel("share of those that were the true lane")
    ax.set_title("Reliability of the lane probabilities, main track, every seed")
    ax.grid(True, alpha=0.3)
    legend = ax.legend(fontsize=8, loc="upper left")
    for handle in legend.legend_handles:  # one marker size in the legend
        if hasattr(handle, "set_sizes"):
            handle.set_sizes([30.0])
    return fig


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

"""The data behind the report's figures."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.models import FittedModel, ModelError
from benchmarks.protocol.plan import RunRef
from benchmarks.protocol.tasks import ChunkResult
from hasa_env.steering import residual_diagnostics

__all__ = ["plot_data"]


def plot_data(
    chunks: Sequence[ChunkResult],
    fitted: Sequence[FittedModel],
    failed: Mapping[str, ModelError],
    plot_run: RunRef,
    curved_runs: Sequence[RunRef],
    train: pd.DataFrame,
    config: ProtocolConfig,
) -> dict[str, Any]:

    traces: dict[tuple, dict] = {}
    early: dict[str, list[np.ndarray]] = defaultdict(list)
    acf: dict[str, list[np.ndarray]] = defaultdict(list)
    for chunk in chunks:
        for key, trace in chunk.traces.items():
            traces.setdefault(key, {}).update(trace)
        for name, arrays in chunk.early_errors.items():
            early[name] += arrays
        for name, arrays in chunk.acf.items():
            acf[name] += arrays
    ok = [m for m in fitted if m.name not in failed]
    training_acf = {}
    for m in ok:
        result = m.model.fit_result
        if result is not None:
            training_acf[m.name] = residual_diagnostics(result.residuals, lags=config.acf_lags)
    validation_acf = {}
    for name, arrays in acf.items():
        if name in failed or not arrays:
            continue
        size = min(len(a) for a in arrays)
        validation_acf[name] = np.nanmean(np.stack([a[:size] for a in arrays]), axis=0)
    plot_trace = traces.get(plot_run.key, {})
    if "predictions" in plot_trace:
        plot_trace["predictions"] = {
            k: v for k, v in plot_trace["predictions"].items() if k not in failed
        }
    if "estimates" in plot_trace:
        plot_trace["estimates"] = {
            k: v for k, v in plot_trace["estimates"].items() if k not in failed
        }
    curved_trace = traces.get(curved_runs[0].key, {}) if curved_runs else {}
    if "predictions" in curved_trace:
        curved_trace["predictions"] = {
            k: v for k, v in curved_trace["predictions"].items() if k not in failed
        }
    early_stats = {}
    for name, arrays in early.items():
        if name in failed or not arrays:
            continue
        size = min(len(a) for a in arrays)
        stack = np.abs(np.stack([a[:size] for a in arrays]))
        early_stats[name] = {
            "mean": np.nanmean(stack, axis=0),
            "std": np.nanstd(stack, axis=0),
            "runs": len(arrays),
        }
    dt = float(np.median(np.diff(train["time"].to_numpy()))) if len(train) > 1 else 0.01
    return {
        "plot_run": {"driver": plot_run.driver, "track": plot_run.track, "run": plot_run.index},
        "trace": plot_trace,
        "curved_trace": curved_trace,
        "curved_run": None
        if not curved_runs
        else {"driver": curved_runs[0].driver, "run": curved_runs[0].index},
        "training_acf": {
            k: {"acf": v.autocorrelation, "band": v.confidence_band, "n": v.n}
            for k, v in training_acf.items()
        },
        "validation_acf": validation_acf,
        "early_error": early_stats,
        "dt": dt,
        "detail_driver": plot_run.driver,
    }

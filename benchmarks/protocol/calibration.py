"""The lane probabilities' calibration in the verdict: the expected calibration error with its
bootstrap interval, and the reliability table (docs/design.md §8.14)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.intervals import (
    BOOTSTRAP_RESAMPLES,
    BOOTSTRAP_SEED,
    percentile_interval,
)
from estimators.calibration import expected_calibration_error

__all__ = ["lane_calibration"]


def _run_calibration_bins(frame: pd.DataFrame) -> tuple[np.ndarray, list[np.ndarray]] | None:
    """The per-run reliability bins of ``frame``'s rows, (R, 3, B), and the same runs grouped
    by seed (recordings: one group); None when no row has them."""
    if "calibration_count" not in frame or not len(frame):
        return None
    rows = frame.dropna(subset=["calibration_count"])
    if not len(rows):
        return None
    bins = np.stack(
        [
            np.array([c, p, o], dtype=np.float64)
            for c, p, o in zip(
                rows["calibration_count"],
                rows["calibration_predicted"],
                rows["calibration_observed"],
                strict=True,
            )
        ]
    )
    seed_of = rows["seed"].astype(object).where(rows["seed"].notna(), "")  # recordings: one
    groups = [bins[np.flatnonzero((seed_of == s).to_numpy())] for s in dict.fromkeys(seed_of)]
    return bins, groups


def _ece_replicates(groups: Sequence[np.ndarray]) -> np.ndarray:
    """Bootstrap replicates of the ECE: seeds resampled, then runs within each seed, with the
    verdict's number of resamples and generator seed (:mod:`benchmarks.protocol.intervals`)."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    replicates = np.empty(BOOTSTRAP_RESAMPLES)
    for b in range(BOOTSTRAP_RESAMPLES):
        picked = [groups[j] for j in rng.integers(len(groups), size=len(groups))]
        replicates[b] = expected_calibration_error(
            sum(g[rng.integers(len(g), size=len(g))].sum(axis=0) for g in picked)
        )
    return replicates


def lane_calibration(table: pd.DataFrame, runs: Sequence[dict[str, Any]]) -> None:
    """``lane_ece`` per model in ``table`` with its 95 % interval (percentile bootstrap: seeds
    resampled, then runs within each seed), and ``reliability`` (per bin of the lane
    probability, of equal width on [0, 1]: the mean probability given and the share that was
    the true lane; None for an empty bin) from the per-run bins of
    :func:`estimators.calibration.lane_calibration_bins`."""
    frame = pd.DataFrame(list(runs))
    for key in ("lane_ece", "lane_ece_ci_low", "lane_ece_ci_high", "reliability"):
        table[key] = None
    if not len(frame) or "calibration_count" not in frame:
        return
    for i, name in table["model"].items():
        found = _run_calibration_bins(frame[frame["model"] == name])
        if found is None:
            continue
        bins, groups = found
        total = bins.sum(axis=0)
        table.at[i, "lane_ece"] = expected_calibration_error(total)
        table.at[i, "reliability"] = [  # type: ignore[assignment]  # a list in an object cell
            None if n == 0 else [round(p / n, 4), round(o / n, 4), int(n)]
            for n, p, o in zip(*total, strict=True)
        ]
        if len(bins) >= 2:
            low, high = percentile_interval(_ece_replicates(groups)[:, None])
            table.at[i, "lane_ece_ci_low"] = float(low[0])
            table.at[i, "lane_ece_ci_high"] = float(high[0])

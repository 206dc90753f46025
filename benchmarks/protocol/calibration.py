"""The lane probabilities' calibration in the verdict: the expected calibration error with its
bootstrap interval, and the reliability table (docs/design.md §8.14)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from estimators.calibration import expected_calibration_error

__all__ = ["CALIBRATION_REPLICATES", "lane_calibration"]


CALIBRATION_REPLICATES = 1000
"""Bootstrap replicates of the expected calibration error's interval."""


def _run_calibration_bins(frame: pd.DataFrame) -> np.ndarray | None:
    """(R, 3, B) the per-run reliability bins of ``frame``'s rows (None: no row has them)."""
    if "calibration_count" not in frame or not len(frame):
        return None
    rows = frame.dropna(subset=["calibration_count"])
    if not len(rows):
        return None
    return np.stack(
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
    rng = np.random.default_rng(20261202)
    for i, name in table["model"].items():
        mine = frame[frame["model"] == name]
        bins = _run_calibration_bins(mine)
        if bins is None:
            continue
        total = bins.sum(axis=0)
        table.at[i, "lane_ece"] = expected_calibration_error(total)
        table.at[i, "reliability"] = [  # type: ignore[assignment]  # a list in an object cell
            None if n == 0 else [round(p / n, 4), round(o / n, 4), int(n)]
            for n, p, o in zip(*total, strict=True)
        ]
        rows = mine[mine["calibration_count"].notna()]
        seed_of = rows["seed"].astype(object).where(rows["seed"].notna(), "")  # recordings: one
        groups = [bins[np.flatnonzero((seed_of == s).to_numpy())] for s in dict.fromkeys(seed_of)]
        replicates = np.empty(CALIBRATION_REPLICATES)
        for b in range(CALIBRATION_REPLICATES):
            picked = [groups[j] for j in rng.integers(len(groups), size=len(groups))]
            replicates[b] = expected_calibration_error(
                sum(g[rng.integers(len(g), size=len(g))].sum(axis=0) for g in picked)
            )
        if len(bins) >= 2:
            low, high = np.percentile(replicates, [2.5, 97.5])
            table.at[i, "lane_ece_ci_low"], table.at[i, "lane_ece_ci_high"] = low, high

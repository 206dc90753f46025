"""examples/bend_residuals.py (docs/design.md §8.28) runs and gives, per seed, the curvature
feed-forward and the residual statistics it cites."""

from __future__ import annotations

import math
from types import ModuleType

import numpy as np
from _programs import load_example


def _example() -> ModuleType:
    return load_example("bend_residuals")


def test_the_example_gives_one_row_per_seed_with_its_feedforward(capsys) -> None:
    module = _example()
    table = module.main(["--seeds", "8201", "--runs", "1"])
    row = table.iloc[0]
    assert list(table["seed"]) == [8201] and "G_standard_error" in capsys.readouterr().out
    assert 0 < row["G_standard_error"] <= 0.25 * abs(row["G"])  # this fit gets the feed-forward
    for key in ("rms_bends", "rms_straights"):
        assert 1e-6 < row[key] < 1e-3  # rad: the size of a model's residual level
    for key in ("acf_bends", "acf_straights", "max_abs_corr_curvature_change"):
        assert -1.0 <= row[key] <= 1.0 and math.isfinite(row[key])


def test_a_feedforward_a_second_late_correlates_with_the_curvatures_change() -> None:
    """The statistic the example reads sees a feed-forward in the wrong place: a residual made
    of the curvature's change one second later is found at that lead, and white noise is not."""
    module = _example()
    t = np.arange(3000)
    kappa = np.where((t > 800) & (t < 2000), 1 / 150, 0.0)
    late = np.roll(kappa, -100) - kappa
    assert module._largest_change_correlation(late, kappa) > 0.99
    noise = np.random.default_rng(0).normal(size=t.size)
    assert module._largest_change_correlation(noise, kappa) < 0.1

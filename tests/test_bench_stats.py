"""The verdict's statistics (benchmarks.protocol.intervals) and verdicts of recorded studies.

- the hierarchical percentile bootstrap stays inside its quantity's range, is reproducible,
  and covers a known mean about as often as it says;
- Clopper-Pearson bounds on 0/n and n/n and against the binomial distribution;
- ranks in every bootstrap replicate among every model;
- ``hasa-bench paper --recordings`` on a small study of three participants gives the
  verdict, lane-decision and per-seed tables, the headline and non-empty summaries.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from benchmarks.protocol.aggregate import verdict
from benchmarks.protocol.gain import steering_free_gain
from benchmarks.protocol.intervals import (
    clopper_pearson,
    hierarchical_bootstrap,
    percentile_interval,
    replicate_ranks,
)
from benchmarks.schema import folder_problems
from hasa_cli.bench import main


def _groups(rng: np.random.Generator, draw, seeds: int = 5, drivers: int = 6) -> list[np.ndarray]:
    return [np.asarray(draw(rng, (drivers, 1)), dtype=float) for _ in range(seeds)]


@pytest.mark.parametrize(
    ("draw", "low", "high"),
    [
        (lambda rng, size: np.abs(rng.normal(0.05, 0.3, size)), 0.0, np.inf),  # an RMSE
        (lambda rng, size: rng.chisquare(1, size) * 20.0, 0.0, np.inf),  # a skewed NEES
        (lambda rng, size: 1.0 - rng.exponential(3.0, size), -np.inf, 1.0),  # an R^2
        (lambda rng, size: rng.integers(0, 2, size).astype(float), 0.0, 1.0),  # a share
    ],
)
def test_bootstrap_intervals_stay_in_the_quantitys_range(draw, low, high) -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        groups = _groups(rng, draw)
        lo, hi = percentile_interval(hierarchical_bootstrap(groups, resamples=500))
        values = np.concatenate(groups)
        assert low <= values.min() <= lo[0] <= hi[0] <= values.max() <= high


def test_bootstrap_is_reproducible_and_handles_missing_values() -> None:
    rng = np.random.default_rng(0)
    groups = _groups(rng, lambda r, size: r.normal(size=size))
    groups[1][:, 0] = np.nan  # a seed without this model's values
    first = hierarchical_bootstrap(groups)
    assert np.array_equal(first, hierarchical_bootstrap(groups))
    assert not np.array_equal(first, hierarchical_bootstrap(groups, seed=5))
    assert np.isfinite(first).all()
    median = hierarchical_bootstrap([np.array([[1.0], [2.0], [100.0]])], median=True)
    assert set(np.unique(median)) <= {1.0, 2.0, 100.0}


def test_hierarchical_bootstrap_covers_a_known_mean() -> None:
    """Seeds shift their drivers' mean (sd 1), drivers vary around it (sd 1): the interval
    of the grand mean over 20 seeds x 10 drivers covers 0 in about 95 % of the studies."""
    rng = np.random.default_rng(11)
    covered = 0
    studies = 200
    for _ in range(studies):
        groups = [rng.normal(rng.normal(), 1.0, (10, 1)) for _ in range(20)]
        lo, hi = percentile_interval(hierarchical_bootstrap(groups, resamples=400))
        covered += lo[0] <= 0.0 <= hi[0]
    assert 0.88 <= covered / studies <= 0.99


def test_clopper_pearson_bounds() -> None:
    low, high = clopper_pearson(0, 20)
    assert low == 0.0 and high == pytest.approx(1.0 - 0.025 ** (1 / 20))
    low, high = clopper_pearson(20, 20)
    assert high == 1.0 and low == pytest.approx(0.025 ** (1 / 20))
    low, high = clopper_pearson(3, 485)
    # the exact bounds: P(X >= 3 | low) = P(X <= 3 | high) = 2.5 %
    assert stats.binom.sf(2, 485, low) == pytest.approx(0.025, rel=1e-6)
    assert stats.binom.cdf(3, 485, high) == pytest.approx(0.025, rel=1e-6)
    assert all(np.isnan(clopper_pearson(0, 0)))


def test_replicate_ranks_rank_every_model() -> None:
    replicates = np.array([[0.3, 0.1, 0.2, np.nan], [0.1, 0.1, 0.5, 0.7]])
    assert replicate_ranks(replicates).tolist() == [[3, 1, 2, 0], [1, 1, 3, 4]]


def test_verdict_of_one_seed_resamples_the_drivers_and_ranks_all_models() -> None:
    seed_rows, estimation = [], []
    values = {"a": [0.2, 0.3, 0.4], "b": [0.5, 0.1, 0.6], "no_steering": [0.9, 0.9, 0.9]}
    for model, per_driver in values.items():
        seed_rows.append({"seed": None, "model": model, "drivers": 3, "runs": 6,
                          "lateral_rmse": float(np.mean(per_driver)), "estimated_runs": 6,
                          "wrong_lane_confident_runs": 0 if model == "a" else 6})  # fmt: skip
        estimation += [
            {"seed": None, "driver": f"P{i}", "model": model, "lateral_rmse_mean": v}
            for i, v in enumerate(per_driver)
        ]
    kinds = {"a": "builtin", "b": "user"}
    rows = {r["model"]: r for r in verdict(seed_rows, ["a", "b"], kinds, estimation=estimation)}
    assert rows["a"]["seeds"] == 1
    assert (
        0.2 <= rows["a"]["lateral_rmse_ci_low"] < rows["a"]["lateral_rmse_ci_high"] <= 0.4 + 1e-12
    )
    assert rows["no_steering"]["lateral_rmse_ci_low"] == rows["no_steering"]["lateral_rmse"]
    assert [rows[m]["rank_lateral"] for m in ("a", "b", "no_steering")] == [1, 2, 3]
    assert rows["a"]["rank_lateral_models"] == 3
    # the drivers are resampled together for every model: b beats a on some replicates
    assert 0.5 < rows["a"]["rank_lateral_stability"] < 1.0
    assert 0.5 < rows["b"]["rank_lateral_stability"] < 1.0
    assert rows["no_steering"]["rank_lateral_stability"] == 1.0
    assert rows["a"]["wrong_lane_confident_runs_share_ci_low"] == 0.0
    assert rows["b"]["wrong_lane_confident_runs_share_ci_high"] == 1.0


# ------------------------------------------------------------------ a recorded study
def test_a_recorded_study_gets_the_verdict_tables_and_the_headline(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from benchmarks.protocol import ProtocolConfig
    from hasa_env.drivers import population, run_population, save_runs

    config = ProtocolConfig(drivers=3, runs=2, duration=3.0, population="paper-pi")
    drivers = population("paper-pi", seed=7, size=3)
    runs = run_population(drivers, runs=2, seed=7, config=config.env_config())
    folder = tmp_path / "study"
    for participant, frames in zip(("P01", "P02", "P03"), runs.values(), strict=True):
        save_runs(frames, folder / participant, prefix="measured")
    out = tmp_path / "bench"
    code = main(["paper", "--recordings", str(folder), "--out", str(out), "--no-plots",
                 "--workers", "1", "--min-duration", "1"])  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["format_version"] == 3
    page = (out / "report.html").read_text()
    assert folder_problems(out) == [] and "Verdict over the recordings" in page
    summary = {r["model"]: r for r in doc["summary"]}
    assert {"two_point", "generalized", "no_steering", "oracle"} <= set(summary)
    assert doc["seed_summary"] and all(r["seed"] is None for r in doc["seed_summary"])
    gen = summary["generalized"]
    assert gen["seeds"] == 1 and gen["drivers"] == 3
    assert gen["lateral_rmse_ci_low"] is not None and gen["rank_lateral"] is not None
    assert gen["wrong_lane_confident_runs_share_ci_high"] is not None
    oracle = summary["oracle"]  # decides at once, on every run
    assert oracle["time_to_decide_median"] == 0.0 and oracle["never_decided_runs"] == 0
    assert oracle["decided_time_share"] == pytest.approx(1.0, abs=0.05)
    assert 0.0 <= oracle["lateral_rmse_after_decision"] < 0.05
    for title in ("Verdict over the recordings", "Lane decisions over the recordings",
                  "Per seed: means over drivers", "Headline (ours vs the paper)"):  # fmt: skip
        assert title in text
    assert "(no rows)" not in text
    report = (out / "report.md").read_text()
    assert "## Summary" in report and "(no rows)" not in report


def test_decision_metrics_of_a_run() -> None:
    from benchmarks.protocol.aggregate import _censored_quantile
    from benchmarks.protocol.tasks import _decision_metrics

    # run 0: passes 0.95 at step 2, drops back at step 3, stays above from step 4 on;
    # run 1 never passes; run 2 is 3 steps long (the rest invalid) and decided at once
    weight = np.array([[0.5, 0.9, 0.97, 0.6, 0.96, 0.99],
                       [0.5, 0.5, 0.5, 0.5, 0.5, 0.5],
                       [0.99, 0.99, 0.99, np.nan, np.nan, np.nan]])  # fmt: skip
    valid = np.isfinite(weight)
    time = np.where(valid, np.arange(6) * 0.1 + 1.0, np.nan)
    error = np.array([[1.0, 1.0, 1.0, 1.0, 0.3, 0.4], [0.5] * 6, [0.1, 0.1, 0.1] + [np.nan] * 3])
    m = _decision_metrics(weight, valid, time, error, 0.95)
    assert m["time_to_decide"][0] == pytest.approx(0.2) and np.isnan(m["time_to_decide"][1])
    assert m["time_to_decide"][2] == 0.0
    assert m["decided_time_share"].tolist() == pytest.approx([0.5, 0.0, 1.0])
    after = m["lateral_rmse_after_decision"]
    assert after[0] == pytest.approx(np.sqrt((0.3**2 + 0.4**2) / 2)) and np.isnan(after[1])
    assert after[2] == pytest.approx(0.1)
    # quantiles with runs that never decided as infinite times; None (degenerate) dropped
    assert _censored_quantile([0.2, np.inf, 0.0, None], 0.5) == 0.2
    assert _censored_quantile([0.2, np.inf, np.inf], 0.5) is None
    assert _censored_quantile([None], 0.5) is None


def test_gain_over_the_best_steering_free_baseline_per_seed() -> None:
    """Per seed the better of no_steering and lane_centring is the reference; the gain is
    its lateral RMSE minus the model's, averaged over seeds, with a paired interval."""
    names = ["m", "no_steering", "lane_centring", "oracle"]
    seed_a = np.array([[0.1, 0.9, 0.3, 0.0], [0.2, 0.9, 0.2, 0.0]])  # lane_centring best: 0.25
    seed_b = np.array([[0.3, 0.9, 1.0, 0.0], [0.3, 0.9, 1.2, 0.0]])  # no_steering best: 0.9
    gain = steering_free_gain([seed_a, seed_b], names)
    expected = (np.array([0.25, 0.25, 0.25, 0.25]) - seed_a.mean(axis=0)
                + np.array([0.9, 0.9, 0.9, 0.9]) - seed_b.mean(axis=0)) / 2  # fmt: skip
    np.testing.assert_allclose(gain["gain_over_steering_free"], expected)
    low, high = gain["gain_over_steering_free_ci_low"], gain["gain_over_steering_free_ci_high"]
    assert np.all(low <= expected + 1e-12) and np.all(expected <= high + 1e-12)
    without = steering_free_gain([seed_a[:, [0, 3]]], ["m", "oracle"])
    assert np.isnan(without["gain_over_steering_free"]).all()

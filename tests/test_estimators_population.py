"""The paper's estimation result on the synthetic population (issue 4's Done means).

The generalized model with the paper's coefficients (GeneralizedModel.paper())
drives the mixture filter on runs of the default synthetic population
("Ill", "1".."8"; docs/design.md §9.1 protocol: 30 s on the straight track
from v = 15 m/s, y = -0.5 m, two lanes 1.8 m apart), once with each
hypothesis true. Four runs per driver keep the test short; the benchmark runs
the full protocol.
"""

from __future__ import annotations

import numpy as np
import pytest

from estimators.baselines import NoSteeringEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.offline import run_estimator
from hasa_env.drivers import population, run_population
from hasa_env.steering import GeneralizedModel

RUNS_PER_DRIVER = 4

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def results() -> dict[int, dict[str, np.ndarray]]:
    drivers = population("paper", seed=0)
    arx = GeneralizedModel.paper().arx()
    out = {}
    for bias_index in (0, 1):
        runs = run_population(
            drivers, runs=RUNS_PER_DRIVER, seed=0, options={"bias_index": bias_index}
        )
        names = list(runs)
        frames = [f for name in names for f in runs[name]]
        res = run_estimator(GaussianMixtureEKF(arx), frames)
        owner = np.repeat(names, RUNS_PER_DRIVER)
        out[bias_index] = {
            "names": names,
            "owner": owner,
            "rmse": res.lateral_rmse(),
            "picked": res.picked_true_lane(),
            "true_weight": res.true_lane_weight(),
            "frames": frames,
        }
    return out


def test_mixture_picks_the_true_lane_whichever_is_true(results):
    for bias_index, r in results.items():
        assert r["picked"].all(), bias_index
        # decided within 2 s and never doubted afterwards (the tempered evidence of
        # estimators.evidence: measured 0.02-1.22 s; the raw eq. 19 decides within 0.04 s)
        assert np.all(r["true_weight"][:, 200:] > 0.99), bias_index


def test_mean_lateral_rmse_below_a_quarter_metre_for_every_driver(results):
    for bias_index, r in results.items():
        assert r["rmse"].mean() < 0.25, bias_index
        for name in r["names"]:
            assert r["rmse"][r["owner"] == name].mean() < 0.25, (bias_index, name)


def test_swapping_the_true_hypothesis_keeps_the_error_statistics(results):
    for name in results[0]["names"]:
        a = results[0]["rmse"][results[0]["owner"] == name]
        b = results[1]["rmse"][results[1]["owner"] == name]
        # the start (0.5 m off the true centre) lies toward the other hypothesis in one case
        # and away from it in the other; the aim cap's 10 s average remembers it (docs/design.md
        # §8.23): measured 0.0002-0.0070 m apart (0.0026 m with its former 2 s average)
        assert abs(a.mean() - b.mean()) < 0.01, name
        assert abs(a.std() - b.std()) < 0.005, name


def test_without_steering_the_population_is_confused(results):
    frames = results[0]["frames"][::RUNS_PER_DRIVER]  # one run per driver
    rmse = run_estimator(NoSteeringEKF(), frames).lateral_rmse()
    assert np.all(np.abs(rmse - 0.9) < 0.05)

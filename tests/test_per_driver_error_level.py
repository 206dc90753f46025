"""examples/per_driver_error_level.py (issue 25's live share with a level of the equation error
per driver; docs/design.md §8.35): the driver's own error is refitted on its calibration run
without touching the pooled model, and both filters run on the same runs."""

from __future__ import annotations

import numpy as np
import pytest
from _programs import load_example


@pytest.mark.slow  # fits a seed's models (about 15 s) and filters two runs twice
def test_driver_level_refits_the_error_only_and_leaves_the_pooled_model() -> None:
    module = load_example("per_driver_error_level")
    from benchmarks.protocol.run import builtin_model
    from benchmarks.protocol.tasks import model_estimator
    from estimators import run_estimator
    from estimators.settings import FilterSettings
    from hasa_env.drivers import SyntheticDriver, run_driver

    config, plan, fitted = builtin_model(8300)
    pooled = fitted.model.equation_error_speed_scaled.to_dict()
    frames = run_driver(
        SyntheticDriver(plan.params["3"]), runs=2, seed=8300103, config=config.env_config()
    )
    own, found = module.with_driver_level(fitted, frames[0])
    assert found and own is not fitted
    assert fitted.model.equation_error_speed_scaled.to_dict() == pooled  # not touched
    mine = own.model.equation_error_speed_scaled.to_dict()
    assert mine != pooled and mine["coloured_std"] > 0
    assert own.training.speed_scaled_gain is not None and own.training.speed_scaled_gain > 0
    same = own.model.parameter_vector, fitted.model.parameter_vector
    np.testing.assert_array_equal(*same)  # the same coefficients
    floor, _ = module.with_driver_level(fitted, frames[0], at_least_pooled=True)
    floored = floor.model.equation_error_speed_scaled.to_dict()
    for level in ("coloured_std", "white_std"):
        assert floored[level] == max(mine[level], pooled[level])
    assert floored["correlation"] == mine["correlation"]
    base = FilterSettings.from_env_config(frames[0].attrs["config"])
    rows = [
        module.summary(run_estimator(model_estimator(m, base), frames[1:])) for m in (fitted, own)
    ]
    for row in rows:
        assert 0.0 <= row["live"] <= 1.0 and 0.0 < row["lateral_rmse"] < 0.5
        assert 0.0 <= row["decided_right"] <= 1.0
        assert row["ends_wrong"] == 0
    assert rows[0]["lateral_rmse"] != rows[1]["lateral_rmse"]  # the filters differ

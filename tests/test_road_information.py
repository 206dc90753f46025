"""The road-blind baseline (RoadBlindModel) and the road information of a steering model:
1 - SSE_model / SSE_road_blind on held-out runs (docs/design.md §6.3)."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from benchmarks.protocol.plan import RunRef
from benchmarks.protocol.tasks import _add_road_information
from hasa_env.steering import (
    ARXForm,
    GeneralizedModel,
    RoadBlindModel,
    SteeringFitWarning,
    SteeringModel,
    road_information,
)


def arx_data(arx: ARXForm, n: int, rng: np.random.Generator) -> pd.DataFrame:
    """Open-loop features of an ARX model (no omega, no v_y) driven by coloured bearings,
    with equation noise 1e-3 rad."""
    phi = 0.02 * np.convolve(rng.standard_normal(n + 4), np.ones(5) / np.sqrt(5), "valid")
    noise = 1e-3 * rng.standard_normal(n)
    delta = np.zeros(n)
    for k in range(max(len(arx.a), len(arx.b)), n):
        delta[k] = (
            sum(c * delta[k - i] for i, c in enumerate(arx.a, start=1))
            + sum(c * phi[k - i] for i, c in enumerate(arx.b))
            + noise[k]
        )
    frame = pd.DataFrame({"delta": delta, "phi": phi, "omega": 0.0, "lateral_velocity": 0.0,
                          "speed": 15.0})  # fmt: skip
    frame.attrs = {"near_distance": 6.2, "far_distance": 20.0, "decision_lag": 1, "dt": arx.dt}
    return frame


def test_road_information_is_one_minus_the_ratio_of_sses_on_common_samples() -> None:
    model = np.array([np.nan, 1.0, -2.0, 0.5, 3.0])
    blind = np.array([4.0, np.nan, 2.0, 1.0, -4.0])
    # common samples: 2, 3, 4 -> SSE 4 + 0.25 + 9 against 4 + 1 + 16
    assert road_information(model, blind) == pytest.approx(1.0 - 13.25 / 21.0)
    assert road_information(blind, blind) == 0.0
    assert road_information(np.zeros(5), blind) == 1.0
    assert road_information(2.0 * blind, blind) == pytest.approx(-3.0)  # worse than blind


def test_road_information_without_enough_common_samples_or_baseline_error_is_nan() -> None:
    assert np.isnan(road_information(np.array([1.0, np.nan, 1.0]), np.ones(3)))
    assert np.isnan(road_information(np.ones(4), np.zeros(4)))
    with pytest.raises(ValueError, match=r"shape \(3,\).*\(4,\)"):
        road_information(np.ones(3), np.ones(4))


def test_the_benchmark_rows_get_the_road_information_of_their_run() -> None:
    runs = [RunRef("Ill", "straight", 1, seed=0), RunRef("1", "straight", 0, seed=0)]
    residuals = {
        "road_blind": [np.array([1.0, 1.0, 1.0, 1.0]), np.array([2.0, 2.0, 2.0, 2.0])],
        "generalized": [np.array([0.5, 0.5, 0.5, 0.5]), np.array([np.nan, 4.0, 4.0, 4.0])],
    }
    rows = [
        {"seed": 0, "driver": d, "track": "straight", "run": i, "model": m}
        for m in ("road_blind", "generalized", "failed_model")
        for d, i in (("Ill", 1), ("1", 0))
    ]
    _add_road_information(rows, residuals, runs)
    values = [r["road_information"] for r in rows]
    assert values == [0.0, 0.0, 0.75, -3.0, None, None]
    rows = [{"seed": 0, "driver": "Ill", "track": "straight", "run": 1, "model": "generalized"}]
    _add_road_information(rows, {"generalized": residuals["generalized"]}, runs)
    assert rows[0]["road_information"] is None  # no baseline: nothing to compare with


def _fit_quietly(model: SteeringModel, runs: list) -> SteeringModel:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SteeringFitWarning)  # the road-blind lane gain is 0
        return model.fit(runs)


def test_the_road_blind_model_is_an_ar_model_of_the_steering_alone() -> None:
    rng = np.random.default_rng(2101)
    truth = ARXForm(a=(1.5, -0.56), b=(0.4, -0.3))
    train = [arx_data(truth, 2000, rng), arx_data(truth, 2000, rng)]
    held_out = arx_data(truth, 2000, rng)
    blind = _fit_quietly(RoadBlindModel(), train)
    assert blind.parameter_names == ("a1", "a2")
    assert [str(r) for r in blind.regressors] == ["delta(k-1)", "delta(k-2)"]
    arx = blind.arx()
    assert arx is not None and arx.b == () and arx.static_lane_gain == 0.0
    assert SteeringModel.from_json(blind.to_json()) == blind  # a model file of its own type
    assert RoadBlindModel(3).with_parameters([0.5, 0.2, 0.1]).structure() == {"na": 3}
    with pytest.raises(ValueError, match=r"order na must be an integer in \[0, 50\]"):
        RoadBlindModel(-1)
    # the same data seen by a model that sees the road: most of what the AR model
    # misses is the road's doing; the road-blind model itself scores 0
    seeing = _fit_quietly(GeneralizedModel(2, 2, 0, 0), train)
    delta = held_out["delta"].to_numpy()
    blind_residual = delta - blind.predict(held_out)
    seeing_residual = delta - seeing.predict(held_out)
    assert road_information(seeing_residual, blind_residual) > 0.5
    assert road_information(blind_residual, blind_residual) == 0.0
    # a model whose road terms are wrong is worse than blind to the road
    flipped = GeneralizedModel.from_coefficients(
        seeing.coefficients()["a"], [-b for b in seeing.coefficients()["b"]]
    )
    assert road_information(delta - flipped.predict(held_out), blind_residual) < 0.0

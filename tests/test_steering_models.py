"""The two-point and generalized models: equations, ARX forms, prediction, free run."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hasa_env.steering import ARXForm, GeneralizedModel, Regressor, TwoPointModel


def features(delta, phi, omega, lateral_velocity, dt=0.01):
    frame = pd.DataFrame(
        {
            "delta": np.asarray(delta, dtype=float),
            "phi": np.asarray(phi, dtype=float),
            "omega": np.asarray(omega, dtype=float),
            "lateral_velocity": np.asarray(lateral_velocity, dtype=float),
            "speed": np.full(len(delta), 15.0),
        }
    )
    frame.attrs = {"near_distance": 6.2, "far_distance": 20.0, "decision_lag": 1, "dt": dt}
    return frame


def test_generalized_paper_preset_reproduces_eq_13_on_a_hand_computed_example():
    # samples k-3 .. k (the last row is k; its delta is the value to predict)
    frame = features(
        delta=[0.0, 0.008, 0.01, 0.5],
        phi=[0.011, 0.015, 0.018, 0.02],
        omega=[0.0, 0.0, 0.0, 0.005],
        lateral_velocity=[0.0, 0.0, 0.12, 0.1],
    )
    # by hand (docs/design.md §5.4 coefficients):
    #   a:  1.47 * 0.01 - 0.51 * 0.008                                   =  0.01062
    #   b: -5.73 * 0.02 + 17.32 * 0.018 - 17.65 * 0.015 + 6.12 * 0.011 = -0.00027
    #   c:  0.11 * 0.005                                                 =  0.00055
    #   d: -0.02 * 0.1 + 0.02 * 0.12                                     =  0.0004
    expected = 0.0113
    model = GeneralizedModel.paper()
    prediction = model.predict(frame)
    assert np.isnan(prediction[:3]).all()
    assert prediction[3] == pytest.approx(expected, abs=1e-15)
    arx = model.arx()
    assert arx.a == (1.47, -0.51)
    assert arx.b == (-5.73, 17.32, -17.65, 6.12)
    assert arx.c == (0.11,)
    assert arx.d == (-0.02, 0.02)
    assert arx.dt == 0.01
    via_arx = arx.predict(frame["delta"], frame["phi"], frame["omega"], frame["lateral_velocity"])
    assert via_arx[3] == pytest.approx(expected, abs=1e-15)


def test_two_point_paper_preset_on_a_hand_computed_example():
    frame = features(
        delta=[0.02, 0.9], phi=[0.01, 0.013], omega=[0.004, 0.003], lateral_velocity=[0, 0]
    )
    # 0.02 - 0.2 * (0.013 - 0.01) + 0.7 * (0.003 - 0.004) + 0.087 * 0.01 * 0.013
    expected = 0.02 - 0.0006 - 0.0007 + 0.00001131
    model = TwoPointModel.paper()
    assert model.parameters == {"near_gain": -0.2, "far_gain": 0.7, "integral_gain": 0.087}
    assert model.predict(frame)[1] == pytest.approx(expected, abs=1e-15)
    arx = model.arx()
    assert arx.a == (1.0,)
    assert arx.b == pytest.approx((-0.2 + 0.087 * 0.01, 0.2))
    assert arx.c == (0.7, -0.7)
    assert arx.d == ()


coefficient = st.floats(-3.0, 3.0)


@settings(max_examples=50, deadline=None)
@given(
    gains=st.tuples(coefficient, coefficient, coefficient),
    seed=st.integers(0, 2**32 - 1),
    dt=st.sampled_from([0.01, 0.02, 0.05]),
)
def test_two_point_model_equals_its_arx_form(gains, seed, dt):
    rng = np.random.default_rng(seed)
    n = 40
    frame = features(rng.normal(0, 0.02, n), rng.normal(0, 0.05, n), rng.normal(0, 0.05, n),
                     rng.normal(0, 0.2, n), dt=dt)  # fmt: skip
    model = TwoPointModel(*gains, dt=dt)
    arx = model.arx()
    direct = model.predict(frame)
    via_arx = arx.predict(frame["delta"], frame["phi"], frame["omega"], frame["lateral_velocity"])
    np.testing.assert_allclose(direct[1:], via_arx[1:], rtol=1e-12, atol=1e-15)


@settings(max_examples=50, deadline=None)
@given(
    orders=st.tuples(*(st.integers(0, 4) for _ in range(4))),
    seed=st.integers(0, 2**32 - 1),
)
def test_generalized_model_equals_its_arx_form_for_any_order(orders, seed):
    rng = np.random.default_rng(seed)
    n = 30
    frame = features(rng.normal(0, 0.02, n), rng.normal(0, 0.05, n), rng.normal(0, 0.05, n),
                     rng.normal(0, 0.2, n))  # fmt: skip
    size = orders[0] + sum(orders[1:])
    model = GeneralizedModel(*orders, parameters=rng.normal(0, 1, size))
    assert len(model.regressors) == size
    arx = model.arx()
    assert (len(arx.a), len(arx.b), len(arx.c), len(arx.d)) == orders
    start = arx.memory_order
    direct = model.predict(frame)
    via_arx = arx.predict(frame["delta"], frame["phi"], frame["omega"], frame["lateral_velocity"])
    np.testing.assert_allclose(direct[start:], via_arx[start:], rtol=1e-12, atol=1e-14)
    assert np.isnan(direct[:start]).all()
    assert GeneralizedModel.from_arx(arx) == model.with_parameters(model.parameter_vector)


def test_regressors_describe_the_paper_order():
    model = GeneralizedModel()
    assert model.orders == {"na": 2, "nb": 4, "nc": 1, "nd": 2}
    assert [str(r) for r in model.regressors] == [
        "delta(k-1)", "delta(k-2)", "phi(k)", "phi(k-1)", "phi(k-2)", "phi(k-3)", "omega(k)",
        "lateral_velocity(k)", "lateral_velocity(k-1)",
    ]  # fmt: skip
    assert model.parameter_names == ("a1", "a2", "b0", "b1", "b2", "b3", "c0", "d0", "d1")
    assert TwoPointModel().regressors[0] == Regressor("delta", 1)
    assert not model.is_fitted and model.arx() is None
    with pytest.raises(RuntimeError, match="no parameters"):
        model.predict(features([0.0] * 5, [0.0] * 5, [0.0] * 5, [0.0] * 5))


def test_free_run_feeds_back_its_own_output():
    rng = np.random.default_rng(3)
    n = 200
    frame = features(rng.normal(0, 0.02, n), rng.normal(0, 0.05, n), rng.normal(0, 0.05, n),
                     rng.normal(0, 0.2, n))  # fmt: skip
    model = GeneralizedModel.from_coefficients((1.2, -0.3), (0.5, -0.2), (0.1,), (0.05,))
    simulated = model.simulate(frame)
    delta = frame["delta"].to_numpy()
    phi, omega, vy = (frame[c].to_numpy() for c in ("phi", "omega", "lateral_velocity"))
    manual = delta.copy()
    for k in range(2, n):
        manual[k] = (1.2 * manual[k - 1] - 0.3 * manual[k - 2] + 0.5 * phi[k] - 0.2 * phi[k - 1]
                     + 0.1 * omega[k] + 0.05 * vy[k])  # fmt: skip
    assert np.isnan(simulated[:2]).all()
    np.testing.assert_allclose(simulated[2:], manual[2:], rtol=1e-10, atol=1e-14)
    # the generic (non-ARX) path agrees with the ARX one
    generic = _NoArx(*model.orders.values(), parameters=model.parameter_vector)
    np.testing.assert_allclose(generic.simulate(frame)[2:], manual[2:], rtol=1e-10, atol=1e-14)


class _NoArx(GeneralizedModel):
    """The generalized model without its ARX form: exercises the generic free run."""

    model_type = "test_generalized_without_arx"

    def arx(self):
        return None


def test_model_checks_feature_distances_and_sample_time():
    frame = features([0.0] * 5, [0.0] * 5, [0.0] * 5, [0.0] * 5)
    with pytest.raises(ValueError, match="near_distance"):
        GeneralizedModel(near_distance=5.0, parameters=[0.0] * 9).predict(frame)
    with pytest.raises(ValueError, match="Ts = 0.02"):
        GeneralizedModel(dt=0.02, parameters=[0.0] * 9).predict(frame)
    with pytest.raises(ValueError, match="all three gains"):
        TwoPointModel(0.1, 0.2)
    with pytest.raises(ValueError, match="order nb"):
        GeneralizedModel(nb=-1)
    with pytest.raises(ValueError, match="9 parameters"):
        GeneralizedModel(parameters=[1.0, 2.0])


def test_arx_form_rejects_non_finite_coefficients():
    with pytest.raises(ValueError, match="finite"):
        ARXForm(a=(float("nan"),), b=(1.0,))

"""The augmented ARX state-space model: structure, docs/design.md's corrected
recursion, exact Jacobians (finite differences over random orders and
coefficients), and the fast filter's tables."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.arx_state_space import ARXStateSpace
from estimators.gm_ekf import FilterMatrices
from estimators.settings import FilterSettings
from hasa_env.steering.arx import ARXForm

PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))

coefficient = st.floats(-3.0, 3.0, allow_nan=False)


@st.composite
def arx_forms(draw: st.DrawFn) -> ARXForm:
    na = draw(st.integers(0, 4))
    nb = draw(st.integers(1, 5))
    nc = draw(st.integers(0, 3))
    nd = draw(st.integers(0, 3))
    return ARXForm(
        a=tuple(draw(coefficient) for _ in range(na)),
        b=tuple(draw(coefficient) for _ in range(nb)),
        c=tuple(draw(coefficient) for _ in range(nc)),
        d=tuple(draw(coefficient) for _ in range(nd)),
        near_distance=draw(st.floats(3.0, 10.0)),
        far_distance=draw(st.floats(12.0, 30.0)),
    )


def random_state(rng: np.random.Generator, n: int) -> np.ndarray:
    x = rng.normal(size=n) * 0.3
    x[0] = rng.uniform(5.0, 40.0)  # v_x
    x[1] = rng.uniform(-3.0, 3.0)  # y
    x[2] = rng.uniform(-2.0, 2.0)  # v_y
    return x


def central_difference(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:  # noqa: ANN001
    cols = []
    for j in range(x.size):
        step = eps * max(1.0, abs(x[j]))
        hi, lo = x.copy(), x.copy()
        hi[j] += step
        lo[j] -= step
        cols.append((f(hi) - f(lo)) / (2 * step))
    return np.stack(cols, axis=-1)


def test_paper_order_has_seven_states_and_the_recordings_lag_eight():
    assert ARXStateSpace(PAPER).n_states == 7
    model = ARXStateSpace(PAPER, decision_lag=1)
    assert model.n_states == 8
    assert model.state_names[:4] == (
        "longitudinal_velocity",
        "lateral_offset",
        "lateral_velocity",
        "bias",
    )
    assert ARXStateSpace(None).n_states == 4


def test_paper_order_matches_design_corrected_recursion():
    """docs/design.md §8.3: g1, g2, g3 and h3 for the paper's order, written out."""
    model = ARXStateSpace(PAPER)
    a1, a2 = PAPER.a
    b0, b1, b2, b3 = PAPER.b
    (c0,) = PAPER.c
    d0, d1 = PAPER.d
    rng = np.random.default_rng(1)
    for _ in range(5):
        x = random_state(rng, 7)
        vx, y, vy, _, m1, m2, m3 = x
        theta = np.arctan(vy / vx)
        phi = -(theta + np.arctan(y / 6.2))
        om = -(theta + np.arctan(y / 20.0))
        g1 = b3 * phi
        g2 = (b2 + a2 * b0) * phi + a2 * c0 * om + a2 * d0 * vy + a2 * m3 + m1
        g3 = (b1 + a1 * b0) * phi + a1 * c0 * om + (d1 + a1 * d0) * vy + a1 * m3 + m2
        h3 = m3 + b0 * phi + c0 * om + d0 * vy
        acc = np.array([0.3, -0.2])
        out = model.transition(x, acc)
        np.testing.assert_allclose(out[4:], [g1, g2, g3], rtol=1e-12, atol=1e-12)
        dt = model.dt
        np.testing.assert_allclose(
            out[:4],
            [vx + dt * 0.3, y + dt * vy - 0.5 * dt * dt * 0.2, vy - dt * 0.2, x[3]],
            rtol=1e-14,
        )
        assert model.predicted_steering(x) == pytest.approx(h3, rel=1e-12, abs=1e-14)
        assert model.measurement(x)[0] == pytest.approx(np.hypot(vx, vy))
        assert model.measurement(x)[1] == pytest.approx(y + x[3])


@given(
    arx=arx_forms(),
    lag=st.integers(0, 2),
    seed=st.integers(0, 2**31 - 1),
    offset=st.booleans(),
)
@settings(max_examples=60, deadline=None)
def test_jacobians_match_finite_differences(arx, lag, seed, offset):
    model = ARXStateSpace(arx, decision_lag=lag, preferred_offset=offset)
    rng = np.random.default_rng(seed)
    x = random_state(rng, model.n_states)
    acc = rng.normal(size=2)
    jac = model.transition_jacobian(x)
    numeric = central_difference(lambda s: model.transition(s, acc), x)
    np.testing.assert_allclose(jac, numeric, rtol=1e-5, atol=1e-6 * (1 + np.abs(jac).max()))
    hjac = model.measurement_jacobian(x)
    numeric_h = central_difference(model.measurement, x)
    np.testing.assert_allclose(hjac, numeric_h, rtol=1e-5, atol=1e-6 * (1 + np.abs(hjac).max()))


@given(arx=arx_forms(), lag=st.integers(0, 2), seed=st.integers(0, 2**31 - 1))
@settings(max_examples=40, deadline=None)
def test_observer_form_reproduces_the_arx_model(arx, lag, seed):
    """Feeding the memory states the true steering reproduces delta(k) of the ARX
    equation (with the decision lag) exactly, whatever the orders."""
    model = ARXStateSpace(arx, decision_lag=lag)
    rng = np.random.default_rng(seed)
    steps = 40
    states = np.array([random_state(rng, model.n_states) for _ in range(steps)])
    features = model.bearings(states)  # u(k) of each sample
    n_hist = max(len(arx.a), len(arx.b), len(arx.c), len(arx.d)) + lag + 2
    delta = list(rng.normal(size=n_hist) * 0.01)  # arbitrary past
    u_hist = [features[0]] * n_hist
    memory = np.zeros(model.n_memory)
    # build the memory from the same past by running the recursion over it
    beta = np.zeros((model.n_memory + 1, 3))
    lagged = model.lagged_arx
    for column, coefficients in enumerate((lagged.b, lagged.c, lagged.d)):
        beta[: len(coefficients), column] = coefficients
    a = np.zeros(model.n_memory + 1)
    a[1 : len(lagged.a) + 1] = lagged.a
    for k in range(steps):
        u_all = [*u_hist, *features[: k + 1]]
        d_all = delta
        expected = sum(a[j] * d_all[-j] for j in range(1, len(a))) + sum(
            beta[j] @ u_all[-1 - j] for j in range(len(beta))
        )
        if k >= model.n_memory:  # the memory has seen n samples of this data
            x = states[k].copy()
            x[4:] = memory
            assert model.predicted_steering(x) == pytest.approx(expected, rel=1e-9, abs=1e-11)
        # advance the memory with the true steering (one-step-ahead predictor form)
        x = states[k].copy()
        x[4:] = memory
        actual = expected + rng.normal() * 0.01
        if model.n_memory:
            memory = (
                memory @ model.memory_matrix.T
                + features[k] @ model.bearing_gain.T
                + model.feedback * (actual - model.predicted_steering(x))
            )
        delta.append(actual)


def test_steady_memory_is_the_constant_past_fixed_point():
    """Memory of a constant past (delta, u) = what the recursion gives after n
    steps of that past, from any start."""
    model = ARXStateSpace(PAPER, decision_lag=1)
    rng = np.random.default_rng(3)
    x = random_state(rng, model.n_states)
    delta = 0.013
    u = model.bearings(x)
    memory = rng.normal(size=model.n_memory)
    for _ in range(model.n_memory):
        x[4:] = memory
        memory = (
            memory @ model.memory_matrix.T
            + u @ model.bearing_gain.T
            + model.feedback * (delta - model.predicted_steering(x))
        )
    np.testing.assert_allclose(
        model.steady_memory(np.array(delta), x), memory, rtol=1e-12, atol=1e-14
    )


@given(arx=arx_forms(), lag=st.integers(0, 2), seed=st.integers(0, 2**31 - 1))
@settings(max_examples=40, deadline=None)
def test_fast_filter_tables_match_the_model(arx, lag, seed):
    """The vectorized filter's predicted mean, Jacobian and measurement Jacobian
    equal the model's (plain and noise-decorrelated)."""
    model = ARXStateSpace(arx, decision_lag=lag)
    mats = FilterMatrices(model, FilterSettings(steering_residual_std=3e-3))
    rng = np.random.default_rng(seed)
    x = np.array([random_state(rng, model.n_states) for _ in range(3)])
    acc = rng.normal(size=(3, 2))
    cov = np.broadcast_to(np.eye(model.n_states), (3, model.n_states, model.n_states)).copy()
    for steering in (np.full(3, np.nan), rng.normal(size=3) * 0.01, np.array([0.01, np.nan, 0.0])):
        x_new, cov_new = mats.predict_batch(x, cov, acc, steering, 1)
        for i in range(3):
            expected = model.transition(x[i], acc[i])
            jac = model.transition_jacobian(x[i])
            q = mats.process_noise
            if mats.decorrelates and np.isfinite(steering[i]):
                expected = expected + mats.steering_gain * (
                    steering[i] - model.predicted_steering(x[i])
                )
                jac = jac - np.outer(mats.steering_gain, model.measurement_jacobian(x[i])[2])
                q = mats.process_noise_decorrelated
            elif mats.decorrelates and mats.unstable_memory:  # no open-loop prediction: held
                jac = model.held_memory_transition_matrix()
                expected = jac @ x[i] + model.input_matrix() @ acc[i]
                q = mats.process_noise_vehicle
            np.testing.assert_allclose(x_new[i], expected, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(cov_new[i], jac @ jac.T + q, rtol=1e-9, atol=1e-9)
    z = np.array([[15.0, 0.1, 0.02]] * 3)
    x_post, cov_post, log_lik = mats.update_batch(x, cov, z, 1, True)
    for i in range(3):
        h = model.measurement(x[i])
        hj = model.measurement_jacobian(x[i])
        s = hj @ hj.T + np.diag(mats.measurement_var)
        gain = hj.T @ np.linalg.inv(s)
        np.testing.assert_allclose(x_post[i], x[i] + gain @ (z[i] - h), rtol=1e-8, atol=1e-9)
        nu = z[i] - h
        expected_ll = -0.5 * (
            nu @ np.linalg.solve(s, nu) + np.log(np.linalg.det(s)) + 3 * np.log(2 * np.pi)
        )
        assert log_lik[i] == pytest.approx(expected_ll, rel=1e-8, abs=1e-8)


def test_decorrelated_process_noise_is_positive_semidefinite():
    mats = FilterMatrices(ARXStateSpace(PAPER, decision_lag=1), FilterSettings())
    for q in (mats.process_noise, mats.process_noise_decorrelated):
        np.testing.assert_allclose(q, q.T)
        assert np.linalg.eigvalsh(q).min() > -1e-18


def test_invalid_lag_and_dt():
    with pytest.raises(ValueError, match="decision_lag"):
        ARXStateSpace(PAPER, decision_lag=-1)
    with pytest.raises(ValueError, match="dt"):
        ARXStateSpace(PAPER, dt=0.0)

"""Gains designed with the driver's own delay and neuromuscular lag (docs/design.md §7.10).

:meth:`~hasa_env.drivers.two_point.TwoPointParams.from_loop` and
:meth:`~hasa_env.drivers.lqr.PreviewCost.from_bandwidth` design the lateral
loop without the driver's delay tau and neuromuscular lag, which then eat
its phase margin (§7.8). Here the loop is broken at the steering input
(small angles, straight road, speed-normalised so it is the same at every
speed when the gains scale as v_ref / v) and the gains are chosen from it::

    L(s) = C(s) P(s) exp(-s tau_e) H(s)
    P(s) = 1 / s^2                         (lateral acceleration v^2 delta / L -> offset y)
    H(s) = w_n^2 / (s^2 + 2 zeta_n w_n s + w_n^2)                  (neuromuscular lag)
    tau_e = tau + 1.5 Ts                   (the delay, one step of action alignment, ZOH)

Two-point PI (velocity form, §7.2; phi ~ -(y' + y / t_n) / v, Omega ~ -(y' + y / t_f) / v)::

    C(s) P(s) = c N(s) / s^3,   c = v_ref / L_w,
    N(s) = A1 s^2 + A0 s + AI,  A1 = k_n + k_f,  A0 = k_n / t_n + k_f / t_f + k_I,  AI = k_I / t_n

:func:`two_point_for_crossover` sets |L(j w_c)| = 1 and arg L(j w_c) = -180 deg + PM at a
target crossover w_c, with a double real zero, N(s) = A1 (s + w_z)^2 (well-damped zeros: lightly
damped ones give the closed loop slow, lightly damped poles near them, a driver who lets the
car drift). The phase N needs at w_c gives w_z, the magnitude A1::

    phi_N = 90 deg + PM + w_c tau_e - arg H(j w_c)          (in (90, 180) deg)
    w_z   = w_c / tan(phi_N / 2)
    A1    = w_c^3 / (c (w_c^2 + w_z^2) |H(j w_c)|)
    k_I = A1 w_z^2 t_n,  k_n + k_f = A1,  k_n / t_n + k_f / t_f = 2 A1 w_z - k_I

phi_N < 180 deg bounds the margin: PM < 90 deg - w_c tau_e + arg H(j w_c); the nearer the
margin to that bound, the lower w_z and the slacker the control of the offset itself.

Preview LQR (:mod:`hasa_env.drivers.lqr`, j = -(k_y y + k_v y' + k_a a), speed-normalised)::

    C(s) P(s) = (k_y + k_v s) / (s^2 (s + k_a))

:func:`preview_cost_for_margin` keeps the LQR design and chooses its bandwidth (bisection)
so that this delayed, lagged loop has a target phase margin; its crossover follows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields, replace
from typing import Any

import numpy as np

from hasa_env.drivers.human import check_range
from hasa_env.drivers.lqr import PreviewCost
from hasa_env.drivers.two_point import TwoPointParams

__all__ = [
    "FREQUENCIES",
    "effective_delay",
    "feedback_gains",
    "loop_margins",
    "neuromuscular_response",
    "preview_cost_for_margin",
    "preview_loop",
    "redesign",
    "two_point_for_crossover",
    "two_point_loop",
]

FREQUENCIES = np.logspace(-1.5, 1.5, 2000)
"""Default frequency grid (rad/s) of the loop responses."""


def effective_delay(delay: float, sample_time: float = 0.01) -> float:
    """tau_e = round(delay / Ts) Ts + 1.5 Ts (s): the driver's delay line, the action applied
    over the next step and the zero-order hold's half step."""
    check_range("effective_delay", "sample_time", sample_time, 1e-4, 0.5)
    return round(delay / sample_time) * sample_time + 1.5 * sample_time


def neuromuscular_response(
    frequencies: np.ndarray, natural_frequency: float, damping: float
) -> np.ndarray:
    """H(j w) = w_n^2 / ((j w)^2 + 2 zeta_n w_n j w + w_n^2) of the lag (complex array)."""
    s = 1j * np.asarray(frequencies, dtype=float)
    wn = natural_frequency
    return wn * wn / (s * s + 2.0 * damping * wn * s + wn * wn)


def two_point_loop(
    params: TwoPointParams,
    frequencies: np.ndarray = FREQUENCIES,
    sample_time: float = 0.01,
    wheelbase: float = 2.8,
) -> np.ndarray:
    """L(j w) of a two-point driver at its reference speed (module docstring), complex array.

    Exactly speed-independent when ``speed_exponent`` is 1.
    """
    s = 1j * np.asarray(frequencies, dtype=float)
    p = params
    c = p.reference_speed / wheelbase
    n = (
        (p.near_gain + p.far_gain) * s * s
        + (p.near_gain / p.near_time + p.far_gain / p.far_time + p.integral_gain) * s
        + p.integral_gain / p.near_time
    )
    tau = effective_delay(p.delay, sample_time)
    lag = neuromuscular_response(frequencies, p.neuromuscular_frequency, p.neuromuscular_damping)
    return c * n / s**3 * np.exp(-s * tau) * lag


def feedback_gains(cost: PreviewCost) -> tuple[float, float, float]:
    """(k_y, k_v, k_a) of :func:`~hasa_env.drivers.lqr.preview_gains` from the plant's own
    3 x 3 Riccati equation: the previewed road's states are not controllable, so the
    feedback gains on the plant's states do not depend on them (only the preview gains do).

    Solved by the structured doubling algorithm (A_0 = A, G_0 = B R^-1 B', H_0 = Q;
    W = I + G_k H_k, A_k+1 = A_k W^-1 A_k, G_k+1 = G_k + A_k W^-1 G_k A_k',
    H_k+1 = H_k + A_k' H_k W^-1 A_k; H_k -> S), in plain numpy: fast for a 3 x 3 problem.
    """
    t = cost.preview_step
    a = np.array([[1.0, t, t * t / 2.0], [0.0, 1.0, t], [0.0, 0.0, 1.0]])
    b = np.array([[t**3 / 6.0], [t * t / 2.0], [t]])
    q = np.diag([t * cost.lateral_weight, t * cost.heading_weight, 0.0])
    r = np.array([[t * cost.steering_rate_weight]])
    s = _riccati(a, b, q, r)
    gain = np.linalg.solve(r + b.T @ s @ b, b.T @ s @ a)[0]
    return float(gain[0]), float(gain[1]), float(gain[2])


def _riccati(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """S of S = A' S A - A' S B (R + B' S B)^-1 B' S A + Q by structured doubling."""
    ak, gk, hk = a.copy(), b @ np.linalg.solve(r, b.T), q.copy()
    eye = np.eye(a.shape[0])
    for _ in range(60):
        w = eye + gk @ hk
        w_a = np.linalg.solve(w, ak)
        w_g = np.linalg.solve(w, gk)
        h_next = hk + ak.T @ hk @ w_a
        ak, gk = ak @ w_a, gk + ak @ w_g @ ak.T
        if np.abs(h_next - hk).max() <= 1e-13 * np.abs(h_next).max():
            return h_next
        hk = h_next
    raise ValueError("the preview design's Riccati equation did not converge")


def preview_loop(
    cost: PreviewCost,
    delay: float,
    natural_frequency: float,
    damping: float,
    frequencies: np.ndarray = FREQUENCIES,
    sample_time: float = 0.01,
) -> np.ndarray:
    """L(j w) = (k_y + k_v s) / (s^2 (s + k_a)) exp(-s tau_e) H(s) of a preview LQR driver."""
    s = 1j * np.asarray(frequencies, dtype=float)
    k_y, k_v, k_a = feedback_gains(cost)
    tau = effective_delay(delay, sample_time)
    lag = neuromuscular_response(frequencies, natural_frequency, damping)
    return (k_y + k_v * s) / (s * s * (s + k_a)) * np.exp(-s * tau) * lag


def loop_margins(frequencies: np.ndarray, response: np.ndarray) -> tuple[float, float]:
    """(crossover w_c rad/s, phase margin deg) of a loop response on an increasing grid.

    w_c is the highest frequency where |L| falls through 1 (linear interpolation in log w);
    the phase is unwrapped from the lowest frequency, taken there in (-360, 0] deg, and
    PM = 180 deg + arg L(j w_c). NaN and NaN if |L| never falls through 1.
    """
    w = np.asarray(frequencies, dtype=float)
    magnitude = np.log(np.abs(response))
    down = np.flatnonzero((magnitude[:-1] >= 0.0) & (magnitude[1:] < 0.0))
    if down.size == 0:
        return math.nan, math.nan
    i = int(down[-1])
    phase = np.unwrap(np.angle(response))
    phase -= 2.0 * math.pi * math.ceil(phase[0] / (2.0 * math.pi))
    share = magnitude[i] / (magnitude[i] - magnitude[i + 1])
    crossover = float(np.exp(np.log(w[i]) + share * (np.log(w[i + 1]) - np.log(w[i]))))
    at = float(phase[i] + share * (phase[i + 1] - phase[i]))
    return crossover, 180.0 + math.degrees(at)


def two_point_for_crossover(
    crossover: float,
    phase_margin: float,
    near_time: float,
    far_time: float,
    delay: float,
    neuromuscular_frequency: float,
    neuromuscular_damping: float,
    sample_time: float = 0.01,
    wheelbase: float = 2.8,
    reference_speed: float = 15.0,
    **kwargs: Any,
) -> TwoPointParams:
    """Two-point gains whose loop with delay and lag crosses over at ``crossover`` (rad/s)
    with ``phase_margin`` (deg), equations in the module docstring.

    Args:
        crossover: w_c (rad/s), in [0.3, 6].
        phase_margin: PM (deg), in [5, 80]; must be below 90 deg - w_c tau_e + arg H(j w_c).
        near_time, far_time, delay, neuromuscular_frequency, neuromuscular_damping,
            reference_speed, **kwargs: the :class:`TwoPointParams` fields.
        sample_time: Ts (s) of the driver's steps.
        wheelbase: L_w (m) of the car.

    Raises:
        ValueError: a target out of range, or a margin the delay and lag do not allow.
    """
    owner = "two_point_for_crossover"
    check_range(owner, "crossover", crossover, 0.3, 6.0)
    check_range(owner, "phase_margin", phase_margin, 5.0, 80.0)
    w = crossover
    tau = effective_delay(delay, sample_time)
    lag = complex(neuromuscular_response(np.array([w]), neuromuscular_frequency,
                                         neuromuscular_damping)[0])  # fmt: skip
    needed = math.pi / 2 + math.radians(phase_margin) + w * tau - math.atan2(lag.imag, lag.real)
    if not needed < math.pi - 1e-3:
        allowed = 90.0 - math.degrees(w * tau - math.atan2(lag.imag, lag.real))
        raise ValueError(
            f"{owner}: phase_margin {phase_margin:g} deg at crossover {w:g} rad/s is not "
            f"reachable with delay {delay:g} s and this lag; allowed: below {allowed:.1f} deg"
        )
    zero = w / math.tan(needed / 2.0)
    c = reference_speed / wheelbase
    a1 = w**3 / (c * (w * w + zero * zero) * abs(lag))
    a0, ai = 2.0 * a1 * zero, a1 * zero * zero
    integral = ai * near_time
    near = (a0 - integral - a1 / far_time) / (1.0 / near_time - 1.0 / far_time)
    return TwoPointParams(
        near_time=near_time,
        far_time=far_time,
        near_gain=near,
        far_gain=a1 - near,
        integral_gain=integral,
        reference_speed=reference_speed,
        delay=delay,
        neuromuscular_frequency=neuromuscular_frequency,
        neuromuscular_damping=neuromuscular_damping,
        **kwargs,
    )


def preview_cost_for_margin(
    phase_margin: float,
    velocity_weight: float,
    delay: float,
    neuromuscular_frequency: float,
    neuromuscular_damping: float,
    sample_time: float = 0.01,
    **kwargs: Any,
) -> PreviewCost:
    """:meth:`PreviewCost.from_bandwidth` with the bandwidth (0.2-3 rad/s) at which the preview
    loop with delay and lag (:func:`preview_loop`) has ``phase_margin`` (deg), by bisection
    (the margin falls as the bandwidth grows).

    Raises:
        ValueError: the margin is out of [5, 80] deg or not reached even at 0.2 rad/s.
    """
    owner = "preview_cost_for_margin"
    check_range(owner, "phase_margin", phase_margin, 5.0, 80.0)

    def margin(bandwidth: float) -> float:
        cost = PreviewCost.from_bandwidth(bandwidth, velocity_weight, **kwargs)
        loop = preview_loop(cost, delay, neuromuscular_frequency, neuromuscular_damping,
                            sample_time=sample_time)  # fmt: skip
        return loop_margins(FREQUENCIES, loop)[1]

    low, high = 0.2, 3.0
    if not margin(low) >= phase_margin:
        raise ValueError(
            f"{owner}: phase_margin {phase_margin:g} deg is not reached with delay {delay:g} s "
            f"and velocity_weight {velocity_weight:g}, even at bandwidth {low} rad/s"
        )
    if margin(high) >= phase_margin:
        return PreviewCost.from_bandwidth(high, velocity_weight, **kwargs)
    for _ in range(14):  # 2.8 rad/s / 2^14: the bandwidth to 2e-4 rad/s
        middle = 0.5 * (low + high)
        low, high = (middle, high) if margin(middle) >= phase_margin else (low, middle)
    return PreviewCost.from_bandwidth(low, velocity_weight, **kwargs)


def redesign(driver: Any, targets: Mapping[str, float]) -> Any:
    """The driver (parameters of any archetype) with gains designed with its own delay and lag.

    ``targets``: "crossover" (rad/s), "phase_margin" (deg), "preview_phase_margin" (deg),
    "preview_velocity_weight" (the keys of
    :class:`~hasa_env.drivers.populations.LoopTargets`).

    Two-point: :func:`two_point_for_crossover` at the target
    crossover and margin; where the delay and lag do not allow that margin there, the
    crossover is lowered in steps of 5 % until they do. Preview, intermittent and noisy
    corrections: :func:`preview_cost_for_margin` (same preview
    time and persistence).
    """
    if isinstance(driver, TwoPointParams):
        keep = {
            f.name: getattr(driver, f.name)
            for f in fields(driver)
            if f.name not in ("near_gain", "far_gain", "integral_gain", "near_time", "far_time",
                              "delay", "neuromuscular_frequency", "neuromuscular_damping")
        }  # fmt: skip
        crossover = targets["crossover"]
        for _ in range(40):
            try:
                return two_point_for_crossover(
                    crossover,
                    targets["phase_margin"],
                    driver.near_time,
                    driver.far_time,
                    driver.delay,
                    driver.neuromuscular_frequency,
                    driver.neuromuscular_damping,
                    **keep,
                )
            except ValueError:
                crossover *= 0.95
        raise ValueError(f"no two-point design reaches the margin {targets['phase_margin']:g} deg")
    cost = preview_cost_for_margin(
        targets["preview_phase_margin"],
        targets["preview_velocity_weight"],
        driver.delay,
        driver.neuromuscular_frequency,
        driver.neuromuscular_damping,
        preview_time=driver.cost.preview_time,
        preview_step=driver.cost.preview_step,
        persistence=driver.cost.persistence,
    )
    return replace(driver, cost=cost)

"""Can a steering model tell lanes apart, and is it stable? (docs/design.md §5.7, §6.5)

- :func:`check_identifiability`: the static lane-offset gain
  ``G = sum(b)/near + sum(c)/far`` must be clearly non-zero (z standard
  errors from zero, the standard error coming from the fit) and have the sign
  of ``1 - sum(a)`` for the estimator to tell lanes apart; the paper's "any
  b_i or c_0 non-zero" is not enough.
- :func:`ar_poles`: the poles of the model's autoregressive part, the roots
  of ``z^n - a_1 z^(n-1) - ... - a_n``; a pole outside the unit circle means
  the model's own steering diverges in free run.

Fits that lose either property warn with a subclass of
:class:`SteeringFitWarning` (:class:`IdentifiabilityWarning`,
:class:`StabilityWarning`), so ``warnings.filterwarnings("ignore",
category=SteeringFitWarning)`` silences both.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hasa_env.steering.arx import ARXForm, autoregression_roots
from hasa_env.steering.design import SteeringModelLike as SteeringModel

__all__ = [
    "IdentifiabilityReport",
    "IdentifiabilityWarning",
    "StabilityWarning",
    "SteeringFitWarning",
    "STABILITY_TOLERANCE",
    "ar_poles",
    "check_identifiability",
]

STABILITY_TOLERANCE = 1e-9
"""|pole| <= 1 + this counts as stable: an integrating model (the two-point
model's a = (1,)) has a pole exactly on the unit circle by construction."""


class SteeringFitWarning(UserWarning):
    """A fitted steering model is unfit for the estimator (base of the fit warnings)."""


class IdentifiabilityWarning(SteeringFitWarning):
    """A fitted model's static lane-offset gain is not clearly non-zero (or has the wrong sign)."""


class StabilityWarning(SteeringFitWarning):
    """A fitted model's autoregressive part has a pole outside the unit circle."""


def ar_poles(arx: ARXForm) -> np.ndarray:
    """Poles of the AR part ``delta(k) = sum_i a_i delta(k-i) + ...``: the roots of
    ``z^n - a_1 z^(n-1) - ... - a_n`` (complex, shape (n,); empty without an AR part)."""
    return autoregression_roots(arx.a)


@dataclass(frozen=True)
class IdentifiabilityReport:
    """The static lane-offset gain of a model (docs/design.md §5.7).

    Attributes:
        static_lane_gain: G = sum(b)/near + sum(c)/far (rad/m). With
            phi ~ -y/near, omega ~ -y/far, a lane-centre error of e metres
            held over the model's memory moves its one-step prediction by
            -G e; at steady state (1 - sum a) delta = -G y.
        standard_error: SE of G from the fit's covariance (NaN if unknown).
        memory_gain: 1 - sum(a) (0 for an integrating model such as the two-point).
        memory_standard_error: its SE (NaN if unknown).
        integrating: 1 - sum(a) is zero or within z SE of zero.
        steady_state_gain: delta/y at steady state = -G / (1 - sum a) (rad/m;
            +-inf for an integrating model).
        lane_snr: |G| * lane_separation / sqrt(residual_std^2 + sensor_std^2): how
            many standard deviations of the steering channel (model residual and
            steering-sensor noise together, as the estimator sees them) one
            prediction moves between two lane hypotheses ``lane_separation`` m
            apart (NaN without a fit).
        identifiable: G is clearly non-zero: |G| > z SE when the SE is
            known, else |G| > min_gain.
        sign_consistent: at steady state the model steers towards the lane
            centre: G has the sign of 1 - sum(a), or G > 0 if it integrates.
        message: a sentence saying what was found.
    """

    static_lane_gain: float
    standard_error: float
    memory_gain: float
    memory_standard_error: float
    integrating: bool
    steady_state_gain: float
    lane_snr: float
    identifiable: bool
    sign_consistent: bool
    message: str

    @property
    def ok(self) -> bool:
        """Identifiable and sign-consistent."""
        return self.identifiable and self.sign_consistent


def _arx_gradient(model: SteeringModel, quantity: Callable[[ARXForm], float]) -> np.ndarray | None:
    """d quantity(arx) / d parameters (exact when the ARX form is affine in the parameters)."""
    theta = model.parameter_vector
    grad = np.zeros(theta.size)
    for j in range(theta.size):
        step = max(1.0, abs(theta[j]))
        up, down = theta.copy(), theta.copy()
        up[j] += step
        down[j] -= step
        arx_up = model.with_parameters(up).arx()
        arx_down = model.with_parameters(down).arx()
        if arx_up is None or arx_down is None:
            return None
        grad[j] = (quantity(arx_up) - quantity(arx_down)) / (2.0 * step)
    return grad


def _standard_error(grad: np.ndarray | None, covariance: np.ndarray | None) -> float:
    if grad is None or covariance is None:
        return float("nan")
    return float(math.sqrt(max(float(grad @ covariance @ grad), 0.0)))


def _unidentifiable(gain: float, se: float, z: float, min_gain: float) -> str:
    """The message of a gain not clearly non-zero: why an estimator may still decide with it."""
    detail = (
        f" (SE {se:.3g}, needs > {z:g} SE)" if math.isfinite(se) else f" (needs |G| > {min_gain:g})"
    )
    return (
        f"static lane-offset gain sum(b)/near + sum(c)/far = {gain:.3g} rad/m is not clearly "
        f"non-zero{detail}: the training run does not establish that the steering tells "
        "the lanes apart, nor which way; an estimator may still decide a lane with it "
        "(a small gain's evidence adds up over thousands of samples), but that decision rests "
        "on a gain the fit cannot tell from zero: check it where the true lane is known"
    )


def check_identifiability(
    model: SteeringModel | ARXForm,
    covariance: np.ndarray | None = None,
    z: float = 3.0,
    min_gain: float = 1e-6,
    residual_std: float | None = None,
    lane_separation: float = 1.8,
    sensor_std: float = 0.0,
) -> IdentifiabilityReport | None:
    """Is the lane offset identifiable through this model? (docs/design.md §5.7)

    The paper's "observable if any b_i or c_0 is non-zero" is not enough:
    b = (0.3, -0.3) is non-zero but carries no information on a constant
    lane-centre error. What matters is the static lane-offset gain
    G = sum(b)/near + sum(c)/far.

    Args:
        model: a steering model (its :meth:`arx` form is used) or an :class:`ARXForm`.
        covariance: covariance of the model's parameters; default: that of the
            model's fit, if any. With it, "clearly non-zero" means ``z``
            standard errors away from zero.
        z: how many standard errors "clearly non-zero" means.
        min_gain: smallest |G| (rad/m) accepted when no standard error is known.
        residual_std: the one-step residual std (rad) for ``lane_snr``;
            default: the model's fit's.
        lane_separation: distance (m) between the lane hypotheses for ``lane_snr``.
        sensor_std: steering-sensor noise std (rad, model units) added to the
            residual for ``lane_snr``: the noise the estimator's steering
            channel faces besides the model's own error.

    Returns:
        An :class:`IdentifiabilityReport`, or None if the model is not an ARX model.
    """
    grad_gain = grad_memory = None
    arx: ARXForm | None
    if isinstance(model, ARXForm):
        arx = model
    else:
        arx = model.arx()
        if arx is None:
            return None
        if model.fit_result is not None:
            if covariance is None:
                covariance = model.fit_result.covariance
            if residual_std is None:
                residual_std = model.fit_result.residual_std
        if covariance is not None:
            grad_gain = _arx_gradient(model, lambda f: f.static_lane_gain)
            grad_memory = _arx_gradient(model, lambda f: 1.0 - sum(f.a))
    gain = arx.static_lane_gain
    se = _standard_error(grad_gain, covariance)
    memory = 1.0 - sum(arx.a)
    memory_se = _standard_error(grad_memory, covariance)
    integrating = abs(memory) < 1e-9 or (math.isfinite(memory_se) and abs(memory) <= z * memory_se)
    if integrating:
        steady = math.copysign(math.inf, -gain) if gain != 0 else float("nan")
    else:
        steady = -gain / memory
    channel_std = math.hypot(residual_std, sensor_std) if residual_std is not None else 0.0
    snr = abs(gain) * lane_separation / channel_std if channel_std > 0 else float("nan")
    identifiable = abs(gain) > z * se if math.isfinite(se) else abs(gain) > min_gain
    sign_consistent = gain > 0 if integrating else gain * memory > 0
    if not identifiable:
        message = _unidentifiable(gain, se, z, min_gain)
    elif not sign_consistent:
        message = (
            f"static lane-offset gain {gain:.3g} rad/m has the wrong sign for 1 - sum(a) = "
            f"{memory:.3g}: at steady state the model steers away from the lane centre"
        )
    else:
        parts = [f"identifiable: static lane-offset gain {gain:.3g} rad/m"]
        if math.isfinite(se) and se > 0:
            parts.append(f" ({abs(gain) / se:.1f} SE)")
        if integrating:
            parts.append(", integrating (1 - sum(a) ~ 0)")
        else:
            parts.append(f", steady-state steering {steady:.3g} rad/m")
        if math.isfinite(snr):
            parts.append(
                f"; lanes {lane_separation:g} m apart move a prediction by {snr:.2g} SDs of the "
                "steering channel"
            )
        message = "".join(parts)
    return IdentifiabilityReport(
        gain,
        se,
        memory,
        memory_se,
        integrating,
        steady,
        snr,
        identifiable,
        sign_consistent,
        message,
    )

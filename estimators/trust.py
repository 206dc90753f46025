"""One rule: a steering model (+ its training record + the user's overrides) -> a trusted filter.

:func:`trusted_filter` is the only place that turns a steering model into the settings of
the Gaussian-mixture EKF that listens to it (docs/design.md §8.13). The benchmark
(:mod:`benchmarks.protocol.tasks`), the env wrappers (:func:`estimators.wrappers.estimator_wrapper`,
used by ``hasa-drive``), the offline runner (:func:`estimators.offline.estimate_recording`,
used by ``hasa-replay``) and the advisor task (:mod:`advisor_tasks.config`) all call it.

The rule, field by field (a field the user names in ``overrides`` is the user's, always):

- ``steering_ratio``: the caller's (model units per measured road-wheel radian).
- ``steering_residual_std`` (rad, model units): the record's residual level, at least 1e-9;
  unknown: the base settings' (FilterSettings' 2e-3).
- ``steering_curvature_limit`` (1/m): the largest road curvature the model was fitted on
  (its own record, else the training record's) plus
  :data:`~estimators.settings.STRAIGHT_CURVATURE` (:func:`~estimators.settings.steering_curvature_limit`);
  unknown: ``math.inf``.
- ``steering_curvature_feedforward`` (model units per 1/m): for a model fitted on straight
  roads only (its curvature limit is :data:`~estimators.settings.STRAIGHT_CURVATURE`) with a
  stable autoregression and a fit that pins G down (:data:`FEEDFORWARD_PRECISION`;
  :func:`curvature_feedforward_error`, from the covariance of its parameters, which a fit and
  its model file keep; none for the presets), the steady-state steering on a bend that its bearings do not explain
  (:func:`curvature_feedforward`, docs/design.md §8.28); the steering then counts on bends too
  (``steering_curvature_limit`` ``math.inf``). A user's ``steering_curvature_feedforward = 0``
  keeps the curvature limit instead.
- ``min_speed`` / ``steering_max_speed`` (m/s): the speeds it was fitted at (its own record,
  else the training record's) widened by :data:`~estimators.settings.SPEED_MARGIN`, the lower end
  never below the base settings' ``min_speed`` (:func:`~estimators.settings.steering_speed_limits`).
- A model that failed its lane-keeping check, or has no ARX form, gives no lane evidence at all:
  the filter is the no-steering one (:class:`~estimators.baselines.NoSteeringEKF`).
- So does a model that predicts the steering no better than the steering's own past does
  (``training.prediction``, :func:`~estimators.tuning.prediction_check` on the data it was
  fitted on: its one-step residual at or above that of a lane-free autoregression of its
  order; docs/design.md §8.13.1; no check where the record has none). Its lane evidence would come from the errors of a model
  that does not describe this driver.
- The ARX form the filter compares with the steering: the model's own, multiplied through
  by its equation error's autoregression when the fit estimated one (``equation_error_ar``,
  :func:`hasa_env.steering.equation_error.whitened_arx`, docs/design.md §8.32), so that the
  filter's steering innovations are white where the model's residuals are not; the residual
  level is then that of the whitened error, the record's (else the base settings')
  ``steering_residual_std`` times ``sqrt(1 - sum_i r_i rho_i)`` (:func:`~hasa_env.steering.equation_error.innovation_variance_ratio`).
  Every check above (prediction, lane keeping, G) reads the model's own form. Where the record
  measured it (``training.whitened_residual_std``, on the same data as its residual level), a
  declared autoregression is taken only if the whitened form's one-step residual is below the
  model's own (the level stays the one above).
- The equation error scaled by the speed (docs/design.md §8.34): a model that declares one
  (``equation_error_speed_scaled``, :class:`~hasa_env.steering.equation_error.SpeedScaledError`)
  gets a filter that carries its coloured part as a state (``steering_coloured_error_std``,
  ``_correlation``, ``_speed``), with ``steering_residual_std`` its white part's std and the
  model's own ARX form (no whitening by the autoregression above). Where the record measured
  it (``training.speed_scaled_gain``), a declaration that describes the one-step residuals no
  better than one white level is ignored with a reason (the autoregression is then taken as
  above).
- ``checks=False`` (the benchmark's unchecked comparison): ``evidence_checks`` off and none of
  the limits above (curvature limit ``math.inf`` even when the user set one).

Every channel the rule switches off comes with a reason in :attr:`TrustedFilter.reasons`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from estimators.baselines import NoSteeringEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.settings import (
    SPEED_MARGIN,
    STRAIGHT_CURVATURE,
    FilterSettings,
    steering_curvature_limit,
    steering_speed_limits,
)
from estimators.tuning import (
    PredictionCheck,
    prediction_check,
    speed_scaled_gain,
    steering_residual_std,
    whitened_residual_std,
)
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.equation_error import (
    SpeedScaledError,
    check_equation_error_ar,
    innovation_variance_ratio,
    whitened_arx,
)

__all__ = [
    "STEERING_EVERYWHERE",
    "TrainingRecord",
    "TrustedFilter",
    "FEEDFORWARD_PRECISION",
    "curvature_feedforward",
    "curvature_feedforward_error",
    "model_limits",
    "trusted_filter",
]


@dataclass(frozen=True)
class TrainingRecord:
    """What a caller knows of how a steering model was fitted and checked, beyond what the
    model keeps itself (its ``training_curvature`` and ``training_speed_range`` come first).

    Attributes:
        residual_std: the model's one-step residual level (rad, model units) on its training
            data or on the data filtered; None: unknown (the base settings' level).
        prediction: the model's prediction check on the data it was fitted on
            (:func:`~estimators.tuning.prediction_check`); None: not measured (not checked).
        curvature: the largest ``|road curvature|`` (1/m) of the roads it was fitted on;
            None: unknown.
        speed_range: (min, max) speed (m/s) it was fitted at; None: unknown.
        keeps_lane: the outcome of its lane-keeping check
            (:func:`hasa_env.drivers.lane_keeping_check`); None: not checked.
        lane_check: that check's one-line summary (for the reason).
        whitened_residual_std: the one-step residual level (rad, model units) of the model's
            form whitened by its declared equation-error autoregression, on the same data as
            ``residual_std`` (:func:`~estimators.tuning.whitened_residual_std`); None: not
            measured (the declaration is then taken as it is).
        speed_scaled_gain: how much better (nats per residual) the model's declared
            speed-scaled equation error describes its one-step residuals on the same data than
            one white level does (:func:`~estimators.tuning.speed_scaled_gain`); None: not
            measured (the declaration is then taken as it is).
    """

    residual_std: float | None = None
    prediction: PredictionCheck | None = None
    curvature: float | None = None
    speed_range: tuple[float, float] | None = None
    keeps_lane: bool | None = None
    lane_check: str = ""
    whitened_residual_std: float | None = None
    speed_scaled_gain: float | None = None

    @classmethod
    def from_run(cls, frame: Any, residual_std: float | None = None) -> TrainingRecord:
        """The record of a training run (a DataFrame with the recording columns): the
        largest finite ``|road_curvature|`` (1/m) and the finite ``speed`` range (m/s), each
        None when the run lacks the column or has no finite value."""
        return cls(
            residual_std=residual_std,
            curvature=_finite_max_abs(
                frame["road_curvature"] if "road_curvature" in frame else None
            ),
            speed_range=_finite_range(frame["speed"] if "speed" in frame else None),
        )

    @classmethod
    def measured(cls, model: Any, runs: Any, *, steering_ratio: float = 1.0) -> TrainingRecord:
        """The record of ``model`` fitted on ``runs`` (a DataFrame or a sequence of them, the
        recording columns), measured there as ``hasa-bench`` measures its models on their
        training runs: the roads and speeds (:meth:`from_run`), the one-step residual level
        (:func:`~estimators.tuning.steering_residual_std`), the prediction check against a
        lane-free autoregression (:func:`~estimators.tuning.prediction_check`), the level
        of its form whitened by a declared equation-error autoregression
        (:func:`~estimators.tuning.whitened_residual_std`) and the gain of a declared
        speed-scaled error (:func:`~estimators.tuning.speed_scaled_gain`); the last four None
        for a model without an ARX form. ``steering_ratio``: model units per recorded
        road-wheel radian (1 for models fitted on recordings). The lane-keeping check, which
        drives cars with the model, is not made here (``keeps_lane`` None;
        :func:`hasa_env.drivers.lane_keeping_check`):
        ``trusted_filter(model, training=TrainingRecord.measured(model, runs))`` is the
        filter ``hasa-bench`` gives a model it fitted on ``runs`` and that passed that check."""
        frames = [runs] if isinstance(runs, pd.DataFrame) else list(runs)
        if not frames:
            raise ValueError("TrainingRecord.measured needs at least one training run")
        record = cls.from_run(pd.concat(frames, ignore_index=True))
        arx = model.arx()
        if arx is None:
            return record
        lag = int(getattr(model, "decision_lag", 1))
        data = frames[0] if len(frames) == 1 else frames
        return replace(
            record,
            residual_std=steering_residual_std(
                arx, data, decision_lag=lag, steering_ratio=steering_ratio
            ),
            prediction=prediction_check(arx, data, decision_lag=lag, steering_ratio=steering_ratio),
            whitened_residual_std=whitened_residual_std(model, data, steering_ratio=steering_ratio),
            speed_scaled_gain=speed_scaled_gain(model, data, steering_ratio=steering_ratio),
        )


def _finite(values: Any) -> np.ndarray:
    out = np.asarray(values, dtype=np.float64).reshape(-1)
    return out[np.isfinite(out)]


def _finite_max_abs(values: Any) -> float | None:
    finite = np.abs(_finite(values)) if values is not None else np.empty(0)
    return float(finite.max()) if finite.size else None


def _finite_range(values: Any) -> tuple[float, float] | None:
    finite = _finite(values) if values is not None else np.empty(0)
    return (float(finite.min()), float(finite.max())) if finite.size else None


STEERING_EVERYWHERE = "the steering counts at every speed and on every road"
"""What :meth:`TrustedFilter.describe` says of a filter that listens to the steering without
any limit or reason."""


@dataclass(frozen=True)
class TrustedFilter:
    """The filter :func:`trusted_filter` makes of a steering model.

    Attributes:
        settings: the filter's :class:`FilterSettings`.
        arx: the ARX form the filter compares with the steering (the model's own, multiplied
            through by its equation error's autoregression when it has one); None: no lane evidence from the steering (no model, no ARX
            form, or the model failed its lane-keeping check).
        decision_lag: the model's decision lag (samples; 0 without ``arx``).
        reasons: one human-readable line per channel the rule switches off or tempers, and
            for a model fitted on straight roads whether it gets the curvature feed-forward
            and why (empty: the steering counts at every speed and on every road as it is).
        equation_error_reason: the line of ``reasons`` that says whether the model's declared
            equation-error autoregression is taken (the form whitened by it) or ignored, the
            one reason decided by the data the training record measured its levels on
            (``hasa-replay``: each recording); ``""`` when the model declares none or gives
            no lane evidence.
    """

    settings: FilterSettings
    arx: ARXForm | None
    decision_lag: int
    reasons: tuple[str, ...] = ()
    equation_error_reason: str = ""

    def estimator(self, dt: float | None = None) -> GaussianMixtureEKF:
        """A fresh filter (sample time ``dt`` s; None: the filter's default): the mixture EKF
        on the model's ARX form, or the no-steering one without it."""
        kwargs = {} if dt is None else {"dt": dt}
        if self.arx is None:
            return NoSteeringEKF(self.settings, **kwargs)
        return GaussianMixtureEKF(self.arx, self.settings, decision_lag=self.decision_lag, **kwargs)

    def describe(self) -> str:
        """The reasons in one line."""
        if self.arx is not None and not self.reasons:
            return STEERING_EVERYWHERE
        return "; ".join(self.reasons)


def model_limits(
    model: Any, training: TrainingRecord | None = None
) -> tuple[float, tuple[float, float]]:
    """(``steering_curvature_limit`` 1/m, (``min_speed``, ``steering_max_speed``) m/s) of a
    steering model: from its own record of the roads and speeds it was fitted on, else from
    ``training``'s; ``math.inf`` and ``(0, math.inf)`` when neither says."""
    training = training or TrainingRecord()
    curvature = getattr(model, "training_curvature", None)
    if curvature is None:
        curvature = training.curvature
    speeds = getattr(model, "training_speed_range", None)
    if speeds is None:
        speeds = training.speed_range
    return steering_curvature_limit(curvature), steering_speed_limits(speeds)


def curvature_feedforward(arx: ARXForm, wheelbase: float, steering_ratio: float = 1.0) -> float:
    """G (model units per 1/m): the steering a driver adds on a bend beyond what the ARX
    model's bearings explain, so that its steady state on a bend of curvature kappa, centred in
    the lane and aligned with it, is the kinematic ``steering_ratio L kappa`` (docs/design.md
    §8.28)::

        bearings there:  phi = kappa near / 2,  Omega = kappa far / 2,  v_y = 0
        model's steady steering:  (sum b near + sum c far) kappa / (2 (1 - sum a))
        G = steering_ratio L - (sum b near + sum c far) / (2 (1 - sum a))

    NaN when the autoregression has no steady state (no steering lags, or ``sum a >= 1``)."""
    steady = _steady_state(arx)
    if steady is None:
        return math.nan
    bearings, rest = steady
    return steering_ratio * wheelbase - bearings / (2.0 * rest)


def _steady_state(arx: ARXForm) -> tuple[float, float] | None:
    """``(sum b near + sum c far, 1 - sum a)`` of :func:`curvature_feedforward`; None when the
    autoregression has no steady state (no steering lags, or ``sum a >= 1``)."""
    total_a = float(np.sum(arx.a))
    if not len(arx.a) or total_a >= 1.0:
        return None
    bearings = float(np.sum(arx.b)) * arx.near_distance + float(np.sum(arx.c)) * arx.far_distance
    return bearings, 1.0 - total_a


FEEDFORWARD_PRECISION = 0.25
"""The largest standard error of G, relative to G, at which the rule gives a model the
curvature feed-forward (docs/design.md §8.28): at 2 standard errors G is then within half of
itself, so the correction removes at least half of the bend's bias."""


def curvature_feedforward_error(model: Any) -> float:
    """The standard error of :func:`curvature_feedforward` from the model's fit: the delta
    method on its parameters' covariance (``model.parameter_covariance``: the fit's, or the one
    its model file kept; else a duck-typed model's ``fit_result.covariance``), the parameters
    mapped to a, b, c by their regressors' features ``delta``, ``phi``, ``omega``. NaN without
    a covariance (a preset, a model file written without one), without a steady state, or for
    a model that does not name its parameters' regressors (``parameter_names``,
    ``regressors``) or whose covariance does not match its parameters."""
    arx = model.arx() if model is not None else None
    if arx is None:
        return math.nan
    steady = _steady_state(arx)
    if steady is None:
        return math.nan
    names = getattr(model, "parameter_names", None)
    regressors = getattr(model, "regressors", None)
    covariance = getattr(model, "parameter_covariance", None)
    order = names
    if covariance is None:  # a model that is no SteeringModel: its fit record, if any
        result = getattr(model, "fit_result", None)
        covariance = getattr(result, "covariance", None)
        order = getattr(result, "parameter_names", None)
    if covariance is None or names is None or regressors is None or order is None:
        return math.nan  # no covariance, or no saying which parameter is which: unknown
    covariance = np.asarray(covariance, dtype=np.float64)
    if covariance.shape != (len(order), len(order)):
        return math.nan
    features = {name: getattr(r, "feature", "") for name, r in zip(names, regressors, strict=False)}
    total_b_c, rest = steady
    slope = {
        "delta": -total_b_c / (2.0 * rest * rest),
        "phi": -arx.near_distance / (2.0 * rest),
        "omega": -arx.far_distance / (2.0 * rest),
    }
    gradient = np.array([slope.get(features.get(name, ""), 0.0) for name in order])
    variance = float(gradient @ covariance @ gradient)
    return math.sqrt(variance) if variance >= 0 else math.nan


def trusted_filter(
    model: Any,
    base: FilterSettings | None = None,
    *,
    steering_ratio: float = 1.0,
    training: TrainingRecord | None = None,
    overrides: Mapping[str, Any] | None = None,
    checks: bool | None = None,
) -> TrustedFilter:
    """The filter for steering ``model`` (any object with ``arx()``; None: no model) by the
    rule of this module's docstring.

    Args:
        base: the settings the rule starts from (e.g. :meth:`FilterSettings.from_env_config`
            of the env or recording; None: the defaults).
        steering_ratio: model units per measured road-wheel radian (> 0).
        training: what the caller knows of the fit and its checks (:class:`TrainingRecord`).
        overrides: :class:`FilterSettings` fields the user set; each wins over the rule.
        checks: True / False: force ``evidence_checks`` (False also drops the model's
            limits and lane-keeping check); None: keep the settings' own.

    Raises:
        ValueError / TypeError: an override names no field or is out of its range.
    """
    training = training or TrainingRecord()
    overrides = dict(overrides or {})
    settings = FilterSettings.with_overrides(base, overrides)
    arx = None if model is None else model.arx()
    off = _switched_off(model, arx, training, checks)
    limits = model_limits(model, training)  # (curvature 1/m, (low, high) m/s) it was fitted on
    rule: dict[str, Any] = {"steering_ratio": steering_ratio}
    noise, white_scale, noise_why = _equation_error(model, arx, training)
    speed_scaled, scaled_why = _speed_scaled(model, arx, training)
    if speed_scaled is not None:  # the coloured part a state of the filter, no whitening
        noise, white_scale, noise_why = (), 1.0, scaled_why
        rule["steering_coloured_error_std"] = speed_scaled.coloured_std
        rule["steering_coloured_error_correlation"] = speed_scaled.correlation
        rule["steering_coloured_error_speed"] = speed_scaled.reference_speed
    elif scaled_why:
        noise_why = "; ".join(why for why in (scaled_why, noise_why) if why)
    level = training.residual_std
    if level is None and noise:  # the base settings' level stands in for the model's
        level = settings.steering_residual_std
    if speed_scaled is not None:
        rule["steering_residual_std"] = max(speed_scaled.white_std, 1e-9)
    elif level is not None:
        rule["steering_residual_std"] = max(float(level) * white_scale, 1e-9)
    if checks is not None:  # the caller's choice, over the user's
        rule["evidence_checks"] = checks
        overrides.pop("evidence_checks", None)
    if checks is False:  # the unchecked filter: no limits, not even the user's curvature limit
        rule["steering_curvature_limit"] = math.inf
        overrides.pop("steering_curvature_limit", None)
    elif not off:
        curvature, (low, high) = limits
        rule["steering_curvature_limit"] = curvature
        rule["min_speed"] = max(settings.min_speed, low)
        rule["steering_max_speed"] = high
    feedforward_why = ""
    if not off:  # a model of straight roads, given the bends' steady steering (checked or not)
        feedforward, feedforward_why = _feedforward(
            model, arx, settings, limits[0], steering_ratio, overrides
        )
        if feedforward is not None:
            rule["steering_curvature_feedforward"] = feedforward
            rule["steering_curvature_limit"] = math.inf
    settings = replace(settings, **{k: v for k, v in rule.items() if k not in overrides})
    if off:
        return TrustedFilter(settings, None, 0, off)
    reasons = _reasons(settings, model, training, overrides, checks, feedforward_why)
    if noise_why:
        reasons += (noise_why,)
    assert arx is not None  # not off: the model has an ARX form
    return TrustedFilter(
        settings,
        whitened_arx(arx, noise),
        int(getattr(model, "decision_lag", 1)),
        reasons,
        noise_why,
    )


def _equation_error(
    model: Any, arx: ARXForm | None, training: TrainingRecord
) -> tuple[tuple[float, ...], float, str]:
    """The model's equation-error autoregression the filter whitens by (``()``: none), the
    factor ``sqrt(1 - sum_i r_i rho_i)`` from its error's level to that of the whitened one
    (1 without) and the reason line. A declared one (``equation_error_ar``) is taken unless the record measured
    that it does not lower the one-step residual on the data (``whitened_residual_std`` at or
    above ``residual_std``): a model of its error that predicts worse than none is not its
    error's (docs/design.md §8.32). ValueError naming the problem when it is not a stationary
    autoregression."""
    if model is None or arx is None:
        return (), 1.0, ""
    noise = getattr(model, "equation_error_ar", ()) or ()
    try:
        noise = check_equation_error_ar(noise)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"steering model {getattr(model, 'name', model)!r}: {exc}") from None
    if not noise:
        return (), 1.0, ""
    listed = ", ".join(f"{r:.3g}" for r in noise)
    own, white = training.residual_std, training.whitened_residual_std
    if own is not None and white is not None and not white < own:
        return (
            (),
            1.0,
            (
                f"its equation error's autoregression r = ({listed}) ignored: whitened by it, the "
                f"steering's one-step residual is {white:.3g} rad, not below its own {own:.3g} rad"
            ),
        )
    scale = math.sqrt(innovation_variance_ratio(noise))
    how = f"residual level x {scale:.3f}"
    if own is not None and white is not None:
        how += f"; whitened, the one-step residual is {white:.3g} rad against {own:.3g} rad"
    return (
        noise,
        scale,
        (
            f"the steering compared whitened by its equation error's autoregression "
            f"r = ({listed}) ({how})"
        ),
    )


def _speed_scaled(
    model: Any, arx: ARXForm | None, training: TrainingRecord
) -> tuple[SpeedScaledError | None, str]:
    """The model's declared speed-scaled equation error the filter carries (None: none, or
    ignored) and the reason line. Taken unless the record measured that it describes the
    residuals no better than one white level (``speed_scaled_gain`` not above 0)."""
    declared = getattr(model, "equation_error_speed_scaled", None) if arx is not None else None
    if declared is None:
        return None, ""
    gain = training.speed_scaled_gain
    described = (
        f"a coloured part of std {declared.coloured_std:.3g} rad at "
        f"{declared.reference_speed:g} m/s scaled by (v_ref / v)^2, rho "
        f"{declared.correlation:.3f} per sample, and a white part of std "
        f"{declared.white_std:.3g} rad"
    )
    if gain is not None and not gain > 0:
        return None, (
            f"its speed-scaled equation error ({described}) ignored: it describes the "
            f"steering's one-step residuals no better than one white level "
            f"({gain:+.3g} nats per sample)"
        )
    how = "" if gain is None else f"; {gain:+.3g} nats per sample over one white level"
    return declared, (
        f"the steering's equation error carried as {described} (docs/design.md §8.34{how})"
    )


def _feedforward(
    model: Any,
    arx: ARXForm | None,
    settings: FilterSettings,
    curvature_limit: float,
    steering_ratio: float,
    overrides: Mapping[str, Any],
) -> tuple[float | None, str]:
    """The curvature feed-forward the rule gives a model fitted on straight roads only (its
    curvature limit :data:`STRAIGHT_CURVATURE`) whose fit pins G down (standard error at most
    :data:`FEEDFORWARD_PRECISION` of G), None for any other (fitted on bends, unknown roads, no
    steady state, no covariance, G too uncertain) or when the user set one; and the reason
    line that says why ('' for a model that is not of straight roads, or when the user set
    the curvature limit and the rule gives no feed-forward)."""
    if arx is None:
        return None, ""
    if "steering_curvature_feedforward" in overrides:  # the user's, already in ``settings``
        user = settings.steering_curvature_feedforward
        if user == 0.0:
            return None, ""
        return None, f"on bends, the steering less G kappa: G = {user:.3g} set by the user"
    if not math.isclose(curvature_limit, STRAIGHT_CURVATURE, rel_tol=1e-9):
        return None, ""
    gain = curvature_feedforward(arx, settings.wheelbase, steering_ratio)
    error = curvature_feedforward_error(model)
    if math.isfinite(gain) and error <= FEEDFORWARD_PRECISION * abs(gain):
        return gain, (
            f"on bends, the steering less the bend's steady steering G kappa: G = {gain:.3g} "
            f"(standard error {error:.2g}), a model fitted on straight roads only "
            "(docs/design.md §8.28)"
        )
    if "steering_curvature_limit" in overrides:  # the user's limit says what happens on bends
        return None, ""
    if not math.isfinite(gain):
        return None, "no curvature feed-forward: its autoregression has no steady state"
    if not math.isfinite(error):
        return None, (
            f"no curvature feed-forward (G = {gain:.3g}): the covariance of its parameters is "
            "unknown (a preset, or a model file saved without one), so whether its fit pins G "
            "down is unknown"
        )
    return None, (
        f"no curvature feed-forward: its fit does not pin G down (G = {gain:.3g}, standard "
        f"error {error:.2g}, more than {FEEDFORWARD_PRECISION:.0%} of G)"
    )


def _switched_off(
    model: Any, arx: ARXForm | None, training: TrainingRecord, checks: bool | None
) -> tuple[str, ...]:
    """The reason the steering gives no lane evidence at all (empty: it may)."""
    if model is None:
        return ("steering off: no steering model",)
    if arx is None:
        return (f"steering off: the model {getattr(model, 'name', '')!r} has no ARX form",)
    if checks is not False and training.keeps_lane is False:
        summary = f" ({training.lane_check})" if training.lane_check else ""
        return (
            "steering off: the model does not keep the car in its lane when it steers itself"
            + summary,
        )
    if checks is not False and training.prediction is not None and not training.prediction.passed:
        return (
            "steering off: the model predicts the steering no better than its own past does "
            f"({training.prediction.describe()})",
        )
    return ()


def _reasons(
    settings: FilterSettings,
    model: Any,
    training: TrainingRecord,
    overrides: Mapping[str, Any],
    checks: bool | None,
    feedforward_why: str = "",
) -> tuple[str, ...]:
    """One line per limit the settings put on the steering channel, and why, with the line
    of :func:`_feedforward` (``feedforward_why``) after the curvature limit's."""
    if checks is False:
        return ("no trust rules: the evidence checks and the model's limits are off",)
    user = "set by the user"
    reasons = []
    limit = settings.steering_curvature_limit
    if math.isfinite(limit):
        why = f"{user} (steering_curvature_limit)"
        if "steering_curvature_limit" not in overrides:
            roads = limit - STRAIGHT_CURVATURE
            why = f"beyond the roads it was fitted on (|curvature| up to {roads:.3g} 1/m)"
        reasons.append(f"steering off where the road ahead curves more than {limit:.3g} 1/m: {why}")
    if feedforward_why:
        reasons.append(feedforward_why)
    speeds = getattr(model, "training_speed_range", None) or training.speed_range
    fitted = (
        f"outside the training speeds {speeds[0]:.1f}-{speeds[1]:.1f} m/s +- {SPEED_MARGIN:g}"
        if speeds is not None
        else "set in the filter settings"
    )
    if settings.min_speed > FilterSettings.min_speed:
        why = f"{user} (min_speed)" if "min_speed" in overrides else fitted
        reasons.append(f"steering off below {settings.min_speed:.1f} m/s: {why}")
    if math.isfinite(settings.steering_max_speed):
        why = f"{user} (steering_max_speed)" if "steering_max_speed" in overrides else fitted
        reasons.append(f"steering off above {settings.steering_max_speed:.1f} m/s: {why}")
    return tuple(reasons)

"""Settings of the mixture filter: noise levels, priors, gate, pruning (SI units)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import KW_ONLY, dataclass, replace
from typing import Any

import numpy as np

from hasa_env.validation import Field, schema, validate_fields

__all__ = [
    "SPEED_MARGIN",
    "STRAIGHT_CURVATURE",
    "FilterSettings",
    "model_curvature_limit",
    "model_speed_limits",
    "steering_curvature_limit",
    "steering_speed_limits",
]


def _positive(unit: str = "", infinite: bool = False) -> Field:
    return Field("number", unit=unit, low=0.0, low_open=True, infinite=infinite)


def _non_negative(unit: str = "") -> Field:
    return Field("number", unit=unit, low=0.0)


_SCHEMA = schema(
    {
        "speed_noise_std": _positive("m/s"),
        "camera_noise_std": _positive("m"),
        "acceleration_noise_std": _non_negative("m/s^2"),
        "steering_residual_std": _non_negative("rad"),
        "steering_sensor_std": _non_negative("rad"),
        "steering_ratio": _positive(),
        "initial_speed_std": _positive("m/s"),
        "initial_lateral_std": Field("number", unit="m", low=0.0, optional=True),
        "initial_lateral_velocity_std": _non_negative("m/s"),
        "bias_std": _non_negative("m"),
        "memory_std": _non_negative("rad"),
        "bias_drift_std": _non_negative("m"),
        "memory_process_std": _non_negative("rad"),
        "missing_acceleration_std": _non_negative("m/s^2"),
        "prune_threshold": Field("number", low=0.0, high=1.0, high_open=True),
        "innovation_gate": _positive(infinite=True),
        "min_speed": _non_negative("m/s"),
        "steering_curvature_limit": Field("number", unit="1/m", low=0.0, infinite=True),
        "steering_max_speed": _positive("m/s", infinite=True),
        "max_acceleration": _positive("m/s^2", infinite=True),
        "evidence_checks": Field("bool"),
        "evidence_window": _positive("s"),
        "evidence_confidence": Field("number", low=0.0, high=1.0, high_open=True),
        "mismatch_model_error": Field("number", low=1.0, low_open=True, infinite=True),
        "forgetting_time": _positive("s", infinite=True),
        "decision_threshold": Field("number", low=0.5, high=1.0, high_open=True),
        "commit_time": _positive("s", infinite=True),
        "weight_floor": Field("number", low=0.0, high=1e-3),
        "preferred_offset_std": Field("number", unit="m", low=0.0, high=2.0),
        "preferred_offset_drift_std": _non_negative("m"),
        "aim_offset_std": Field("number", unit="m", low=0.0, high=2.0),
        "aim_offset_time": _positive("s"),
        "aim_offset_limit": _positive(infinite=True),
        "mismatch_drops_steering": Field("bool"),
        "wheelbase": _positive("m"),
        "steering_curvature_feedforward": Field("number", unit="rad m"),
        "steering_coloured_error_std": _non_negative("rad"),
        "steering_coloured_error_correlation": Field("number", low=0.0, high=1.0, high_open=True),
        "steering_coloured_error_speed": _positive("m/s"),
    }
)
"""What every field of :class:`FilterSettings` allows."""


@dataclass(frozen=True)
class FilterSettings:
    """Noise levels, priors and pruning of the mixture filter (SI units; rad in model units).

    Attributes:
        speed_noise_std: speedometer noise (m/s), R_11 = std^2.
        camera_noise_std: camera lateral-offset noise (m), R_22.
        acceleration_noise_std: IMU noise (m/s^2) on each axis; process noise
            Q = B_D diag(std^2) B_D^T on the vehicle states.
        steering_residual_std: std of the steering model's equation error e(k)
            (rad, model units): the model residual level, which dominates the
            steering channel. R_33 = residual^2 + (ratio * sensor)^2.
        steering_sensor_std: steering-sensor noise (rad, measured units).
        steering_ratio: model units per measured unit: the filter compares
            ``steering_ratio * delta_measured`` with the model (1: the model
            predicts the road-wheel angle the sensor measures).
        initial_speed_std: prior std of v_x around the first speed reading (m/s).
        initial_lateral_std: prior std of y_i around ``camera - b_i`` (m);
            None: camera_noise_std.
        initial_lateral_velocity_std: prior std of v_y around 0 (m/s).
        bias_std: prior std of each hypothesis' bias around b_i (m).
        memory_std: prior std of each memory state around its constant-past
            value (rad, model units).
        bias_drift_std: random-walk std of b per sample (m); 0: constant bias.
        memory_process_std: extra process noise on each memory state per
            sample (rad), for model mismatch beyond the equation error.
        missing_acceleration_std: process noise (m/s^2) used in place of the
            IMU noise when an IMU reading is NaN (the input is then taken as 0).
        prune_threshold: hypotheses whose weight falls below this are pruned
            (weight 0, state frozen; irreversible); the most likely one is
            never pruned. Default 0: no pruning (``weight_floor`` keeps
            unlikely hypotheses alive instead).
        innovation_gate: outlier gate g on each measurement channel c (speed,
            camera, steering). The channel is missing at this step for every
            hypothesis (never gated per hypothesis: a wrong hypothesis' large
            steering innovations *are* the lane evidence) when no hypothesis
            explains it, each weighed by its log-odds against the most likely
            one (weights w_i before the update)::

                min_i [ nu_ic^2 / S_i,cc + 2 ln(w_max / w_i) ] > g^2

            For the most likely hypothesis the term is its normalized
            innovation, ``|nu_c| / sqrt(S_cc) > g``; a less likely hypothesis
            keeps the channel only if it explains it better by its log-odds,
            so once a lane is decided (``w_max / w_i > exp(g^2 / 2)``, 7e7 for
            g = 6) the test is the most likely hypothesis' alone, while a
            wrong favourite cannot veto the evidence against itself (with the
            favourite's test alone, a 0.99 prior on the wrong lane kept 2 of
            9 synthetic-population runs on it for all 30 s, their steering
            gated at 2997 of 3000 steps). Default 6: a Gaussian channel
            exceeds it with probability 2e-9 per sample; a camera reading
            30 m off is about 600 sigma. ``math.inf`` turns gating off.
        min_speed: below this speed (m/s) the steering channel is off: no
            update from it and no weight from it (the run's mixture speed
            estimate ``sum_i w_i |v_i|`` at k-1 decides, the same for every
            hypothesis), and the memory states are held (``m(k+1) = m(k)``,
            no bearing terms: ``theta = atan2(v_y, v_x)`` and its Jacobian
            ``1 / |v|`` degenerate as v -> 0). When the estimate rises above it
            again the memory states restart from the measured steering and
            each hypothesis' own bearings, as at reset. Default 3 m/s (11
            km/h): the filter's lateral-velocity error is about 0.03 m/s rms
            on the synthetic population (0.005 m/s with a matched model),
            which at 3 m/s tilts theta by 10 mrad, the near-point bearing of
            a 6 cm offset (at 15 m/s: 2 mrad), so the bearings stop carrying
            lane information; and the steering models describe lane keeping
            at road speeds (the paper fits 15-45 m/s), not manoeuvring. 0
            turns it off.
        steering_curvature_limit: where the road ahead curves more than this
            (1/m: the largest ``|kappa|`` of the lane centre at the near and
            far points, ``kappa = 2 dy / (dx^2 + dy^2)`` from the road points
            of :mod:`estimators.road_geometry`), the steering channel is off
            as below ``min_speed`` (memory held, restarted after): the steering
            model is trusted only on roads as curved as those it was fitted
            on. A model fitted on a straight road mispredicts the steering on
            a bend by a slowly varying offset that a lane offset explains as
            well: measured on the benchmark's curved track, the generalized
            model fitted on a straight run ended 6 of 20 runs with more than
            0.99 on the wrong lane, each flipped within 1 s of the first bend
            while its model error stayed near 1 (consistent). The benchmark,
            the advisor task and the command-line programs set it per model
            from the roads it was fitted on (:func:`estimators.trust.trusted_filter`);
            ``math.inf`` (the default) trusts the model on any road.
        steering_max_speed: above this speed (m/s, the mixture's estimate) the
            steering channel is off as below ``min_speed`` (memory held,
            restarted below it): with ``min_speed`` it confines the steering
            evidence to the speeds a model was fitted at. ``math.inf`` (the
            default): any speed. The benchmark, the advisor task and the
            command-line programs set both per model from the speeds it was
            fitted at (:func:`estimators.trust.trusted_filter`; docs/design.md §8.11).
        max_acceleration: IMU readings with |a| above this (m/s^2) are
            implausible and treated as missing, like NaN (input 0 with
            ``missing_acceleration_std``). Default 50 m/s^2 (about 5 g):
            several times what tyres can transmit (about 10 m/s^2), so it
            only catches sensor faults. ``math.inf`` turns it off.
        evidence_checks: temper the steering evidence by its consistency,
            forget toward the prior, floor the weights and stop on a model
            mismatch (:mod:`estimators.evidence`, whose docstring states the
            rule). False: the weights follow paper eq. 19 as written (the
            decision state is still reported).
        evidence_window: time constant (s) of the running normalized-
            innovation statistics (lambda, rho) of the steering channel.
        evidence_confidence: the steering evidence is tempered by an upper
            confidence bound on lambda at this one-sided probability, not by
            lambda itself (:func:`estimators.evidence.model_error_bound`): a
            model earns its weight as the data check it. 0 (or 0.5 and
            below): lambda itself.
        mismatch_model_error: lambda (the best hypothesis' running mean
            normalized steering innovation squared; 1 for a consistent model)
            above which the model fits no hypothesis: a model mismatch, while
            which the weights do not move. Default 9: residuals three times the
            level the filter was given. The drivers of the synthetic population
            differ by up to 3x in their steering noise, so a model tuned on one
            driver meets lambda up to about 9 on the others while it still tells
            their lanes apart; with 4, the benchmark's generalized model lost
            0.035 m of lateral RMSE to runs frozen undecided (0.171 m against
            0.136 m, seeds 0-4) and the sign-flipped stress model ended 7
            instead of 4 of 465 runs in the wrong lane.
        forgetting_time: time constant (s) with which the log weights return
            to the prior without fresh evidence (``math.inf``: never).
        decision_threshold: the weight a hypothesis needs for the run to be
            ``"decided"``.
        commit_time: how long (s) a checked decision must hold before a reversal of it
            counts as a contradiction (:mod:`estimators.evidence`, the reversal rule;
            ``math.inf``: never, the rule is off).
        weight_floor: no weight falls below this (0: no floor).
        preferred_offset_std: prior std sigma_p (m) of the driver's preferred lateral
            offset p, a state of every hypothesis when > 0 (a steering model's features
            are then taken from y - p; :mod:`estimators.arx_state_space`, docs/design.md
            §8.18). 0: no such state, the driver is assumed to aim at the lane centre.
        preferred_offset_drift_std: random-walk std of p per sample (m).
        aim_offset_std: prior std sigma_a (m) of where a driver holds the car from the lane
            centre. When > 0, no run's lane log-odds (weights against the prior) exceed what
            that prior gives for where the car has been held under each hypothesis, its
            lateral offset averaged over ``aim_offset_time`` (:mod:`estimators.evidence`, the
            aim cap; docs/design.md §8.19). Default 0.3 m: people hold the car 0.2-0.5 m
            from the centre. 0: no cap (the filter before it).
        aim_offset_time: time constant (s) of that average. Default 10 s (2 s before
            docs/design.md §8.23: a 2 s average follows the car's wander, and the cap's
            ratchet kept the largest bound any wander allowed).
        aim_offset_limit: with the aim cap on, a run in which the average offset of *every*
            hypothesis has passed ``aim_offset_limit * aim_offset_std`` (in units of sigma_a;
            default 4: 1.2 m), at steps where the car was held within half that of some
            hypothesis' centre, is refused as a model mismatch for the rest of the
            run: the driver held the car where the aim prior puts no driver under any
            hypothesis (a lane shift or change followed on purpose), so no lane-keeping
            steering model's evidence means anything there (:mod:`estimators.evidence`, the
            path rule; docs/design.md §8.24). ``math.inf``: off.
        mismatch_drops_steering: while a run is in ``model_mismatch`` its steering reading
            updates none of its states (its innovation is still scored, so the mismatch test
            can end): the evidence rule has rejected the model there, and a reading it
            mispredicts by many times its residual level would drag the lateral estimate
            (docs/design.md §8.25). False: the steering updates the states throughout (the
            filter before 2026-12-05).
        wheelbase: the car's wheelbase L (m; the env's ``vehicle.wheelbase``).
        steering_curvature_feedforward: G (model units per 1/m): the steering a driver
            adds on a bend of curvature kappa beyond what the model's bearings explain; the
            filter compares the model with ``steering_ratio * delta_measured - G kappa``,
            kappa read from the road points (:func:`estimators.arx_state_space.road_curvature_ahead`).
            0 (the default): none. The trust rule sets it for a model fitted on straight roads,
            from its coefficients and L (:func:`estimators.trust.curvature_feedforward`;
            docs/design.md §8.28).
        steering_coloured_error_std: the stationary std (rad, model units) at
            ``steering_coloured_error_speed`` of a coloured part of the equation error whose
            level scales with the speed as ``(v_ref / v)^2``: the steering a given lateral
            acceleration needs (docs/design.md §8.34). When > 0 every hypothesis carries it as
            a state epsilon (:mod:`estimators.arx_state_space`) and
            ``steering_residual_std`` is the white rest of the error. 0 (the default): none.
        steering_coloured_error_correlation: rho, epsilon's correlation from one sample to
            the next (``epsilon(k+1) = rho epsilon(k) + eta(k)``), in [0, 1).
        steering_coloured_error_speed: v_ref (m/s), the speed at which epsilon's stationary
            std is ``steering_coloured_error_std``.
    """

    speed_noise_std: float = 0.05
    camera_noise_std: float = 0.05
    acceleration_noise_std: float = 0.05
    steering_residual_std: float = 2e-3
    steering_sensor_std: float = 1e-4
    steering_ratio: float = 1.0
    initial_speed_std: float = 0.1
    initial_lateral_std: float | None = None
    initial_lateral_velocity_std: float = 0.3
    bias_std: float = 1e-3
    memory_std: float = 0.01
    bias_drift_std: float = 0.0
    memory_process_std: float = 0.0
    missing_acceleration_std: float = 3.0
    prune_threshold: float = 0.0
    _: KW_ONLY  # the fields below are keyword-only
    innovation_gate: float = 6.0
    min_speed: float = 3.0
    steering_curvature_limit: float = math.inf
    steering_max_speed: float = math.inf
    max_acceleration: float = 50.0
    evidence_checks: bool = True
    evidence_window: float = 5.0
    evidence_confidence: float = 0.0
    mismatch_model_error: float = 9.0
    forgetting_time: float = math.inf
    decision_threshold: float = 0.95
    commit_time: float = 1.0
    weight_floor: float = 0.0
    preferred_offset_std: float = 0.0
    preferred_offset_drift_std: float = 0.0
    aim_offset_std: float = 0.3
    aim_offset_time: float = 10.0
    aim_offset_limit: float = 4.0
    mismatch_drops_steering: bool = True
    wheelbase: float = 2.8
    steering_curvature_feedforward: float = 0.0
    steering_coloured_error_std: float = 0.0
    steering_coloured_error_correlation: float = 0.0
    steering_coloured_error_speed: float = 15.0

    def __post_init__(self) -> None:
        """Validate every field (:mod:`hasa_env.validation`; ValueError naming the field and
        its allowed range) and keep the converted values (numpy scalars become floats)."""
        validate_fields(
            self,
            _SCHEMA,
            describe=lambda path: f"FilterSettings.{path}",
            error=lambda path, message: ValueError(message),
        )
        if self.steering_residual_std == 0 and self.steering_sensor_std == 0:
            raise ValueError(
                "FilterSettings.steering_residual_std and steering_sensor_std cannot both be 0 "
                "(the steering channel would have no noise)"
            )

    @classmethod
    def with_overrides(
        cls, settings: FilterSettings | None, overrides: Mapping[str, Any]
    ) -> FilterSettings:
        """``settings`` (default: the defaults) with the named fields replaced."""
        settings = settings or cls()
        return replace(settings, **overrides) if overrides else settings

    @classmethod
    def from_env_config(cls, config: Mapping[str, Any], **overrides: Any) -> FilterSettings:
        """Settings with the sensor noise levels of an env config (``env.unwrapped.config``)."""
        noise = config["noise"]
        values = {
            "speed_noise_std": float(noise["speed"]),
            "camera_noise_std": float(noise["camera"]),
            "acceleration_noise_std": float(noise["imu"]),
            "steering_sensor_std": float(noise["steering"]),
        }
        wheelbase = config.get("vehicle", {}).get("wheelbase")
        # a noise-free env would make R singular: keep a floor
        floored: dict[str, Any] = {k: max(v, 1e-6) for k, v in values.items()}
        if wheelbase is not None:
            floored["wheelbase"] = float(wheelbase)
        floored.update(overrides)
        return cls(**floored)


STRAIGHT_CURVATURE = 2e-4
"""|kappa| (1/m) below which a road counts as straight for a steering model: a radius of 5 km,
whose steady-state steering (L kappa, 0.5 mrad at the road wheel for L = 2.7 m) is a few
times the steering noise the filter is given."""


def steering_curvature_limit(training_curvature: Any) -> float:
    """The ``steering_curvature_limit`` (1/m) for a model fitted on data with road curvature
    ``training_curvature`` (1/m, any shape; NaN ignored; None or empty: unknown, ``math.inf``):
    the largest ``|kappa|`` it saw plus :data:`STRAIGHT_CURVATURE`."""
    if training_curvature is None:
        return math.inf
    values = np.abs(np.asarray(training_curvature, dtype=np.float64)).reshape(-1)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.inf
    return float(values.max()) + STRAIGHT_CURVATURE


def model_curvature_limit(model: Any) -> float:
    """The ``steering_curvature_limit`` (1/m) for a steering model from the roads it was fitted
    on (its ``training_curvature``, set by ``fit`` and kept in its file; the paper's presets
    0), ``math.inf`` when they are unknown."""
    value = getattr(model, "training_curvature", None)
    return math.inf if value is None else steering_curvature_limit(value)


SPEED_MARGIN = 1.0
"""m/s by which a model's training speeds are widened before its steering counts as evidence
(:func:`steering_speed_limits`). Set after one trace (docs/design.md §8.11: a fit at 15 m/s whose
lane evidence turned between 16.9 and 18.4 m/s) and checked on seeds not used to set it."""


def steering_speed_limits(training_speeds: Any) -> tuple[float, float]:
    """(``min_speed``, ``steering_max_speed``) in m/s for a model fitted at ``training_speeds``
    (m/s, any shape; NaN ignored; None or empty: unknown, ``(0, math.inf)``): their range widened
    by :data:`SPEED_MARGIN`, the lower end no lower than FilterSettings' default ``min_speed``."""
    if training_speeds is None:
        return 0.0, math.inf
    values = np.asarray(training_speeds, dtype=np.float64).reshape(-1)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 0.0, math.inf
    low = max(float(values.min()) - SPEED_MARGIN, FilterSettings.min_speed)
    return low, float(values.max()) + SPEED_MARGIN


def model_speed_limits(model: Any) -> tuple[float, float]:
    """(``min_speed``, ``steering_max_speed``) (m/s) for a steering model from the speeds it was
    fitted at (its ``training_speed_range``, set by ``fit`` and kept in its file;
    :func:`steering_speed_limits`), ``(0, math.inf)`` when they are unknown (the paper's
    presets, old model files)."""
    return steering_speed_limits(getattr(model, "training_speed_range", None))

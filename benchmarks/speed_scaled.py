"""The speed-scaled equation error of a fitted generalized model (docs/design.md §8.34), fitted
on held-out residuals: one implementation for ``hasa-bench``'s built-in generalized model
(:mod:`benchmarks.protocol.models`) and ``hasa-replay --fit`` (:mod:`benchmarks.recordings`),
and the phrases ``hasa-replay`` prints of what a fit found (its speed-scaled error, its equation
error's autoregression).

A module of its own, not of :mod:`benchmarks.protocol`, so that ``hasa-replay`` does not import
the whole protocol package."""

from __future__ import annotations

import copy
import functools
import warnings
from typing import Any

import pandas as pd

from estimators.tuning import held_out_speed_scaled_error, speed_scaled_gain
from hasa_env.sim.road import Road
from hasa_env.steering import GeneralizedModel, SteeringModel

__all__ = [
    "add_speed_scaled_error",
    "describe_equation_error",
    "describe_speed_scaled",
    "fits_speed_scaled_error",
    "speed_scaled_description",
]


def fits_speed_scaled_error(model: SteeringModel) -> bool:
    """Whether a program that fits ``model`` itself also fits its speed-scaled equation error:
    a :class:`GeneralizedModel` of the class itself, not a subclass (user code, whose refits on
    held-out runs ``hasa-bench`` would have to run isolated). ``hasa-bench`` and ``hasa-replay
    --fit`` both ask this, so they give the same model the same error."""
    return type(model) is GeneralizedModel


def add_speed_scaled_error(
    model: GeneralizedModel,
    fitted: GeneralizedModel,
    runs: list[pd.DataFrame],
    sensor_std: float,
    info: dict[str, Any],
    *,
    road: Road | None = None,
) -> None:
    """Give the generalized model ``fitted`` (``model`` fitted on ``runs``, on ``road``; None:
    each run's from its metadata) its speed-scaled equation error, fitted on held-out residuals
    (each run's from the model refitted on the others; with one run, ``fitted``'s in-sample
    residuals; :func:`estimators.tuning.held_out_speed_scaled_error`), and record in ``info``
    the error (``speed_scaled_error``, :func:`speed_scaled_description`; None: none found, e.g.
    a fit on the boundary or too few residuals), whether it was held out
    (``speed_scaled_held_out``) and its gain over one white level on ``runs``
    (``speed_scaled_gain``, what the trust rule reads)."""
    found, info["speed_scaled_held_out"] = held_out_speed_scaled_error(
        fitted, runs, functools.partial(_refit, model, sensor_std=sensor_std, road=road)
    )
    fitted.equation_error_speed_scaled = found
    info["speed_scaled_error"] = speed_scaled_description(fitted)
    info["speed_scaled_gain"] = speed_scaled_gain(fitted, runs)


def _refit(
    model: GeneralizedModel, runs: list[pd.DataFrame], *, sensor_std: float, road: Road | None
) -> Any:
    """``model`` fitted on ``runs`` as the fit ``fitted`` came from, its warnings not shown
    (they are the fit's own, reported once)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return copy.deepcopy(model).fit(runs, road, sensor_std=sensor_std)


def speed_scaled_description(fitted: SteeringModel) -> dict[str, float] | None:
    """The model's speed-scaled equation error (docs/design.md §8.34) as numbers; None: none."""
    found = getattr(fitted, "equation_error_speed_scaled", None)
    return None if found is None else found.to_dict()


def describe_equation_error(model: SteeringModel) -> str:
    """A fitted model's equation error (docs/design.md §8.32) in one phrase: white, or the
    autoregression its fit estimated."""
    order = int(getattr(model, "equation_error_order", 0))
    ar = ", ".join(f"{r:.3g}" for r in getattr(model, "equation_error_ar", ()) or ())
    if not order or not ar:  # none found: too few residuals, or not stationary
        return "white equation error" + (f" (no AR({order}) found)" if order else "")
    return f"equation error AR({order}): {ar}"


def describe_speed_scaled(found: dict[str, Any]) -> str:
    """What fitting a model's speed-scaled equation error found
    (:func:`benchmarks.speed_scaled.add_speed_scaled_error`'s record), in one phrase."""
    error = found["speed_scaled_error"]
    if error is None:
        return (
            "no speed-scaled equation error found (its fit is on the boundary or the "
            "residuals are too few); the filter uses the model's equation error as before"
        )
    how = (
        "held out: each recording's residuals from the model refitted on the others"
        if found["speed_scaled_held_out"]
        else "in-sample: one recording fitted on; --fit-on 2 or more holds it out"
    )
    gain = found["speed_scaled_gain"]
    over = (
        ""
        if gain is None
        else f"; {gain:+.3g} nats per sample over one white level on the recordings fitted on"
    )
    return (
        f"speed-scaled equation error sigma_c {error['coloured_std']:.3g} rad at "
        f"{error['reference_speed']:g} m/s, rho {error['correlation']:.3f}, sigma_w "
        f"{error['white_std']:.3g} rad ({how}{over})"
    )

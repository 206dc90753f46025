"""One check that data and estimator share a sample time (recordings, envs, the replay tool).

A steering model's ARX coefficients belong to one sample time Ts: they
relate delta(k) to delta(k-1), u(k-1), ... one Ts apart. An estimator fed
rows 0.1 s apart with a model of Ts = 0.01 s would read ten samples of the
driver's dynamics as one and can end up confidently wrong. The rows of a
hasa recording or env are one env step apart::

    step = action_repeat / sim_frequency      (s)

(or, without a config, the median spacing of the ``time`` column), and the
check demands

    step = estimator.dt = Ts of the estimator's steering model

(relative tolerance 1e-6), raising a :class:`ValueError` that names both
rates and what to do otherwise. The env's IMU averages over the whole env
step (:mod:`hasa_env.envs.lane_keeping`), so ``action_repeat > 1`` is fine with a
model of that step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["check_sample_time", "config_sample_time", "recording_sample_time"]

_RELATIVE_TOLERANCE = 1e-6


def config_sample_time(config: Mapping[str, Any]) -> tuple[float, float, int]:
    """(env step (s), sim_frequency (Hz), action_repeat) of an env config."""
    frequency = float(config["sim_frequency"])
    repeat = int(config.get("action_repeat", 1))
    return repeat / frequency, frequency, repeat


def recording_sample_time(frame: pd.DataFrame) -> tuple[float, float | None, int | None] | None:
    """(row spacing (s), sim_frequency (Hz) or None, action_repeat or None) of a recording.

    From ``frame.attrs["config"]`` (action_repeat / sim_frequency) when it
    has one, else the median difference of the ``time`` column; None when
    neither tells (no config, fewer than two finite times).
    """
    config = frame.attrs.get("config") if hasattr(frame, "attrs") else None
    if isinstance(config, Mapping) and "sim_frequency" in config:
        return config_sample_time(config)
    if "time" not in frame.columns:
        return None
    time = frame["time"].to_numpy(dtype=np.float64)
    spacing = np.diff(time[np.isfinite(time)])
    if spacing.size == 0:
        return None
    return float(np.median(spacing)), None, None


def _same(a: float, b: float) -> bool:
    return abs(a - b) <= _RELATIVE_TOLERANCE * max(abs(a), abs(b))


def check_sample_time(
    estimator: Any,
    step: float,
    *,
    source: str = "the recording",
    sim_frequency: float | None = None,
    action_repeat: int | None = None,
) -> None:
    """Raise ValueError unless data sampled every ``step`` s suit ``estimator``.

    The data's step must equal the Ts of the estimator's steering model
    (``estimator.steering_model.dt``, when it has one) and the estimator's
    own ``dt`` (an estimator without these attributes is not checked on them).

    Args:
        estimator: the estimator (e.g. :class:`estimators.gm_ekf.GaussianMixtureEKF`).
        step: time between two rows of the data (s).
        source: what the data are, for the message ("the recording", "the env").
        sim_frequency, action_repeat: the data's simulation rate (Hz) and
            samples per row, when known (named in the message).
    """
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"{source} has no positive sample time (got {step!r} s between rows)")
    rates = f"{source} is sampled every {step:g} s"
    if sim_frequency is not None and action_repeat is not None:
        rates += f" (sim_frequency {sim_frequency:g} Hz, action_repeat {action_repeat})"
    model = getattr(estimator, "steering_model", None)
    model_dt = getattr(model, "dt", None)
    if model_dt is not None and not _same(step, model_dt):
        advice = f"use a steering model fitted on data sampled every {step:g} s"
        if sim_frequency is not None:
            repeat = model_dt * sim_frequency
            if repeat >= 1 and _same(repeat, round(repeat)):
                advice = (
                    f"record (or run the env) with action_repeat {round(repeat)} so that rows are "
                    f"{model_dt:g} s apart, or {advice}"
                )
        raise ValueError(
            f"{rates} but the estimator's model belongs to Ts = {model_dt:g} s: the sample "
            f"times must agree; {advice} (and build the estimator with dt equal to it)"
        )
    dt = getattr(estimator, "dt", None)
    if dt is not None and not _same(step, dt):
        raise ValueError(
            f"{rates} but the estimator steps with dt = {dt:g} s: the sample times must agree; "
            f"build the estimator with dt={step:g}"
            + (" (its steering model's Ts)" if model_dt is not None else "")
        )

"""What ``hasa-replay --estimator`` says of the estimator on one recording: the phrase of its
line and the verdict its JSON carries (issue 25: how much of the time the participant's
steering counted as lane evidence, and whether the reported std covers the error)."""

from __future__ import annotations

import math
from typing import Any

from estimators.calibration import STEERING_CHANNEL_STATES, steering_channel_shares
from estimators.offline import EstimatorRun

__all__ = ["describe_estimate", "estimate_verdict"]


def estimate_verdict(run: EstimatorRun) -> dict[str, Any]:
    """``steering``: the share of the recording's time per state of the steering channel
    (:data:`~estimators.calibration.STEERING_CHANNEL_STATES`: ``live`` when it counted as lane
    evidence at half its weight or more; None each when the filter has no steering channel),
    and ``lateral_nees`` (1: the reported lateral std is right on average); None each when
    the run kept no result."""
    if run.result is None:
        return {"steering": None, "lateral_nees": None}
    shares = steering_channel_shares(run.result)
    of_run = {name: float(shares[name][0]) for name in STEERING_CHANNEL_STATES}
    steering = None if all(math.isnan(v) for v in of_run.values()) else of_run
    nees = float(run.result.lateral_nees()[0])
    return {"steering": steering, "lateral_nees": nees if math.isfinite(nees) else None}


def describe_estimate(run: EstimatorRun) -> str:
    """The estimator's result in one phrase: lateral RMSE, final weights, when trusted, how
    it ended, how much of the time the steering counted and the lateral NEES."""
    hyp = ", ".join(
        f"{b:+g} m: {w:.3f}" for b, w in zip(run.hypotheses, run.weights[-1], strict=True)
    )
    trusted = "never" if math.isnan(run.trusted_from) else f"{run.trusted_from:.2f} s"
    decision = run.final_decision + (f" ({run.refused_by})" if run.refused_by else "")
    text = (
        f"lateral RMSE {run.lateral_rmse:.3f} m, final weights [{hyp}], "
        f"true lane trusted (> 0.9) from {trusted}, ends {decision}"
    )
    verdict = estimate_verdict(run)
    steering = verdict["steering"]
    if steering is not None:
        tempered = steering["tempered_model_error"] + steering["tempered_autocorrelation"]
        text += (
            f"; steering live {steering['live']:.0%} of the time (off {steering['off']:.0%}, "
            f"unused {steering['unused']:.0%}, tempered {tempered:.0%}, "
            f"in mismatch {steering['mismatch']:.0%})"
        )
    if verdict["lateral_nees"] is not None:
        text += f"; lateral NEES {verdict['lateral_nees']:.2f}"
    return text

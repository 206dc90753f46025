"""Human steering models: visual features, the ARX description, models, fitting.

- :mod:`~hasa_env.steering.features`: near/far-point bearings and the
  features of a recorded run (:func:`steering_features`).
- :mod:`~hasa_env.steering.base`: the :class:`SteeringModel` interface every
  model implements (how to write your own is in its docstring).
- :mod:`~hasa_env.steering.models`: :class:`TwoPointModel` and
  :class:`GeneralizedModel` with the paper's presets.
- :mod:`~hasa_env.steering.fitting`: least squares with standard errors,
  BIC order search, residual diagnostics, the identifiability check, scores.
- :mod:`~hasa_env.steering.arx`: :class:`ARXForm`, what the estimator builds on.
"""

from importlib import import_module
from typing import Any

from hasa_env.steering.arx import ARXForm

# Everything but ARXForm is loaded on first use: the fitting module pulls in
# scipy.signal and statsmodels, which code that only needs ARXForm (the
# estimators) should not pay for at import.
_LAZY = {
    **dict.fromkeys(("Design", "ModelFileError", "Regressor", "SteeringModel", "lagged"), "base"),
    **dict.fromkeys(("near_far_bearings", "steering_features"), "features"),
    **dict.fromkeys(
        (
            "FitResult",
            "IdentifiabilityReport",
            "IdentifiabilityWarning",
            "OrderSelection",
            "ResidualDiagnostics",
            "check_identifiability",
            "residual_diagnostics",
            "score",
            "score_runs",
            "select_order",
        ),
        "fitting",
    ),
    **dict.fromkeys(("GeneralizedModel", "TwoPointModel"), "models"),
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hasa_env.steering' has no attribute {name!r}")
    return getattr(import_module(f"hasa_env.steering.{module}"), name)


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "ARXForm",
    "Design",
    "FitResult",
    "GeneralizedModel",
    "IdentifiabilityReport",
    "IdentifiabilityWarning",
    "ModelFileError",
    "OrderSelection",
    "Regressor",
    "ResidualDiagnostics",
    "SteeringModel",
    "TwoPointModel",
    "check_identifiability",
    "lagged",
    "near_far_bearings",
    "residual_diagnostics",
    "score",
    "score_runs",
    "select_order",
    "steering_features",
]

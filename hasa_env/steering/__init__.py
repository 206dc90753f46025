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

from hasa_env.steering.arx import ARXForm
from hasa_env.steering.base import (
    Design,
    ModelFileError,
    Regressor,
    SteeringModel,
    lagged,
)
from hasa_env.steering.features import near_far_bearings, steering_features
from hasa_env.steering.fitting import (
    FitResult,
    IdentifiabilityReport,
    IdentifiabilityWarning,
    OrderSelection,
    ResidualDiagnostics,
    check_identifiability,
    residual_diagnostics,
    score,
    score_runs,
    select_order,
)
from hasa_env.steering.models import GeneralizedModel, TwoPointModel

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

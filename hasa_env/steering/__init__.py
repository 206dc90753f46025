"""Human steering models: visual features, the ARX description, models, fitting.

- :mod:`~hasa_env.steering.features`: near/far-point bearings and the
  features of a recorded run (:func:`steering_features`).
- :mod:`~hasa_env.steering.design`: :class:`Regressor`, :class:`Design`,
  :func:`lagged`: the pieces a model's equation is written in.
- :mod:`~hasa_env.steering.base`: the :class:`SteeringModel` interface every
  model implements (how to write your own is in its docstring).
- :mod:`~hasa_env.steering.models`: :class:`TwoPointModel` and
  :class:`GeneralizedModel` with the paper's presets, and :class:`RoadBlindModel`,
  the road-blind AR baseline.
- :mod:`~hasa_env.steering.fitting`: fitting a model, with the fit's checks;
- :mod:`~hasa_env.steering.regression`: least squares and ridge regression
  with standard errors, the penalty by blocked cross-validation;
- :mod:`~hasa_env.steering.identifiability`: can the model tell lanes apart,
  is it stable;
- :mod:`~hasa_env.steering.scoring`: scores (road information among them) and residual
  diagnostics.
- :mod:`~hasa_env.steering.order`: BIC order selection.
- :mod:`~hasa_env.steering.model_file`: the JSON model files.
- :mod:`~hasa_env.steering.arx`: :class:`ARXForm`, what the estimator builds on.
"""

from hasa_env._lazy import lazy_attributes
from hasa_env.steering.arx import ARXForm

__all__ = [
    "ARXForm",
    "Design",
    "FitChecks",
    "FitResult",
    "GeneralizedModel",
    "IdentifiabilityReport",
    "IdentifiabilityWarning",
    "ModelFileError",
    "OrderSelection",
    "Regressor",
    "ResidualDiagnostics",
    "RoadBlindModel",
    "StabilityWarning",
    "SteeringFitWarning",
    "SteeringModel",
    "TwoPointModel",
    "ar_poles",
    "check_identifiability",
    "fit_model",
    "lagged",
    "ljung_box",
    "near_far_bearings",
    "residual_diagnostics",
    "road_information",
    "score",
    "score_features",
    "score_runs",
    "select_order",
    "steering_features",
]

# Everything but ARXForm loads on first use: the model and fitting modules pull
# in pandas, scipy.signal and statsmodels (~1 s), which code that only needs
# ARXForm (an estimator filtering with a model) should not pay for at import.
_SUBMODULES = {
    "design": ("Design", "Regressor", "lagged"),
    "model_file": ("ModelFileError",),
    "features": ("near_far_bearings", "steering_features"),
    "fitting": ("FitChecks", "FitResult", "fit_model"),
    "identifiability": (
        "IdentifiabilityReport",
        "IdentifiabilityWarning",
        "StabilityWarning",
        "SteeringFitWarning",
        "ar_poles",
        "ar_poles",
        "check_identifiability",
        "fit_model",
    ),
    "scoring": (
        "ResidualDiagnostics",
        "ljung_box",
        "residual_diagnostics",
        "road_information",
        "score",
        "score_features",
        "score_runs",
    ),
    "order": ("OrderSelection", "select_order"),
    # SteeringModel (defined in base) through models, which registers the built-in types, so
    # that SteeringModel.load reads their files whatever else was imported.
    "models": ("GeneralizedModel", "RoadBlindModel", "SteeringModel", "TwoPointModel"),
}
__getattr__, __dir__ = lazy_attributes(
    __name__,
    {name: f"{__name__}.{module}" for module, names in _SUBMODULES.items() for name in names},
    eager=["ARXForm"],
)

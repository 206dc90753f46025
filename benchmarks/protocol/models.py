"""The steering models a benchmark scores: user-model loading, fitting on the training run."""

from __future__ import annotations

import copy
import math
import pickle
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import pandas as pd

from benchmarks.protocol.config import BASELINES, BUILTIN_MODELS, BenchmarkError
from estimators.tuning import steering_residual_std
from hasa_env.steering import GeneralizedModel, SteeringFitWarning, SteeringModel, TwoPointModel
from hasa_env.steering.features import steering_features
from hasa_env.steering.loading import (
    ModelLoadError,
    describe_exception,
    import_model,
    load_model,
    model_spec_kind,
)
from hasa_env.steering.model_file import ModelFileError

__all__ = [
    "Candidate",
    "FittedModel",
    "ModelError",
    "describe",
    "fit_models",
    "load_models",
    "load_user_model",
]


class ModelError(Exception):
    """A user model failed; the message names the model and what went wrong.

    Attributes:
        model: the model's name (or its import path if it never loaded).
        stage: "import", "interface", "fit", "predict" or "estimate".
        detail: what went wrong.
    """

    def __init__(self, model: str, stage: str, detail: str) -> None:
        self.model = model
        self.stage = stage
        self.detail = detail
        super().__init__(f"model {model!r} failed ({stage}): {detail}")

    def __reduce__(self) -> tuple[Any, tuple[str, str, str]]:
        # picklable, so it can come back from a worker process
        return (type(self), (self.model, self.stage, self.detail))

    def to_dict(self) -> dict[str, str]:
        return {"model": self.model, "stage": self.stage, "message": str(self)}


def load_user_model(spec: str) -> Any:
    """The steering model a user names: ``"package.module:Name"`` or a saved model file.

    ``Name`` may be a :class:`hasa_env.steering.SteeringModel` subclass
    (instantiated without arguments), an instance of one, or a function
    returning one; a model file (``model.save("m.json")``, any registered
    type, user types included) gives a fitted model
    (:func:`hasa_env.steering.loading.load_model`). A model whose
    ``regressors`` and ``design()`` disagree is refused.

    Raises:
        ModelError: naming ``spec``, with stage "import" (module or attribute
            not found, or the module raised; a model file that cannot be
            read) or "interface" (not a steering model, or its regressors
            and design disagree).
    """
    try:
        kind = model_spec_kind(spec) if isinstance(spec, str) else "import"
        if kind == "preset":
            raise ModelLoadError(
                spec, "import", "the paper's presets are the built-in models already; name a "
                "user model ('package.module:ClassName' or a saved model file)"
            )  # fmt: skip
        return load_model(spec) if kind == "file" else _checked(import_model(spec), spec)
    except ModelLoadError as exc:
        raise ModelError(str(spec), exc.stage, exc.detail) from None
    except ModelFileError as exc:
        raise ModelError(str(spec), "import", str(exc)) from None


def _checked(model: Any, spec: str) -> Any:
    try:
        model.check_regressors()
    except ValueError as exc:
        raise ModelLoadError(spec, "interface", str(exc)) from None
    return model


describe = describe_exception
"""``Type: message (at file:line in function)`` of an exception (its innermost frame)."""


@dataclass(frozen=True)
class FittedModel:
    """A fitted model as the tasks receive it.

    Attributes:
        name: the name in the results; kind: "builtin" or "user";
        model: the fitted :class:`SteeringModel`; residual_std: its one-step
        residual level on the training run for the filter (rad; None: no
        ARX form, no estimation).
    """

    name: str
    kind: str
    model: Any
    residual_std: float | None


@dataclass(frozen=True)
class Candidate:
    """A model to fit on each seed's training run: unfitted, loaded once.

    Attributes:
        name: the name in the results; kind: "builtin" or "user";
        spec: the user's import path or model file (None for built-ins);
        model: the model, unfitted unless ``fixed``;
        fixed: a saved model file's fitted model, scored with its own parameters
            (not refitted on the training run).
    """

    name: str
    kind: str
    spec: str | None
    model: Any
    fixed: bool = False


def load_models(user_specs: Sequence[str], errors: list[ModelError]) -> list[Candidate]:
    """The built-in models and every user model that loads (failures go to ``errors``).

    Done before any run is generated, so a model that does not import costs
    nothing and is reported at once.
    """
    candidates = [
        Candidate("two_point", "builtin", None, TwoPointModel()),
        Candidate("generalized", "builtin", None, GeneralizedModel()),
    ]
    used = set(BUILTIN_MODELS) | set(BASELINES)
    for spec in user_specs:
        try:
            model = load_user_model(spec)
        except ModelError as exc:
            errors.append(exc)
            continue
        name = str(getattr(model, "name", "") or spec)
        if name in used:
            name = spec if spec not in used else f"{spec}#{len(used)}"
        used.add(name)
        fixed = model_spec_kind(spec) == "file" and model.is_fitted
        candidates.append(Candidate(name, "user", spec, model, fixed))
    return candidates


def fit_models(
    train: pd.DataFrame,
    candidates: Sequence[Candidate],
    errors: list[ModelError],
    *,
    seed: int | None = None,
    sensor_std: float = 0.0,
) -> tuple[list[FittedModel], list[dict[str, Any]]]:
    """Fit every candidate on one training run (a seed's); the fitted models and their
    descriptions (parameters, training statistics, the fit's checks)."""
    dt = steering_features(train).attrs.get("dt", 0.01)
    fitted: list[FittedModel] = []
    infos: list[dict[str, Any]] = []
    for candidate in candidates:
        name, kind = candidate.name, candidate.kind
        info: dict[str, Any] = {"name": name, "kind": kind, "spec": candidate.spec, "seed": seed}
        model = copy.deepcopy(candidate.model)
        if kind == "builtin" and abs(model.dt - dt) > 1e-12:
            model = type(model)(**model.structure(), **(model.common_kwargs() | {"dt": dt}))
        try:
            model_fitted, info_fit = _fit_one(name, model, train, sensor_std, candidate.fixed)
        except ModelError as exc:
            if kind == "builtin":
                raise BenchmarkError(f"the built-in {exc}") from None
            errors.append(exc)
            info["error"] = str(exc)
            infos.append(info)
            continue
        info.update(info_fit)
        info["error"] = None
        fitted.append(FittedModel(name, kind, model_fitted, info_fit["filter_residual_std"]))
        infos.append(info)
    return fitted, infos


def _fit_one(
    name: str, model: Any, train: pd.DataFrame, sensor_std: float, fixed: bool = False
) -> tuple[Any, dict[str, Any]]:
    """Fit one model on the training run (a ``fixed`` one keeps its parameters); its
    description; ModelError if it fails."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SteeringFitWarning)
        try:
            if fixed:
                fitted = model
            elif type(model).fit is SteeringModel.fit:  # the project's fit: ridge + checks
                fitted = model.fit(train, sensor_std=sensor_std)
            else:
                fitted = model.fit(train)
        except Exception as exc:  # noqa: BLE001 - a user model may raise anything
            raise ModelError(name, "fit", f"fit() raised {describe(exc)}") from None
    if not isinstance(fitted, SteeringModel):
        raise ModelError(
            name, "fit", f"fit() returned {type(fitted).__name__}, expected a fitted SteeringModel"
        )
    if not fitted.is_fitted:
        raise ModelError(name, "fit", "fit() returned a model without parameters")
    try:
        pickle.dumps(fitted)
    except Exception as exc:  # noqa: BLE001
        raise ModelError(
            name, "fit", f"the fitted model cannot be pickled for the workers: {describe(exc)}"
        ) from None
    fitted.name = name
    result = fitted.fit_result
    info: dict[str, Any] = {
        "model_type": getattr(fitted, "model_type", ""),
        "parameters": fitted.parameters,
        "standard_errors": fitted.standard_errors,
        "training": None,
        "identifiability": None,
        "checks": None,
        "warnings": [str(w.message) for w in caught if issubclass(w.category, UserWarning)],
        "refitted": not fixed,
    }
    if result is not None:
        info["training"] = {
            "n_obs": result.n_obs,
            "residual_std": result.residual_std,
            "r2": result.r2,
            "r2_increments": result.r2_increments,
            "bic": result.bic,
        }
        checks = getattr(result, "checks", None)
        if checks is not None:
            info["checks"] = checks.to_dict()
        if result.identifiability is not None:
            info["identifiability"] = {
                "static_lane_gain": result.identifiability.static_lane_gain,
                "identifiable": result.identifiability.ok,
                "message": result.identifiability.message,
            }
    try:
        arx = fitted.arx()
    except Exception as exc:  # noqa: BLE001
        raise ModelError(name, "fit", f"arx() raised {describe(exc)}") from None
    residual = None
    if arx is not None:
        try:
            residual = steering_residual_std(arx, train, decision_lag=fitted.decision_lag)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(
                name, "fit", f"its ARX form cannot predict the training run: {describe(exc)}"
            ) from None
        if not (math.isfinite(residual) and residual >= 0):
            raise ModelError(name, "fit", f"its ARX form predicts non-finite steering ({residual})")
    info["arx"] = arx is not None
    info["filter_residual_std"] = residual
    notes = []
    if fixed:
        notes.append(
            "a saved model file: scored with the parameters of its file, not refitted on the "
            "training run"
        )
    if arx is None:
        notes.append(
            "not an ARX model (its arx() returns None): scored on steering prediction only, so "
            "it has no rows in the lateral-estimation table (paper table 2): the "
            "Gaussian-mixture EKF builds its state from the model's ARX form; implement arx() "
            "(README 'Write a steering model') to have it estimated"
        )
    if notes:
        info["note"] = "; ".join(notes)
    return fitted, info

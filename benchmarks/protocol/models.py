"""The steering models a benchmark scores: user-model loading, fitting on the training run,
and the isolation of user code.

Isolation of user code: :mod:`benchmarks.protocol.isolation` (:func:`run_isolated`).
"""

from __future__ import annotations

import copy
import math
import pickle
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import pandas as pd

from benchmarks.protocol.builtin_fit import builtin_generalized
from benchmarks.protocol.config import (
    BASELINES,
    BUILTIN_MODELS,
    DEFAULT_MODEL_TIME_LIMIT,
    STEERING_BASELINE,
    BenchmarkError,
)
from benchmarks.protocol.isolation import (
    DEFAULT_MODEL_MEMORY_LIMIT,
    ModelError,
    describe,
    guarded_in_time,
    run_isolated,
)
from benchmarks.speed_scaled import (
    add_speed_scaled_error,
    fits_speed_scaled_error,
    speed_scaled_description,
)
from benchmarks.stress import STRESS_MODELS, stress_models
from estimators.trust import TrainingRecord, model_limits, trusted_filter
from estimators.tuning import (
    PredictionCheck,
    steering_residuals_by_speed,
)
from hasa_env.drivers import SpeedProfile, lane_keeping_checks
from hasa_env.steering import (
    GeneralizedModel,
    RoadBlindModel,
    SteeringFitWarning,
    SteeringModel,
    TwoPointModel,
)
from hasa_env.steering.features import steering_features
from hasa_env.steering.loading import (
    ModelLoadError,
    import_model,
    load_model,
    model_spec_kind,
)
from hasa_env.steering.model_file import ModelFileError

__all__ = [
    "DEFAULT_MODEL_MEMORY_LIMIT",
    "DEFAULT_MODEL_TIME_LIMIT",
    "Candidate",
    "FittedModel",
    "ModelError",
    "check_lane_keeping",
    "describe_trust",
    "describe",
    "fit_models",
    "load_models",
    "load_user_model",
    "private_copy",
    "run_isolated",
]


def load_user_model(spec: str, trust_module: bool = False) -> SteeringModel:
    """The steering model a user names: ``"package.module:Name"`` or a saved model file.

    ``Name`` may be a :class:`hasa_env.steering.SteeringModel` subclass
    (instantiated without arguments), an instance of one, or a function
    returning one; a model file (``model.save("m.json")``, any registered
    type, user types included) gives a fitted model
    (:func:`hasa_env.steering.loading.load_model`; with ``trust_module`` a file
    of a type not registered yet imports the module its ``"class"`` names). A model
    whose ``regressors`` and ``design()`` disagree is refused.

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
        if kind == "file":
            return load_model(spec, trust_module=trust_module)
        return _checked(import_model(spec), spec)
    except ModelLoadError as exc:
        raise ModelError(str(spec), exc.stage, exc.detail) from None
    except ModelFileError as exc:
        raise ModelError(str(spec), "import", str(exc)) from None


def _checked(model: SteeringModel, spec: str) -> SteeringModel:
    try:
        model.check_regressors()
    except ValueError as exc:
        raise ModelLoadError(spec, "interface", str(exc)) from None
    return model


def private_copy(frame: pd.DataFrame) -> pd.DataFrame:
    """A deep copy of a run frame (values and ``attrs``) for one model to do with as it likes."""
    out = frame.copy(deep=True)
    out.attrs = copy.deepcopy(frame.attrs)
    return out


@dataclass(frozen=True)
class FittedModel:
    """A fitted model as the tasks receive it.

    Attributes:
        name: the name in the results; kind: "builtin" or "user";
        model: the fitted :class:`SteeringModel`; residual_std: its one-step
        residual level on the training run for the filter (rad; None: no
        ARX form, no estimation); training: what the filter's rule
        (:func:`estimators.trust.trusted_filter`) needs beyond the model's own record:
        for a model the benchmark fitted, its training run's road curvatures and speeds
        (:meth:`~estimators.trust.TrainingRecord.from_run`; none for a saved model), and
        the outcome of its lane-keeping check (:func:`check_lane_keeping`): with the
        evidence checks on, a model that fails it gets the no-steering estimator.
    """

    name: str
    kind: str
    model: Any
    residual_std: float | None
    training: TrainingRecord = TrainingRecord()


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


def _check_user_model(spec: str, trust_module: bool = False) -> str:
    """Import and create the model (in a child process when isolated); its class name."""
    model = load_user_model(spec, trust_module)
    try:
        pickle.dumps(model)
    except Exception as exc:  # noqa: BLE001
        raise ModelError(
            spec, "interface", f"the model cannot be pickled for the workers: {describe(exc)}"
        ) from None
    return type(model).__qualname__


def load_models(
    user_specs: Sequence[str],
    errors: list[ModelError],
    *,
    time_limit: float | None = DEFAULT_MODEL_TIME_LIMIT,
    stress: bool = False,
    trust_module: bool = False,
) -> list[Candidate]:
    """The built-in models, every user model that loads (failures go to ``errors``)
    and, with ``stress``, the stress set (:mod:`benchmarks.stress`, kind "stress").

    Done before any run is generated, so a model that does not import costs
    nothing and is reported at once. With a ``time_limit`` each user model is
    first imported and created in a child process (:func:`run_isolated`), so
    a module that hangs, exits or crashes while importing is reported, not
    fatal; only then is it imported here (the model object is needed here), stopped by
    an alarm after ``time_limit`` too (:func:`benchmarks.protocol.isolation.guarded_in_time`). With
    ``trust_module`` a model file may import the module its ``"class"`` names
    (:func:`hasa_env.steering.loading.load_model_file`).
    """
    candidates = [
        Candidate("two_point", "builtin", None, TwoPointModel()),
        Candidate("generalized", "builtin", None, GeneralizedModel()),
        Candidate(
            STEERING_BASELINE,
            "baseline",
            None,
            RoadBlindModel(name=STEERING_BASELINE),
        ),
    ]
    if stress:
        candidates += [Candidate(name, "stress", None, model) for name, model in stress_models()]
    used = set(BUILTIN_MODELS) | set(BASELINES) | set(STRESS_MODELS) | {STEERING_BASELINE}
    for spec in user_specs:
        try:
            if time_limit is not None:
                run_isolated(
                    _check_user_model, (spec, trust_module), model=str(spec), stage="import",
                    time_limit=time_limit,
                )  # fmt: skip
            model = guarded_in_time(
                load_user_model, (spec, trust_module), str(spec), "import", time_limit
            )
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
    train: pd.DataFrame | Sequence[pd.DataFrame],
    candidates: Sequence[Candidate],
    errors: list[ModelError],
    *,
    seed: int | None = None,
    sensor_std: float = 0.0,
    constant_speed_train: pd.DataFrame | None = None,
    time_limit: float | None = DEFAULT_MODEL_TIME_LIMIT,
    generalized_orders: str = "paper",
    equation_error_order: int = 0,
    speed_scaled_error: bool = False,
) -> tuple[list[FittedModel], list[dict[str, Any]]]:
    """Fit every candidate on the training run (a seed's; or several runs, each a run of its
    own for the fit: lags never cross between them); the fitted models and their
    descriptions (parameters, training statistics, the fit's checks).

    A stress model that trains on a constant-speed run (``training =
    "constant_speed"``) gets ``constant_speed_train``; its filter's residual
    level still comes from ``train``. A user model gets its own copy of the
    training run and is fitted isolated with ``time_limit`` (:func:`run_isolated`).
    ``generalized_orders`` (:data:`~benchmarks.defaults.GENERALIZED_ORDERS`): ``"bic"``
    selects the built-in generalized model's orders on ``train`` first
    (:func:`~benchmarks.protocol.builtin_fit.with_selected_orders`); ``"paper"`` keeps the candidate's. The built-in
    generalized model's fit estimates an ``equation_error_order``-lag autoregression of its
    equation error (0: white; docs/design.md §8.32); with ``speed_scaled_error`` its error's
    speed-scaled coloured part is fitted on ``train`` too, and its filter carries it as a state
    instead (docs/design.md §8.34); so is a user's :class:`GeneralizedModel` itself (not a
    subclass, not a saved file), as ``hasa-replay --fit`` fits it."""
    runs = [train] if isinstance(train, pd.DataFrame) else list(train)
    train = train if isinstance(train, pd.DataFrame) else runs  # a list: what the fit takes
    dt = steering_features(runs[0]).attrs.get("dt", 0.01)
    fitted: list[FittedModel] = []
    infos: list[dict[str, Any]] = []
    for candidate in candidates:
        name, kind = candidate.name, candidate.kind
        info: dict[str, Any] = {"name": name, "kind": kind, "spec": candidate.spec, "seed": seed}
        model = copy.deepcopy(candidate.model)
        if kind in ("builtin", "baseline") and abs(model.dt - dt) > 1e-12:
            model = type(model)(**model.structure(), **(model.common_kwargs() | {"dt": dt}))
        own: pd.DataFrame | list[pd.DataFrame] = train
        if kind == "builtin" and isinstance(model, GeneralizedModel):
            model = builtin_generalized(
                model, train, generalized_orders, equation_error_order, info
            )
        if getattr(model, "training", "") == "constant_speed":
            if constant_speed_train is None:
                raise BenchmarkError(f"stress model {name!r} needs a constant-speed training run")
            own = constant_speed_train
        try:
            if kind != "user":
                model_fitted, info_fit = _fit_one(
                    name, model, own, sensor_std, candidate.fixed, residual_on=train
                )
            else:
                mine = (
                    private_copy(train)
                    if isinstance(train, pd.DataFrame)
                    else [private_copy(r) for r in runs]
                )
                model_fitted, info_fit = run_isolated(
                    _fit_one, (name, model, mine, sensor_std, candidate.fixed),
                    model=name, stage="fit", time_limit=time_limit,
                )  # fmt: skip
        except ModelError as exc:
            if kind in ("builtin", "stress", "baseline"):
                raise BenchmarkError(f"the built-in {exc}") from None
            errors.append(exc)
            info["error"] = str(exc)
            infos.append(info)
            continue
        if speed_scaled_error and _gets_speed_scaled_error(candidate, model):
            add_speed_scaled_error(model, model_fitted, runs, sensor_std, info_fit)
        info.update(info_fit)
        info["error"] = None
        # the road-blind baseline is a steering reference only: it has no lane information
        residual = None if kind == "baseline" else info_fit["filter_residual_std"]
        # trusted on roads and at speeds like those it was fitted on: its own record (fit,
        # model file), else the training run's for a model the benchmark fitted
        training = _training_record(candidate.fixed, own, info_fit, residual is not None)
        limit, speeds = model_limits(model_fitted, training)
        info["steering_curvature_limit"] = limit
        info["steering_speed_limits"] = [speeds[0], speeds[1] if math.isfinite(speeds[1]) else None]
        fitted.append(FittedModel(name, kind, model_fitted, residual, training))
        infos.append(info)
    return fitted, infos


def _gets_speed_scaled_error(candidate: Candidate, model: SteeringModel) -> bool:
    """Whether the benchmark fits ``model``'s speed-scaled equation error (docs/design.md
    §8.34): the built-in generalized model's, and a user's that the benchmark fits, by the
    rule ``hasa-replay --fit`` follows (:func:`benchmarks.speed_scaled.fits_speed_scaled_error`;
    a saved model file keeps its own)."""
    if candidate.kind == "builtin":
        return isinstance(model, GeneralizedModel)
    return candidate.kind == "user" and not candidate.fixed and fits_speed_scaled_error(model)


def _training_record(
    fixed: bool, own: pd.DataFrame | list[pd.DataFrame], info_fit: dict[str, Any], lanes: bool
) -> TrainingRecord:
    """What the trust rule knows of a fitted model's training: the roads and speeds of the
    runs it was fitted on (none for a ``fixed`` model: its own record counts), the levels its
    declarations were checked by, and (``lanes``: it gives lane evidence) its prediction check,
    made on the run it was fitted on (not a saved model's: docs/design.md §8.13.1)."""
    training = (
        TrainingRecord()
        if fixed
        else TrainingRecord.from_run(own if isinstance(own, pd.DataFrame) else pd.concat(own))
    )
    training = replace(
        training,
        whitened_residual_std=info_fit["whitened_residual_std"],
        speed_scaled_gain=info_fit["speed_scaled_gain"],
    )
    if lanes and not fixed:
        check = PredictionCheck(
            info_fit["prediction_residual_std"], info_fit["lane_free_residual_std"]
        )
        training = replace(training, prediction=check)
    return training


def _fit_one(
    name: str,
    model: Any,
    train: pd.DataFrame | list[pd.DataFrame],
    sensor_std: float,
    fixed: bool = False,
    residual_on: pd.DataFrame | list[pd.DataFrame] | None = None,
) -> tuple[Any, dict[str, Any]]:
    """Fit one model on the training run (a ``fixed`` one keeps its parameters); its
    description; ModelError if it fails. The filter's residual level is measured on
    ``residual_on`` (default ``train``)."""
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
    info = _fit_description(fitted, fixed, caught)
    has_arx, residual, prediction, whitened, by_speed, gain = _filter_residual(
        name, fitted, train if residual_on is None else residual_on
    )
    info["whitened_residual_std"] = whitened
    info["speed_scaled_gain"] = gain
    info["residual_by_speed"] = by_speed
    info["arx"] = has_arx
    info["filter_residual_std"] = residual
    info["prediction_residual_std"] = None if prediction is None else prediction.residual_std
    info["lane_free_residual_std"] = (
        None if prediction is None else prediction.lane_free_residual_std
    )
    note = _fit_note(fixed, has_arx)
    if note:
        info["note"] = note
    return fitted, info


def _fit_description(
    fitted: SteeringModel, fixed: bool, caught: Sequence[warnings.WarningMessage]
) -> dict[str, Any]:
    """A fitted model's description: type, parameters and standard errors, the training
    statistics, identifiability and checks of its fit, the fit's warnings."""
    result = fitted.fit_result
    info: dict[str, Any] = {
        "model_type": getattr(fitted, "model_type", ""),
        "structure": _structure(fitted),
        "parameters": fitted.parameters,
        "standard_errors": fitted.standard_errors,
        "training": None,
        "identifiability": None,
        "checks": None,
        "warnings": [str(w.message) for w in caught if issubclass(w.category, UserWarning)],
        "refitted": not fixed,
        "equation_error_ar": list(getattr(fitted, "equation_error_ar", ()) or ()),
        "speed_scaled_error": speed_scaled_description(fitted),
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
    return info


def _structure(fitted: SteeringModel) -> dict[str, Any] | None:
    """The model's structure (the generalized model's orders, ...) as JSON-able numbers and
    strings; None when it has none or is not of that kind (a user model's)."""
    try:
        structure = dict(fitted.structure())
    except Exception:  # noqa: BLE001 - a user model's structure() may raise anything
        return None
    plain = (int, float, str, bool, type(None))
    return structure if all(isinstance(v, plain) for v in structure.values()) else None


def _filter_residual(
    name: str, fitted: SteeringModel, run: pd.DataFrame | list[pd.DataFrame]
) -> tuple[
    bool, float | None, PredictionCheck | None, float | None, list[dict[str, Any]], float | None
]:
    """Whether the model has an ARX form, the filter's steering-residual level on ``run``
    (:func:`estimators.tuning.steering_residual_std`), the trust rule's prediction check
    there (:func:`estimators.tuning.prediction_check`), both None without ARX form, the
    level of its form whitened by its declared equation-error autoregression
    (:func:`estimators.tuning.whitened_residual_std`; None: none declared) and its residuals
    by speed (:func:`estimators.tuning.steering_residuals_by_speed`; [] without ARX form) and
    what its declared speed-scaled equation error gains over one white level
    (:func:`estimators.tuning.speed_scaled_gain`; None: none declared); ModelError if a form
    fails or predicts non-finite steering."""
    try:
        arx = fitted.arx()
    except Exception as exc:  # noqa: BLE001
        raise ModelError(name, "fit", f"arx() raised {describe(exc)}") from None
    if arx is None:
        return False, None, None, None, [], None
    try:
        measured = TrainingRecord.measured(fitted, run)  # what the library's users get
        residual, prediction = measured.residual_std, measured.prediction
        whitened, gain = measured.whitened_residual_std, measured.speed_scaled_gain
        by_speed = steering_residuals_by_speed(arx, run, decision_lag=fitted.decision_lag)
    except Exception as exc:  # noqa: BLE001
        raise ModelError(
            name, "fit", f"its ARX form cannot predict the training run: {describe(exc)}"
        ) from None
    for level in (residual, whitened):
        if level is not None and not (math.isfinite(level) and level >= 0):
            raise ModelError(name, "fit", f"its ARX form predicts non-finite steering ({level})")
    return True, residual, prediction, whitened, by_speed, gain


def _fit_note(fixed: bool, has_arx: bool) -> str:
    """What a reader of the results should know about how the model was scored ("" if nothing)."""
    notes = []
    if fixed:
        notes.append(
            "a saved model file: scored with the parameters of its file, not refitted on the "
            "training run"
        )
    if not has_arx:
        notes.append(
            "not an ARX model (its arx() returns None): scored on steering prediction only, so "
            "it has no rows in the lateral-estimation table (paper table 2): the "
            "Gaussian-mixture EKF builds its state from the model's ARX form; implement arx() "
            "(README 'Write a steering model') to have it estimated"
        )
    return "; ".join(notes)


LANE_CHECK_DURATION = 30.0
"""How long (s) the lane-keeping check drives, whatever the training run's time limit (a model
that steers away from the lane centre needs a few seconds to leave the road, one that drifts
more)."""


def _lane_keeping(
    models: list[SteeringModel],
    env_id: str,
    config: dict[str, Any],
    speed: SpeedProfile,
    seed: int,
) -> list[dict[str, Any]]:
    checks = lane_keeping_checks(models, env_id=env_id, config=config, speed=speed, seed=seed)
    return [check.to_dict() | {"summary": check.describe()} for check in checks]


def check_lane_keeping(
    fitted: Sequence[FittedModel],
    infos: Sequence[dict[str, Any]],
    *,
    env_id: str,
    config: dict[str, Any],
    speed: SpeedProfile,
    seed: int | None,
    time_limit: float | None = DEFAULT_MODEL_TIME_LIMIT,
) -> list[FittedModel]:
    """Let every fitted model with an estimator drive (:func:`hasa_env.drivers.lane_keeping_check`:
    4 cars, no equation noise, on the training run's env and config, for
    :data:`LANE_CHECK_DURATION`) and keep the outcome: in each model's description
    (``infos``, key ``lane_keeping``) and in :attr:`FittedModel.training`.

    A model that drives off the road has lane terms that do not keep a lane, so the
    estimator takes no lane evidence from it (docs/design.md §8.11). A user model's drive
    runs isolated with ``time_limit``; if it fails there (raises, hangs), it does not pass
    and the reason is kept."""
    config = dict(config) | {"time_limit": LANE_CHECK_DURATION}
    speed = replace(speed, pedal_noise=0.0)
    described = {info["name"]: info for info in infos}  # (all of this seed)
    drive_seed = 0 if seed is None else seed
    checked = [fm for fm in fitted if fm.kind != "baseline" and fm.residual_std is not None]
    outcomes: dict[str, dict[str, Any]] = {}
    ours = [fm for fm in checked if fm.kind != "user"]  # all their cars in one vector env
    if ours:
        try:
            results = _lane_keeping([fm.model for fm in ours], env_id, config, speed, drive_seed)
        except ValueError as exc:
            raise BenchmarkError(f"the lane-keeping check of the built-in models: {exc}") from None
        outcomes.update({fm.name: r for fm, r in zip(ours, results, strict=True)})
    for fm in (fm for fm in checked if fm.kind == "user"):  # each in its own process
        try:
            outcomes[fm.name] = run_isolated(
                _lane_keeping, ([fm.model], env_id, config, speed, drive_seed),
                model=fm.name, stage="lane-keeping check", time_limit=time_limit,
            )[0]  # fmt: skip
        except ModelError as exc:
            outcomes[fm.name] = {
                "passed": False, "error": str(exc), "summary": f"could not drive: {exc}"
            }  # fmt: skip
    out = []
    for fm in fitted:
        outcome = outcomes.get(fm.name)
        if outcome is None:
            out.append(fm)
            continue
        info = described.get(fm.name)
        if info is not None:
            info["lane_keeping"] = outcome
        lane = {"keeps_lane": bool(outcome["passed"]), "lane_check": outcome.get("summary", "")}
        out.append(replace(fm, training=replace(fm.training, **lane)))
    return out


def describe_trust(
    fitted: Sequence[FittedModel],
    infos: Sequence[dict[str, Any]],
    overrides: Mapping[str, Any],
) -> None:
    """Put in each estimated model's description (key ``steering_trust``) the reasons
    :func:`estimators.trust.trusted_filter` gives for every limit on its steering channel
    (with the protocol's ``filter_settings`` as the user's ``overrides``), and the filter's
    ``steering_curvature_limit`` (None: none) and ``steering_curvature_feedforward`` (None: the
    estimator uses none of the model's steering)."""
    described = {info["name"]: info for info in infos}
    for fm in fitted:
        info = described.get(fm.name)
        if fm.residual_std is None or info is None:
            continue
        training = replace(fm.training, residual_std=fm.residual_std)  # as the filter's
        trust = trusted_filter(fm.model, training=training, overrides=overrides)
        info["steering_trust"] = list(trust.reasons)
        if trust.arx is None:  # no lane evidence from its steering anywhere
            info["steering_curvature_feedforward"] = None
            continue
        limit = trust.settings.steering_curvature_limit  # the filter's (the feed-forward lifts it)
        info["steering_curvature_limit"] = limit if math.isfinite(limit) else None
        info["steering_curvature_feedforward"] = trust.settings.steering_curvature_feedforward

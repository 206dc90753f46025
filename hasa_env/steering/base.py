"""The one interface every steering model implements: :class:`SteeringModel`.

A steering model predicts the driver's road-wheel angle delta(k) (rad) from
what the driver saw: the near- and far-point bearings phi, omega (rad), the
lateral velocity v_y (m/s) and the past steering (see
:mod:`hasa_env.steering.features` for the sample alignment). Every model has

- ``name`` and ``model_type`` (the ``"type"`` of its JSON file);
- ``parameter_names`` and ``parameters`` (``None`` until fitted or given);
- ``regressors``: which features it uses at which lags
  (:class:`Regressor`, e.g. ``phi(k-1)``);
- ``predict(run)``: one-step-ahead prediction with the *measured* past
  steering (NaN where the history is too short);
- ``fit(runs)``: least squares on one or many runs, with standard errors
  (:mod:`hasa_env.steering.fitting`); returns a new, fitted model;
- ``arx()``: its :class:`~hasa_env.steering.arx.ARXForm` where it is an ARX
  model (the estimator builds on that), else ``None``;
- ``simulate(run)``: free run driven by the measured bearings, feeding back
  its own steering;
- ``to_json()`` / ``from_json()`` and ``save(path)`` / ``load(path)``, with
  validation that names the file, the field and the allowed values.

Writing your own model
----------------------
A model that is *linear in its parameters* (most are) implements four things
and inherits everything else (fitting, standard errors, scoring, JSON, free
run, driving the car through :class:`hasa_env.drivers.ModelDriver`)::

    from hasa_env.steering.base import Design, Regressor, SteeringModel, lagged

    class NearPointPD(SteeringModel):
        model_type = "near_point_pd"          # the "type" in its JSON file

        @property
        def parameter_names(self):
            return ("memory", "proportional", "derivative")

        @property
        def regressors(self):
            return (Regressor("delta", 1), Regressor("phi", 0), Regressor("phi", 1))

        def design(self, features):
            # delta(k) = offset(k) + sum_j parameter_j * column_j(k)
            delta, phi = features["delta"].to_numpy(), features["phi"].to_numpy()
            columns = np.column_stack([lagged(delta, 1), phi, phi - lagged(phi, 1)])
            return Design(target=delta, offset=np.zeros_like(delta), matrix=columns)

        def arx(self):  # optional: only if the model is an ARX model
            m, p, d = (self.parameters[n] for n in self.parameter_names)
            return ARXForm(a=(m,), b=(p + d, -d), near_distance=self.near_distance,
                           far_distance=self.far_distance, dt=self.dt)

A model with structure (orders, options) also overrides :meth:`structure`
(a JSON-able dict of its constructor's keyword arguments). A model that is
*not* linear in its parameters overrides :meth:`predict_features` and
:meth:`fit` instead of :meth:`design`. Defining the subclass registers its
``model_type`` so :meth:`SteeringModel.load` can read its files.
``examples/custom_steering_model.py`` is a complete, runnable example.

Why this module is long: it is the one class users subclass, so its docstrings are the guide to
writing a model, and its public API (features, prediction, simulation, fitting, files) is kept
in one place; the work is in :mod:`hasa_env.steering.fitting`, ``scoring`` and ``model_file``.
"""

from __future__ import annotations

import inspect
import json
import math
import os
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Self

import numpy as np
import pandas as pd

from hasa_env.files import read_bounded_text
from hasa_env.sim.road import Road
from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE, ARXForm
from hasa_env.steering.design import FEATURE_NAMES, Design, Regressor, lagged
from hasa_env.steering.equation_error import SpeedScaledError
from hasa_env.steering.features import STEERING_SIGNALS, is_feature_frame, steering_features
from hasa_env.steering.fitting import FitResult, fit_model
from hasa_env.steering.model_file import (
    MAX_MODEL_FILE_BYTES,
    MODEL_FILE_FORMAT,
    MODEL_FILE_VERSION,
    MODEL_TYPES,
    ModelFileError,
    model_from_dict,
)
from hasa_env.steering.scoring import simulate_arx

__all__ = [
    "FEATURE_NAMES",
    "MODEL_FILE_FORMAT",
    "MODEL_TYPES",
    "Design",
    "ModelDefinitionError",
    "ModelFileError",
    "Regressor",
    "SteeringModel",
    "lagged",
]


class ModelDefinitionError(ValueError):
    """A steering model whose definition contradicts itself, e.g. its ``regressors``
    do not list what its ``design()`` uses; the message names the model and the mismatch."""


_PROBE_SCALES = {"delta": 0.02, "phi": 0.05, "omega": 0.05, "lateral_velocity": 0.3}
"""Typical size of each feature (rad, m/s) in :meth:`SteeringModel.check_regressors`'s probe
frame; the others 1."""


def _rows_changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows where ``a`` and ``b`` differ (NaN equals NaN); 1-D or per row of a 2-D array."""
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    return ~same if same.ndim == 1 else ~same.all(axis=1)


def _lag_mismatches(feature: str, used: set[int], wanted: set[int]) -> list[str]:
    """What :meth:`SteeringModel.check_regressors` reports for one feature: lags the design
    uses but ``regressors`` does not list, and the reverse (a negative lag is a future sample)."""

    def show(lags: set[int]) -> str:
        return ", ".join(
            str(Regressor(feature, lag)) if lag >= 0 else f"{feature}(k+{-lag})"
            for lag in sorted(lags)
        )

    problems = []
    if used - wanted:
        problems.append(f"design() uses {show(used - wanted)}, which regressors does not list")
    if wanted - used:
        problems.append(f"regressors lists {show(wanted - used)}, which design() does not use")
    return problems


class SteeringModel(ABC):
    """Base class of all steering models (see the module docstring).

    Args:
        parameters: the parameter values, a mapping name -> value or a sequence
            in ``parameter_names`` order; ``None``: not fitted yet.
        near_distance: near-point distance (m) of the bearings phi.
        far_distance: far-point distance (m) of the bearings omega.
        dt: sample time Ts (s) the parameters belong to.
        decision_lag: samples between the bearings seen and the steering
            recorded (see :mod:`hasa_env.steering.features`).
        steering_signal: which steering a recording's features take:
            ``"measured"`` (default: ``sensor_steering``, the signal the
            estimator sees) or ``"applied"`` (the true ``steering`` column).
        name: a label (default: ``model_type``).
        standard_errors: standard errors of the parameters (same form), if known.
    """

    model_type: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if inspect.isabstract(cls):
            return
        if not cls.model_type or not isinstance(cls.model_type, str):
            raise TypeError(
                f"{cls.__name__} must set the class attribute model_type (its JSON 'type')"
            )
        previous = MODEL_TYPES.get(cls.model_type)
        if previous is not None and previous.__qualname__ != cls.__qualname__:
            raise TypeError(
                f"model_type {cls.model_type!r} of {cls.__qualname__} is already used by "
                f"{previous.__module__}.{previous.__qualname__}"
            )
        MODEL_TYPES[cls.model_type] = cls

    def __init__(
        self,
        parameters: Mapping[str, float] | Sequence[float] | np.ndarray | None = None,
        *,
        near_distance: float = NEAR_POINT_DISTANCE,
        far_distance: float = FAR_POINT_DISTANCE,
        dt: float = 0.01,
        decision_lag: int = 1,
        steering_signal: str = "measured",
        name: str | None = None,
        standard_errors: Mapping[str, float] | Sequence[float] | np.ndarray | None = None,
    ) -> None:
        for label, value in (
            ("near_distance", near_distance),
            ("far_distance", far_distance),
            ("dt", dt),
        ):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{label} must be a finite positive number, got {value!r}")
        if (
            isinstance(decision_lag, bool)
            or not isinstance(decision_lag, int | np.integer)
            or decision_lag < 0
        ):
            raise ValueError(f"decision_lag must be a non-negative integer, got {decision_lag!r}")
        if steering_signal not in STEERING_SIGNALS:
            raise ValueError(
                f"steering_signal must be one of {', '.join(map(repr, STEERING_SIGNALS))}, "
                f"got {steering_signal!r}"
            )
        self.steering_signal = steering_signal
        self.near_distance = float(near_distance)
        self.far_distance = float(far_distance)
        self.dt = float(dt)
        self.decision_lag = int(decision_lag)
        self.name = str(name) if name is not None else self.model_type
        self._parameters = self._as_vector(parameters, "parameters")
        self._standard_errors = self._as_vector(standard_errors, "standard_errors")
        self.fit_result: FitResult | None = None
        self.saved_covariance: np.ndarray | None = None
        """The parameters' covariance read from a model file (p x p, in
        :attr:`parameter_names` order); None: none was saved (see
        :attr:`parameter_covariance`)."""
        self.equation_error_ar: tuple[float, ...] = ()
        """The fitted autoregression (r_1, ..., r_p) of the model's equation error
        (:mod:`hasa_env.steering.equation_error`; set by :meth:`fit` when
        :attr:`equation_error_order` > 0, saved in the model file); ``()``: white, as the
        paper's."""
        self.equation_error_speed_scaled: SpeedScaledError | None = None
        """The equation error as a coloured part scaled by the speed plus a white part
        (:class:`hasa_env.steering.equation_error.SpeedScaledError`, docs/design.md §8.34; set
        by whoever fits it, e.g. ``hasa-bench``, saved in the model file); None: none. An
        estimator then carries the coloured part as a state instead of whitening by
        :attr:`equation_error_ar`."""
        self.training_curvature: float | None = None
        self.training_speed_range: tuple[float, float] | None = None
        """The largest |road curvature| (1/m) of the data the model was fitted on (0 for a
        straight road); None: unknown. Set by :meth:`fit`, saved in the model file; an
        estimator trusts the model's steering only on roads up to it (docs/design.md §8.11)."""

    # ------------------------------------------------------------ to implement
    @property
    @abstractmethod
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the parameters, in the order of the design matrix's columns."""

    @property
    @abstractmethod
    def regressors(self) -> tuple[Regressor, ...]:
        """The features the model uses, at which lags."""

    @abstractmethod
    def design(self, features: pd.DataFrame) -> Design:
        """The model's equation over one run of features (see :class:`Design`)."""

    def structure(self) -> dict[str, Any]:
        """Keyword arguments (JSON-able) that fix the model's structure, e.g. its orders."""
        return {}

    def arx(self) -> ARXForm | None:
        """The model as an ARX model (:class:`ARXForm`), or None if it is not one."""
        return None

    # ---------------------------------------------------------------- values
    def _as_vector(self, values: Any, label: str) -> np.ndarray | None:
        if values is None:
            return None
        names = self.parameter_names
        if isinstance(values, Mapping):
            missing = [n for n in names if n not in values]
            extra = [k for k in values if k not in names]
            if missing or extra:
                raise ValueError(
                    f"{type(self).__name__} {label}: missing {missing}, unexpected {extra}; "
                    f"expected exactly {list(names)}"
                )
            vector = np.array([float(values[n]) for n in names], dtype=np.float64)
        else:
            vector = np.asarray(values, dtype=np.float64).reshape(-1)
            if vector.size != len(names):
                raise ValueError(
                    f"{type(self).__name__} {label}: got {vector.size} values for the "
                    f"{len(names)} parameters {list(names)}"
                )
        if not np.all(np.isfinite(vector)):
            raise ValueError(f"{type(self).__name__} {label} must be finite, got {vector.tolist()}")
        vector.setflags(write=False)
        return vector

    @property
    def is_fitted(self) -> bool:
        """True once the model has parameter values."""
        return self._parameters is not None

    @property
    def parameters(self) -> dict[str, float] | None:
        """Parameter values by name, or None if the model has none yet."""
        if self._parameters is None:
            return None
        return dict(zip(self.parameter_names, self._parameters.tolist(), strict=True))

    @property
    def parameter_vector(self) -> np.ndarray:
        """Parameter values in ``parameter_names`` order (raises if not fitted)."""
        if self._parameters is None:
            raise RuntimeError(f"{self.name}: the model has no parameters yet; fit it or give them")
        return self._parameters

    @property
    def standard_errors(self) -> dict[str, float] | None:
        """Standard errors of the parameters by name (from a fit), or None."""
        if self._standard_errors is None:
            return None
        return dict(zip(self.parameter_names, self._standard_errors.tolist(), strict=True))

    @property
    def parameter_covariance(self) -> np.ndarray | None:
        """The parameters' covariance matrix (p x p, in :attr:`parameter_names` order): the
        fit's (:attr:`fit_result`), else the one read from the model file
        (:attr:`saved_covariance`); None: unknown (a preset, an older model file)."""
        result = self.fit_result
        if result is not None and tuple(result.parameter_names) == self.parameter_names:
            return np.asarray(result.covariance, dtype=np.float64)
        return self.saved_covariance

    @property
    def max_lag(self) -> int:
        """Largest lag of any regressor (samples)."""
        return max((r.lag for r in self.regressors), default=0)

    def check_regressors(self) -> None:
        """Check that :attr:`regressors` lists exactly the features and lags :meth:`design` uses.

        ``regressors`` is what the rest of the project trusts: the fit's
        identifiability checks, the estimator's memory and the model file all
        read it, so a model whose design uses other features or lags would be
        fitted and ranked on a wrong description. The check perturbs each
        feature of :data:`FEATURE_NAMES` at one sample of a synthetic features
        frame and sees which rows of the design's offset and matrix change:
        a change ``l`` rows later is a use of that feature at lag ``l``. It
        also checks that the design has one column per parameter. A model
        whose ``design`` raises ``NotImplementedError`` (one that is not
        linear in its parameters) is not checked. ``fit`` and
        :func:`hasa_env.steering.loading.load_model` call it.

        Raises:
            ModelDefinitionError: naming the model and each mismatch.
        """
        label = f"{type(self).__name__} (model_type {self.model_type!r})"
        declared: dict[str, set[int]] = {}
        for r in self.regressors:
            declared.setdefault(r.feature, set()).add(int(r.lag))
        reach = self.max_lag + 8  # uses up to this many samples beyond the declared lags show
        j = reach + 4  # the perturbed sample
        base = self._probe_frame(2 * reach + 10)

        def design_of(frame: pd.DataFrame) -> Design | None:
            try:
                return self.design(frame)
            except NotImplementedError:
                return None
            except Exception as exc:
                raise ModelDefinitionError(
                    f"{label}: design() raised {type(exc).__name__}: {exc} on a features frame "
                    f"with the columns {list(FEATURE_NAMES)}"
                ) from exc

        reference = design_of(base)
        if reference is None:
            return
        names = self.parameter_names
        if reference.matrix.shape[1] != len(names):
            raise ModelDefinitionError(
                f"{label}: design() returns {reference.matrix.shape[1]} columns for the "
                f"{len(names)} parameters {list(names)}; it needs one column per parameter, "
                "in parameter_names order"
            )

        problems = []
        for feature in FEATURE_NAMES:
            used: set[int] = set()
            for step in (0.37, -0.61):
                frame = base.copy()
                values = frame[feature].to_numpy(copy=True)
                values[j] += step * _PROBE_SCALES.get(feature, 1.0) + 1e-3
                frame[feature] = values
                other = design_of(frame)
                assert other is not None
                rows = np.flatnonzero(
                    _rows_changed(reference.offset, other.offset)
                    | _rows_changed(reference.matrix, other.matrix)
                )
                used |= {int(r) - j for r in rows}
            problems += _lag_mismatches(feature, used, declared.get(feature, set()))
        if problems:
            raise ModelDefinitionError(
                f"{label}: regressors and design() disagree: " + "; ".join(problems) + ". "
                "regressors must list exactly the features and lags design() reads (the fit's "
                "checks, the estimator and the model file rely on it)"
            )

    def _probe_frame(self, n: int) -> pd.DataFrame:
        """The synthetic features frame :meth:`check_regressors` perturbs: ``n`` rows of
        seeded noise of each feature's typical size (speed 15 +- 1 m/s), this model's attrs."""
        rng = np.random.default_rng(20240615)
        columns = {f: _PROBE_SCALES.get(f, 1.0) * rng.standard_normal(n) for f in FEATURE_NAMES}
        columns["speed"] = 15.0 + rng.standard_normal(n)
        base = pd.DataFrame(columns)
        base.attrs = {
            "near_distance": self.near_distance,
            "far_distance": self.far_distance,
            "decision_lag": self.decision_lag,
            "steering": "sensor_steering" if self.steering_signal == "measured" else "steering",
            "dt": self.dt,
        }
        return base

    @property
    def equation_error_order(self) -> int:
        """Lags of the equation error's autoregression the fit estimates (0: white, the
        paper's; a model type with the option overrides this)."""
        return 0

    def common_kwargs(self) -> dict[str, Any]:
        """Constructor keywords shared by every model (distances, dt, lag, name)."""
        return {
            "near_distance": self.near_distance,
            "far_distance": self.far_distance,
            "dt": self.dt,
            "decision_lag": self.decision_lag,
            "steering_signal": self.steering_signal,
            "name": self.name,
        }

    def with_parameters(
        self,
        parameters: Mapping[str, float] | Sequence[float] | np.ndarray,
        standard_errors: Mapping[str, float] | Sequence[float] | np.ndarray | None = None,
        fit_result: FitResult | None = None,
    ) -> Self:
        """A copy of this model (same structure and features) with new parameter values."""
        model = type(self)(
            **self.structure(),
            parameters=parameters,
            standard_errors=standard_errors,
            **self.common_kwargs(),
        )
        model.fit_result = fit_result
        return model

    # ------------------------------------------------------------ prediction
    def features(self, data: pd.DataFrame, road: Road | None = None) -> pd.DataFrame:
        """Features of one run for this model: ``data`` itself if it already holds
        features (checked against the model's distances), else
        :func:`~hasa_env.steering.features.steering_features` of the recording."""
        if not isinstance(data, pd.DataFrame):
            raise TypeError(f"expected a pandas DataFrame (one run), got {type(data).__name__}")
        if is_feature_frame(data):
            for key, mine in (
                ("near_distance", self.near_distance),
                ("far_distance", self.far_distance),
                ("decision_lag", self.decision_lag),
            ):
                theirs = data.attrs.get(key)
                if theirs is not None and float(theirs) != float(mine):
                    raise ValueError(
                        f"{self.name}: the features were computed with {key}={theirs}, "
                        f"the model uses {mine}; recompute them with steering_features"
                    )
            features = data
        else:
            features = steering_features(
                data,
                road,
                self.near_distance,
                self.far_distance,
                decision_lag=self.decision_lag,
                steering=self.steering_signal,
            )
        data_dt = features.attrs.get("dt")
        if data_dt is not None and abs(float(data_dt) - self.dt) > 1e-9 * max(1.0, self.dt):
            raise ValueError(
                f"{self.name}: the run is sampled every {data_dt:g} s but the model's "
                f"coefficients belong to Ts = {self.dt:g} s"
            )
        return features

    def predict_features(self, features: pd.DataFrame) -> np.ndarray:
        """One-step-ahead predictions from a features frame (NaN where history is short)."""
        design = self.design(features)
        theta = self.parameter_vector
        if design.matrix.shape[1] != theta.size:
            raise ValueError(
                f"{self.name}: design has {design.matrix.shape[1]} columns for "
                f"{theta.size} parameters {list(self.parameter_names)}"
            )
        out = np.full(design.target.size, np.nan)
        valid = np.isfinite(design.offset) & np.all(np.isfinite(design.matrix), axis=1)
        out[valid] = design.offset[valid] + design.matrix[valid] @ theta
        return out

    def predict(self, data: pd.DataFrame, road: Road | None = None) -> np.ndarray:
        """One-step-ahead predictions delta_hat(k) (rad) for one run.

        Uses the *measured* past steering (and the bearings seen). ``data`` is a
        recording (the features are computed with the model's distances;
        ``road`` as in :func:`~hasa_env.steering.features.steering_features`)
        or a features frame. Returns an array aligned with the run's rows, NaN
        where the history is too short.
        """
        return self.predict_features(self.features(data, road))

    def simulate(self, data: pd.DataFrame, road: Road | None = None) -> np.ndarray:
        """Free-run simulation over one run: delta(k) from the model's own past outputs.

        The bearings and lateral velocity are the measured ones (open loop); the
        measured steering is used only until the first sample the model can
        predict. Returns an array aligned with the run's rows (NaN before that
        sample). ARX models use their :meth:`arx` form; other models are run
        sample by sample through :meth:`predict_features`.
        """
        features = self.features(data, road)
        one_step = self.predict_features(features)
        finite = np.flatnonzero(np.isfinite(one_step))
        out = np.full(len(features), np.nan)
        if finite.size == 0:
            return out
        start = int(finite[0])
        arx = self.arx()
        if arx is not None:
            return simulate_arx(arx, features, start)
        delta = features["delta"].to_numpy(dtype=np.float64).copy()
        window = self.max_lag + 1
        work = features.copy()
        values = work["delta"].to_numpy(dtype=np.float64).copy()
        for k in range(start, len(features)):
            lo = max(0, k - window + 1)
            part = work.iloc[lo : k + 1].copy()
            part["delta"] = values[lo : k + 1]
            prediction = self.predict_features(part)[-1]
            values[k] = prediction if np.isfinite(prediction) else delta[k]
            out[k] = prediction
        return out

    # --------------------------------------------------------------- fitting
    def fit(
        self,
        runs: pd.DataFrame | Sequence[pd.DataFrame],
        road: Road | None = None,
        **options: Any,
    ) -> Self:
        """Fit on one or many runs; returns a new, fitted model.

        Each run is a recording (or a features frame); lags never cross from
        one run into the next. By default ridge regression with the penalty
        from blocked cross-validation on these runs; standard errors and the
        fit's checks (condition number, AR poles, stability, identifiability)
        come with the fit (``standard_errors``, ``fit_result``); an unstable or
        unidentifiable fit warns (docs/design.md §6.5). ``options``: those of
        :func:`hasa_env.steering.fitting.fit_model` (``ridge``, ``folds``,
        ``sensor_std``, ...).

        Raises:
            ModelDefinitionError: the model's regressors and design disagree
                (:meth:`check_regressors`).
        """
        self.check_regressors()
        return fit_model(self, runs, road=road, **options)  # type: ignore[return-value]

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """The model as a JSON-able dict (see :meth:`from_dict` for the fields).

        ``class`` names the model's class (``"package.module:ClassName"``) so
        that :func:`hasa_env.steering.loading.load_model_file` can import a
        user type's module when told to trust it; it is left out for a class defined in ``__main__``
        (a script), which no other program can import.
        """
        cls = type(self)
        document: dict[str, Any] = {
            "format": MODEL_FILE_FORMAT,
            "format_version": MODEL_FILE_VERSION,
            "type": self.model_type,
            "name": self.name,
            "dt": self.dt,
            "features": {
                "near_distance": self.near_distance,
                "far_distance": self.far_distance,
                "decision_lag": self.decision_lag,
                "steering_signal": self.steering_signal,
                "regressors": [str(r) for r in self.regressors],
            },
            "structure": self.structure(),
            "parameters": self.parameters,
            "standard_errors": self.standard_errors,
        }
        covariance = self.parameter_covariance if self._parameters is not None else None
        if covariance is not None and np.all(np.isfinite(covariance)):
            names = self.parameter_names
            document["parameter_covariance"] = {
                row: dict(zip(names, values, strict=True))
                for row, values in zip(names, covariance.tolist(), strict=True)
            }
        equation_error: dict[str, Any] = {}
        if self.equation_error_ar:
            equation_error["autoregression"] = list(self.equation_error_ar)
        if self.equation_error_speed_scaled is not None:
            equation_error["speed_scaled"] = self.equation_error_speed_scaled.to_dict()
        if equation_error:
            document["equation_error"] = equation_error
        training: dict[str, float] = {}
        if self.training_curvature is not None:
            training["max_abs_road_curvature"] = self.training_curvature
        if self.training_speed_range is not None:
            training["min_speed"], training["max_speed"] = self.training_speed_range
        if training:
            document["training"] = training
        if cls.__module__ != "__main__" and "<locals>" not in cls.__qualname__:
            document["class"] = f"{cls.__module__}:{cls.__qualname__}"
        return document

    def to_json(self, indent: int | None = 2) -> str:
        """The model as JSON text (floats written exactly)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], source: str = "<model>") -> SteeringModel:
        """Build a model from :meth:`to_dict`'s form, validating every field
        (:func:`hasa_env.steering.model_file.model_from_dict`).

        Raises:
            ModelFileError: naming ``source``, the field and the allowed values.
        """
        return model_from_dict(document, source, None if cls is SteeringModel else cls)

    @classmethod
    def from_json(
        cls, text: str | bytes | Mapping[str, Any], source: str = "<json>"
    ) -> SteeringModel:
        """Build a model from JSON text (or an already parsed dict); see :meth:`from_dict`."""
        if isinstance(text, Mapping):
            return cls.from_dict(text, source)
        try:
            document = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelFileError(
                f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
            ) from None
        except RecursionError:
            raise ModelFileError(f"{source}: not a model file: JSON nested too deeply") from None
        except ValueError as exc:  # an integer of more than 4300 digits
            raise ModelFileError(f"{source}: cannot be read as JSON: {str(exc)[:200]}") from None
        return cls.from_dict(document, source)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model to a JSON file."""
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(self.to_json())
            handle.write("\n")

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> SteeringModel:
        """Read a model file written by :meth:`save` (``SteeringModel.load`` reads any
        registered type; it never imports a module: :func:`hasa_env.steering.loading.load_model_file`).

        The file must be a regular file of at most ``MAX_MODEL_FILE_BYTES`` (16 MiB)."""
        source = os.fspath(path)
        try:
            text = read_bounded_text(path, "the model file", MAX_MODEL_FILE_BYTES)
        except FileNotFoundError:
            raise ModelFileError(f"{source}: no such model file") from None
        except UnicodeDecodeError as exc:
            raise ModelFileError(f"{source}: not a UTF-8 text file ({exc.reason})") from None
        except OSError as exc:  # a FIFO, a device, too large, unreadable
            raise ModelFileError(f"{source}: cannot read it: {exc.strerror or exc}") from None
        return cls.from_json(text, source)

    # ------------------------------------------------------------------ misc
    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        assert isinstance(other, SteeringModel)

        def same(x: np.ndarray | None, y: np.ndarray | None) -> bool:
            if x is None or y is None:
                return x is None and y is None
            return bool(np.array_equal(x, y))

        return (
            self.structure() == other.structure()
            and self.common_kwargs() == other.common_kwargs()
            and same(self._parameters, other._parameters)
            and same(self._standard_errors, other._standard_errors)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        params = self.parameters
        shown = (
            "not fitted" if params is None else ", ".join(f"{k}={v:.6g}" for k, v in params.items())
        )
        structure = ", ".join(f"{k}={v!r}" for k, v in self.structure().items())
        head = f"{type(self).__name__}({structure + '; ' if structure else ''}{shown}"
        return (
            f"{head}; near={self.near_distance:g} m, far={self.far_distance:g} m, Ts={self.dt:g} s)"
        )

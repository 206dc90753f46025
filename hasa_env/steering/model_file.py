"""Steering-model files: the JSON document of a model, its registry of types, its errors.

A model file (``model.save(path)``, ``SteeringModel.load(path)``) is a JSON
object with ``format`` (= ``"hasa_env.steering_model"``), ``format_version``
(1), ``type`` (a registered model type: every concrete
:class:`~hasa_env.steering.base.SteeringModel` subclass registers its
``model_type`` in :data:`MODEL_TYPES` when it is defined), ``name``, ``dt``
(s), ``features`` (near/far distances in m, decision lag, the regressors),
``structure`` (the model's keyword arguments, e.g. its orders),
``parameters``, ``standard_errors``, optionally ``parameter_covariance`` (the fit's
covariance of the parameters, row name -> column name -> value) and, optionally, ``class``
(``"package.module:ClassName"``: with ``trust_module=True``,
:func:`hasa_env.steering.loading.load_model_file` imports a user type's
module; never otherwise, since importing runs code). :func:`model_from_dict` validates every field through the shared
validator (:mod:`hasa_env.validation`) and names the file, the field and the
allowed values.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE
from hasa_env.steering.equation_error import SpeedScaledError, check_equation_error_ar
from hasa_env.validation import ABSENT, ANY_JSON, REQUIRED, Field, schema, validate, version

__all__ = [
    "MAX_MODEL_FILE_BYTES",
    "MODEL_FILE_FORMAT",
    "MODEL_FILE_VERSION",
    "MODEL_TYPES",
    "ModelFileError",
    "model_from_dict",
]

MODEL_FILE_FORMAT = "hasa_env.steering_model"
"""Value of the ``"format"`` field of a model file."""

MODEL_FILE_VERSION = 1

MAX_MODEL_FILE_BYTES = 16 * 2**20
"""Largest model file read (16 MiB; a model file is a few KB)."""

MODEL_TYPES: dict[str, type] = {}
"""Registered model types: JSON ``"type"`` -> class (filled when a subclass is defined)."""


class ModelFileError(ValueError):
    """A steering-model file or JSON document that cannot be read; the message names the field."""


_FEATURES = {
    "near_distance": Field(
        "number", NEAR_POINT_DISTANCE, "Near-point look-ahead distance.", unit="m", low=0.0,
        low_open=True,
    ),
    "far_distance": Field(
        "number", FAR_POINT_DISTANCE, "Far-point look-ahead distance.", unit="m", low=0.0,
        low_open=True,
    ),
    "decision_lag": Field("integer", 1, "Samples between a decision and its steering.", low=0),
    "steering_signal": Field(
        "choice", "measured", "The steering the model was fitted on.",
        choices=("measured", "applied"),
    ),
    "regressors": Field("strings", None, "The regressors' names (checked against the structure)."),
}  # fmt: skip
_TRAINING = {
    "max_abs_road_curvature": Field(
        "number", None, "The largest |road curvature| of the training data (null: unknown).",
        unit="1/m", low=0.0, optional=True,
    ),
    "min_speed": Field(
        "number", None, "The lowest speed of the training data (null: unknown).",
        unit="m/s", low=0.0, optional=True,
    ),
    "max_speed": Field(
        "number", None, "The highest speed of the training data (null: unknown).",
        unit="m/s", low=0.0, optional=True,
    ),
}  # fmt: skip
_SPEED_SCALED = {
    "coloured_std": Field(
        "number",
        REQUIRED,
        "Stationary std of the coloured part at the reference speed.",
        unit="rad",
        low=0.0,
    ),
    "correlation": Field(
        "number",
        REQUIRED,
        "The coloured part's correlation per sample.",
        low=0.0,
        high=1.0,
        high_open=True,
    ),
    "white_std": Field("number", REQUIRED, "Std of the white part.", unit="rad", low=0.0),
    "reference_speed": Field(
        "number",
        15.0,
        "The speed the coloured std is quoted at.",
        unit="m/s",
        low=0.0,
        low_open=True,
    ),
}
_EQUATION_ERROR = {
    "autoregression": Field(
        "numbers", (), "Its autoregression r_1 .. r_p (stationary; empty: white).",
    ),
    "speed_scaled": Field(
        "mapping", ABSENT, "A coloured part scaled by (v_ref / v)^2 plus a white part "
        "(docs/design.md §8.34; optional).", fields=_SPEED_SCALED, optional=True,
    ),
}  # fmt: skip
_PARAMETERS = Field(
    "mapping", each=Field("number"), optional=True, doc="Parameter name -> value, or null."
)
_STANDARD_ERRORS = Field(
    "mapping", None, "Parameter name -> standard error, or null.", each=Field("number", low=0.0),
    optional=True,
)  # fmt: skip

_COVARIANCE = Field(
    "mapping", None, "The fit's covariance of the parameters: row name -> column name -> value.",
    each=Field("mapping", each=Field("number")), optional=True,
)  # fmt: skip


CLASS_PATH = re.compile(r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*")
"""What the ``class`` field holds: ``package.module:ClassName``."""


def _schema(cls: str | None = None) -> Field:
    """The fields of a model file; the allowed ``type`` values are the types registered now
    (``cls``: the file's ``class`` field, named in the hint of an unregistered type)."""
    where = f" ({cls})" if cls else ""
    return schema(
        {
            "format": Field("choice", choices=(MODEL_FILE_FORMAT,)),
            "format_version": version(MODEL_FILE_VERSION, default=MODEL_FILE_VERSION),
            "class": Field(
                "string",
                None,
                "The model's class, for importing a user type's module.",
                optional=True,
                pattern=CLASS_PATH,
                pattern_doc="package.module:ClassName",
            ),  # fmt: skip
            "type": Field(
                "choice",
                choices=tuple(sorted(MODEL_TYPES)),
                hint=f"a custom model's class{where} must be defined (its module imported) "
                "before loading its file: a model file never imports code by itself "
                "(hasa_env.steering.loading.load_model_file(..., trust_module=True) and "
                "--trust-model-module import the module its 'class' field names)",
            ),
            "name": Field("string", None, "Label of the model (default: its type)."),
            "dt": Field(
                "number", doc="Sample time of the coefficients.", unit="s", low=0.0, low_open=True
            ),  # fmt: skip
            "features": Field("mapping", fields=_FEATURES),
            "structure": Field("mapping", {}, "The model's keyword arguments.", each=ANY_JSON),
            "parameters": _PARAMETERS,
            "standard_errors": _STANDARD_ERRORS,
            "parameter_covariance": _COVARIANCE,
            "training": Field(
                "mapping", {}, "What the model was fitted on (optional).", fields=_TRAINING
            ),
            "equation_error": Field(
                "mapping", {}, "The equation error's model (optional).", fields=_EQUATION_ERROR
            ),
        }
    )


def model_from_dict(
    document: Mapping[str, Any], source: str = "<model>", expected: type | None = None
) -> Any:
    """Build a model from :meth:`to_dict`'s form, validating every field.

    Fields: ``format`` (= "hasa_env.steering_model"), ``format_version``
    (1), ``type`` (a registered model type), ``name``, ``dt`` (s, > 0),
    ``features`` {``near_distance``, ``far_distance`` (m, > 0),
    ``decision_lag`` (int >= 0), ``steering_signal`` ("measured" or "applied"),
    ``regressors`` (optional; checked)},
    ``structure`` (the model's keyword arguments), ``parameters`` (name ->
    number, or null), ``standard_errors`` (same, >= 0, or null), optionally
    ``parameter_covariance`` (name -> name -> number: every parameter in each row, symmetric,
    its diagonal the squared standard errors when those are given) and, optionally,
    ``training`` {``max_abs_road_curvature`` (1/m, >= 0, or null), ``min_speed`` and
    ``max_speed`` (m/s, both or neither)}.

    Raises:
        ModelFileError: naming ``source``, the field and the allowed values.
    """

    def fail(path: str, message: str) -> ModelFileError:
        return ModelFileError(f"{source}: {message}")

    if not MODEL_TYPES:  # only hasa_env.steering.base imported: no type is defined yet
        raise ModelFileError(
            f"{source}: no steering model type is defined yet: import hasa_env.steering (the "
            "built-in models register there) or your model's module before reading a model file"
        )
    cls = document.get("class") if isinstance(document, Mapping) else None
    doc = validate(
        document,
        _schema(cls if isinstance(cls, str) else None),
        describe=lambda path: f"field '{path}'" if path else "the document",
        error=fail,
    )
    model_type = doc["type"]
    target = MODEL_TYPES[model_type]
    if expected is not None and not issubclass(target, expected):
        raise ModelFileError(
            f"{source}: field 'type' is {model_type!r} but {expected.__name__}.from_json expects "
            f"{getattr(expected, 'model_type', None)!r}; use SteeringModel.load to read any model"
        )
    features = doc["features"]
    common = {
        "near_distance": features["near_distance"],
        "far_distance": features["far_distance"],
        "dt": doc["dt"],
        "decision_lag": features["decision_lag"],
        "steering_signal": features["steering_signal"],
        "name": model_type if doc["name"] is None else doc["name"],
    }
    structure = doc["structure"]
    try:
        skeleton = target(**structure, parameters=None, standard_errors=None, **common)
    except (TypeError, ValueError) as exc:
        raise ModelFileError(
            f"{source}: field 'structure' is not valid for {model_type!r}: {exc}"
        ) from None
    names = skeleton.parameter_names
    values = {}
    for field in ("parameters", "standard_errors"):
        raw = doc[field]
        if raw is not None:
            missing = [n for n in names if n not in raw]
            extra = [k for k in raw if k not in names]
            if missing or extra:
                raise ModelFileError(
                    f"{source}: field '{field}' has "
                    f"{'missing ' + str(missing) if missing else ''}"
                    f"{' and ' if missing and extra else ''}"
                    f"{'unexpected ' + str(extra) if extra else ''}; "
                    f"allowed names for this structure: {list(names)}"
                )
            raw = {n: raw[n] for n in names}
        values[field] = raw
    if values["parameters"] is None and values["standard_errors"] is not None:
        raise ModelFileError(f"{source}: field 'standard_errors' given without 'parameters'")
    listed = features["regressors"]
    if listed is not None:
        regressors = [str(r) for r in skeleton.regressors]
        if listed != regressors:
            raise ModelFileError(
                f"{source}: field 'features.regressors' is {listed!r} but this structure uses "
                f"{regressors}"
            )
    model = target(
        **structure,
        parameters=values["parameters"],
        standard_errors=values["standard_errors"],
        **common,
    )
    model.saved_covariance = _covariance(doc["parameter_covariance"], names, values, source)
    _read_training(model, doc, source)
    return model


def _read_training(model: Any, doc: Mapping[str, Any], source: str) -> None:
    """Set what the model file says of the model's fit beyond its parameters: the training
    roads and speeds and its equation error's autoregression (ModelFileError naming the
    field)."""
    model.training_curvature = doc["training"].get("max_abs_road_curvature")
    low, high = doc["training"].get("min_speed"), doc["training"].get("max_speed")
    if (low is None) != (high is None) or (low is not None and low > high):
        raise ModelFileError(
            f"{source}: fields 'training.min_speed' and 'training.max_speed' must both be given, "
            f"with min_speed <= max_speed (got {low!r} and {high!r})"
        )
    model.training_speed_range = None if low is None else (float(low), float(high))
    try:
        model.equation_error_ar = check_equation_error_ar(doc["equation_error"]["autoregression"])
    except ValueError as exc:
        raise ModelFileError(f"{source}: field 'equation_error.autoregression': {exc}") from None
    scaled = doc["equation_error"].get("speed_scaled")
    model.equation_error_speed_scaled = None if scaled is None else SpeedScaledError(**scaled)


def _covariance(
    raw: Mapping[str, Mapping[str, float]] | None,
    names: tuple[str, ...],
    values: Mapping[str, Any],
    source: str,
) -> np.ndarray | None:
    """The ``parameter_covariance`` field as a (p, p) array in ``names`` order (None: not given),
    checked: every parameter named in every row, symmetric, a non-negative diagonal that
    matches the squared ``standard_errors`` when those are given."""
    if raw is None:
        return None
    if values["parameters"] is None:
        raise ModelFileError(f"{source}: field 'parameter_covariance' given without 'parameters'")
    if set(raw) != set(names) or any(set(row) != set(names) for row in raw.values()):
        bad = next(
            (f"row {k!r}" for k, row in raw.items() if k in names and set(row) != set(names)),
            f"rows {sorted(raw)}",
        )
        raise ModelFileError(
            f"{source}: field 'parameter_covariance' must name every parameter in every row "
            f"({list(names)}); {bad} does not"
        )
    matrix = np.array([[float(raw[r][c]) for c in names] for r in names], dtype=np.float64)
    scale = max(float(np.max(np.abs(matrix))), 1e-300)
    if not np.allclose(matrix, matrix.T, rtol=1e-9, atol=1e-12 * scale):
        raise ModelFileError(f"{source}: field 'parameter_covariance' is not symmetric")
    diagonal = np.diag(matrix)
    if np.any(diagonal < 0):
        raise ModelFileError(
            f"{source}: field 'parameter_covariance' has a negative variance on its diagonal "
            f"({names[int(np.argmin(diagonal))]!r}: {float(np.min(diagonal))!r})"
        )
    errors = values["standard_errors"]
    if errors is not None:
        expected = np.array([float(errors[n]) for n in names]) ** 2
        if not np.allclose(diagonal, expected, rtol=1e-6, atol=1e-300):
            raise ModelFileError(
                f"{source}: field 'parameter_covariance' has a diagonal that is not the squared "
                "'standard_errors'"
            )
    return matrix

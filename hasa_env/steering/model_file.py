"""Steering-model files: the JSON document of a model, its registry of types, its errors.

A model file (``model.save(path)``, ``SteeringModel.load(path)``) is a JSON
object with ``format`` (= ``"hasa_env.steering_model"``), ``format_version``
(1), ``type`` (a registered model type: every concrete
:class:`~hasa_env.steering.base.SteeringModel` subclass registers its
``model_type`` in :data:`MODEL_TYPES` when it is defined), ``name``, ``dt``
(s), ``features`` (near/far distances in m, decision lag, the regressors),
``structure`` (the model's keyword arguments, e.g. its orders),
``parameters``, ``standard_errors`` and, optionally, ``class``
(``"package.module:ClassName"``, so that
:func:`hasa_env.steering.loading.load_model_file` can import a user type's
module). :func:`model_from_dict` validates every field and names the file,
the field and the allowed values.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE

__all__ = [
    "MODEL_FILE_FORMAT",
    "MODEL_FILE_VERSION",
    "MODEL_TYPES",
    "ModelFileError",
    "model_from_dict",
]

MODEL_FILE_FORMAT = "hasa_env.steering_model"
"""Value of the ``"format"`` field of a model file."""

MODEL_FILE_VERSION = 1

MODEL_TYPES: dict[str, type] = {}
"""Registered model types: JSON ``"type"`` -> class (filled when a subclass is defined)."""


class ModelFileError(ValueError):
    """A steering-model file or JSON document that cannot be read; the message names the field."""


def _finite_positive(value: Any, field: str, source: str) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise ModelFileError(
            f"{source}: field '{field}' must be a finite positive number, got {value!r}"
        )
    return float(value)


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
    number, or null) and ``standard_errors`` (same, or null).

    Raises:
        ModelFileError: naming ``source``, the field and the allowed values.
    """
    if not isinstance(document, Mapping):
        raise ModelFileError(f"{source}: expected a JSON object, got {type(document).__name__}")
    known = {
        "format", "format_version", "type", "name", "dt", "features", "structure",
        "parameters", "standard_errors", "class",
    }  # fmt: skip
    unknown = sorted(set(document) - known)
    if unknown:
        raise ModelFileError(
            f"{source}: unknown field '{unknown[0]}'; allowed fields: {', '.join(sorted(known))}"
        )
    for field in ("format", "type", "dt", "features", "parameters"):
        if field not in document:
            raise ModelFileError(f"{source}: missing field '{field}'")
    if document["format"] != MODEL_FILE_FORMAT:
        raise ModelFileError(
            f"{source}: field 'format' is {document['format']!r}; allowed: {MODEL_FILE_FORMAT!r}"
        )
    version = document.get("format_version", MODEL_FILE_VERSION)
    if version != MODEL_FILE_VERSION:
        raise ModelFileError(
            f"{source}: field 'format_version' is {version!r}; allowed: {MODEL_FILE_VERSION}"
        )
    cls = document.get("class")
    if cls is not None and not isinstance(cls, str):
        raise ModelFileError(
            f"{source}: field 'class' must be a string 'package.module:ClassName', got {cls!r}"
        )
    model_type = document["type"]
    if model_type not in MODEL_TYPES:
        where = f" ({cls})" if cls else ""
        raise ModelFileError(
            f"{source}: field 'type' is {model_type!r}; "
            f"allowed: {', '.join(sorted(MODEL_TYPES))} "
            f"(a custom model's class{where} must be defined (imported) before loading its "
            "file; hasa_env.steering.loading.load_model_file imports the module its 'class' "
            "field names)"
        )
    target = MODEL_TYPES[model_type]
    if expected is not None and not issubclass(target, expected):
        raise ModelFileError(
            f"{source}: field 'type' is {model_type!r} but {expected.__name__}.from_json expects "
            f"{expected.model_type!r}; use SteeringModel.load to read any model"
        )
    dt = _finite_positive(document["dt"], "dt", source)
    features = document["features"]
    if not isinstance(features, Mapping):
        raise ModelFileError(f"{source}: field 'features' must be an object, got {features!r}")
    allowed_features = {
        "near_distance",
        "far_distance",
        "decision_lag",
        "steering_signal",
        "regressors",
    }
    bad = sorted(set(features) - allowed_features)
    if bad:
        raise ModelFileError(
            f"{source}: unknown field 'features.{bad[0]}'; "
            f"allowed: {', '.join(sorted(allowed_features))}"
        )
    near = _finite_positive(
        features.get("near_distance", NEAR_POINT_DISTANCE), "features.near_distance", source
    )
    far = _finite_positive(
        features.get("far_distance", FAR_POINT_DISTANCE), "features.far_distance", source
    )
    signal = features.get("steering_signal", "measured")
    if signal not in ("measured", "applied"):
        raise ModelFileError(
            f"{source}: field 'features.steering_signal' must be 'measured' or 'applied', "
            f"got {signal!r}"
        )
    lag = features.get("decision_lag", 1)
    if isinstance(lag, bool) or not isinstance(lag, int) or lag < 0:
        raise ModelFileError(
            f"{source}: field 'features.decision_lag' must be a non-negative integer, got {lag!r}"
        )
    name = document.get("name", model_type)
    if not isinstance(name, str):
        raise ModelFileError(f"{source}: field 'name' must be a string, got {name!r}")
    structure = document.get("structure", {})
    if not isinstance(structure, Mapping):
        raise ModelFileError(f"{source}: field 'structure' must be an object, got {structure!r}")
    try:
        skeleton = target(
            **structure,
            near_distance=near,
            far_distance=far,
            dt=dt,
            decision_lag=lag,
            steering_signal=signal,
            name=name,
        )
    except (TypeError, ValueError) as exc:
        raise ModelFileError(
            f"{source}: field 'structure' is not valid for {model_type!r}: {exc}"
        ) from None
    names = skeleton.parameter_names
    values = {}
    for field in ("parameters", "standard_errors"):
        raw = document.get(field)
        if raw is None:
            values[field] = None
            continue
        if not isinstance(raw, Mapping):
            raise ModelFileError(
                f"{source}: field '{field}' must be an object name -> number or null, got {raw!r}"
            )
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
        for key in names:
            item = raw[key]
            if (
                isinstance(item, bool)
                or not isinstance(item, int | float)
                or not math.isfinite(item)
            ):
                raise ModelFileError(
                    f"{source}: field '{field}.{key}' must be a finite number, got {item!r}"
                )
            if field == "standard_errors" and item < 0:
                raise ModelFileError(f"{source}: field '{field}.{key}' must be >= 0, got {item!r}")
        values[field] = {n: float(raw[n]) for n in names}
    if values["parameters"] is None and values["standard_errors"] is not None:
        raise ModelFileError(f"{source}: field 'standard_errors' given without 'parameters'")
    listed = features.get("regressors")
    if listed is not None:
        expected = [str(r) for r in skeleton.regressors]
        if not isinstance(listed, list) or listed != expected:
            raise ModelFileError(
                f"{source}: field 'features.regressors' is {listed!r} but this structure uses "
                f"{expected}"
            )
    return target(
        **structure,
        parameters=values["parameters"],
        standard_errors=values["standard_errors"],
        near_distance=near,
        far_distance=far,
        dt=dt,
        decision_lag=lag,
        steering_signal=signal,
        name=name,
    )

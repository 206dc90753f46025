"""Steering models by name or file: what the command-line tools accept as ``--model``.

:func:`load_model` takes ``"two-point"`` / ``"generalized"`` (the paper's
presets, :meth:`TwoPointModel.paper`, :meth:`GeneralizedModel.paper`), the
path of a saved model file (:meth:`SteeringModel.load`) or
``"package.module:Name"`` (a model, a model class or a function returning one). The paper's presets
describe the steering-WHEEL angle of its G29 (docs/design.md §5): in a
recording, which holds road-wheel angles, they apply with a steering ratio of
15 (:func:`default_steering_ratio`, :func:`in_model_units`).
"""

from __future__ import annotations

import importlib
import os

import pandas as pd

from hasa_env.steering.base import SteeringModel
from hasa_env.steering.models import GeneralizedModel, TwoPointModel

__all__ = [
    "PAPER_PRESETS",
    "PAPER_STEERING_RATIO",
    "default_steering_ratio",
    "in_model_units",
    "load_model",
]

PAPER_PRESETS = ("two-point", "generalized")
PAPER_STEERING_RATIO = 15.0
"""Model units per road-wheel radian of the paper's presets: their coefficients describe the
G29's steering-wheel angle (docs/design.md §5: the generalized preset centres the car at
15-45 m/s only with a steering ratio of 15)."""


def default_steering_ratio(spec: str, fitted: bool) -> float:
    """Steering ratio (model units per recorded road-wheel radian) for a model given by ``spec``.

    The paper's presets (not refitted) work in steering-wheel units: 15; a model
    fitted on recordings, or loaded from a file, is taken to work in road-wheel units: 1.
    """
    return PAPER_STEERING_RATIO if spec in PAPER_PRESETS and not fitted else 1.0


def in_model_units(frame: pd.DataFrame, steering_ratio: float) -> pd.DataFrame:
    """A copy of a recording frame with ``steering`` and ``sensor_steering`` times the ratio."""
    if steering_ratio == 1.0:
        return frame
    out = frame.copy()
    for column in ("steering", "sensor_steering"):
        out[column] = frame[column] * steering_ratio
    return out


def load_model(spec: str, dt: float = 0.01) -> SteeringModel:
    """A steering model: ``two-point`` / ``generalized`` (paper presets), a saved model file,
    or ``package.module:Name``.

    ``dt`` (s) is the sample time the two-point preset is built for (its
    integral term depends on it); the generalized preset's coefficients
    belong to Ts = 0.01 s whatever ``dt`` is, and a file carries its own.
    """
    if spec == "two-point":
        return TwoPointModel.paper(dt=dt)
    if spec == "generalized":
        return GeneralizedModel.paper()
    if os.path.exists(spec):
        return SteeringModel.load(spec)
    if spec.count(":") == 1 and all(spec.split(":")):
        return _import_model(spec)
    raise ValueError(
        f"unknown model {spec!r}: use 'two-point', 'generalized', the path of a saved model file "
        "or 'package.module:Name'"
    )


def _import_model(spec: str) -> SteeringModel:
    """The model named by ``"package.module:Name"``: a :class:`SteeringModel` instance, a
    subclass (created without arguments) or a function returning one."""
    module_name, attribute = spec.split(":")
    try:
        obj = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"model {spec!r}: cannot import module {module_name!r} ({exc})") from None
    for part in attribute.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"model {spec!r}: module {module_name!r} has no {attribute!r}")
        obj = getattr(obj, part)
    if isinstance(obj, type) and issubclass(obj, SteeringModel):
        obj = obj()
    elif callable(obj) and not isinstance(obj, SteeringModel):
        obj = obj()
    if not isinstance(obj, SteeringModel):
        raise ValueError(
            f"model {spec!r} is a {type(obj).__name__}, not a hasa_env.steering.SteeringModel "
            "(see examples/custom_steering_model.py)"
        )
    return obj

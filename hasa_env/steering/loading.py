"""Steering models by name, file or import path: what the command-line tools accept as ``--model``.

:func:`load_model` takes

- ``"two-point"`` / ``"generalized"``: the paper's presets
  (:meth:`TwoPointModel.paper`, :meth:`GeneralizedModel.paper`);
- the path of a saved model file (``model.save("m.json")``) of a registered
  model type: a built-in one, or a user type whose module has been imported.
  A file names its class in ``"class"`` (e.g. ``"my_pkg.models:NearFarPD"``),
  but reading a file imports that module only when the caller says so
  (``trust_module=True``, ``--trust-model-module``): a user model is code,
  and a file is data (docs/design.md, "Model files are data");
- ``"package.module:Name"``: a :class:`SteeringModel` subclass (created
  without arguments), an instance of one, or a function returning one
  (:func:`import_model`).

Every model it returns has passed :meth:`SteeringModel.check_regressors`
(its ``regressors`` list what its ``design()`` uses). The paper's presets
describe the steering-WHEEL angle of its G29 (docs/design.md §5.8): in a
recording, which holds road-wheel angles, they apply with a steering ratio of
15 (:func:`default_steering_ratio`, :func:`in_model_units`).
"""

from __future__ import annotations

import importlib
import json
import os
import re
import sys
import traceback
from pathlib import Path
from typing import Any

import pandas as pd

from hasa_env.files import read_bounded_text
from hasa_env.steering.base import SteeringModel
from hasa_env.steering.model_file import (
    CLASS_PATH,
    MAX_MODEL_FILE_BYTES,
    MODEL_TYPES,
    ModelFileError,
)
from hasa_env.steering.models import GeneralizedModel, TwoPointModel
from hasa_env.validation import did_you_mean

__all__ = [
    "MODEL_SPEC_FORMS",
    "PAPER_PRESETS",
    "PAPER_STEERING_RATIO",
    "ModelLoadError",
    "add_module_folders",
    "default_steering_ratio",
    "describe_exception",
    "import_model",
    "in_model_units",
    "load_model",
    "load_model_file",
    "model_spec_kind",
]

PAPER_PRESETS = ("two-point", "generalized")
PAPER_STEERING_RATIO = 15.0
"""Model units per road-wheel radian of the paper's presets: their coefficients describe the
G29's steering-wheel angle (docs/design.md §5: the generalized preset centres the car at
15-45 m/s only with a steering ratio of 15)."""

MODEL_SPEC_FORMS = (
    "'two-point' or 'generalized' (the paper's presets), the path of a saved model file "
    "(model.save('model.json')), or 'package.module:ClassName' (a SteeringModel subclass)"
)
"""What a model spec may be, for messages."""

_IMPORT_PATH = re.compile(r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*")
_HINT = (
    "a steering model must subclass hasa_env.steering.SteeringModel "
    "(README 'Write a steering model', examples/custom_steering_model.py)"
)


class ModelLoadError(ValueError):
    """A model spec that does not give a usable steering model.

    Attributes:
        spec: what was asked for; stage: ``"import"`` (module or attribute not
        found, or the module raised), ``"interface"`` (not a steering model, or
        its definition contradicts itself) or ``"file"`` (a model file);
        detail: what went wrong.
    """

    def __init__(self, spec: str, stage: str, detail: str) -> None:
        self.spec, self.stage, self.detail = spec, stage, detail
        super().__init__(f"model {spec!r}: {detail}")

    def __reduce__(self) -> tuple[Any, tuple[str, str, str]]:
        return (type(self), (self.spec, self.stage, self.detail))


def describe_exception(exc: BaseException) -> str:
    """``Type: message (at file:line in function)``, the line being the innermost frame's."""
    text = f"{type(exc).__name__}: {exc}"
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith("<")]
    if frames:
        last = frames[-1]
        text += f" (at {Path(last.filename).name}:{last.lineno} in {last.name})"
    return text


def model_spec_kind(spec: str) -> str:
    """``"preset"``, ``"file"`` or ``"import"``: which form of :data:`MODEL_SPEC_FORMS` ``spec`` is.

    A spec is a file if that path exists or it ends in ``.json``; an import
    path if it reads ``package.module:Name``.

    Raises:
        ModelLoadError: it is none of them.
    """
    if spec in PAPER_PRESETS:
        return "preset"
    if os.path.exists(spec) or spec.lower().endswith(".json"):
        return "file"
    if _IMPORT_PATH.fullmatch(spec):
        return "import"
    raise ModelLoadError(
        spec, "import", f"unknown model; use {MODEL_SPEC_FORMS}{did_you_mean(spec, PAPER_PRESETS)}"
    )


def import_model(spec: str) -> SteeringModel:
    """The steering model ``"package.module:Name"`` names (not checked, maybe unfitted).

    ``Name`` (dots allowed for nested attributes) may be a
    :class:`SteeringModel` subclass (created without arguments), an instance
    of one, or a function returning one. The module is imported from the
    installed packages and ``sys.path`` (the command-line tools add the
    working directory).

    Raises:
        ModelLoadError: stage ``"import"`` or ``"interface"``, naming ``spec``.
    """
    if not isinstance(spec, str) or not _IMPORT_PATH.fullmatch(spec):
        raise ModelLoadError(
            str(spec),
            "import",
            "expected 'package.module:ClassName' (a module path, a colon, a name in the module)",
        )
    module_name, attribute = spec.split(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # noqa: BLE001 - any error in the user's module
        raise ModelLoadError(
            spec, "import", f"cannot import module {module_name!r}: {describe_exception(exc)}"
        ) from None
    obj: Any = module
    for part in attribute.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ModelLoadError(
                spec, "import", f"module {module_name!r} has no attribute {attribute!r}"
            ) from None
    if isinstance(obj, SteeringModel):
        return obj
    if isinstance(obj, type):
        if not issubclass(obj, SteeringModel):
            raise ModelLoadError(
                spec, "interface", f"{obj.__qualname__} is not a SteeringModel; {_HINT}"
            )
        try:
            return obj()
        except TypeError as exc:
            raise ModelLoadError(
                spec,
                "interface",
                f"cannot create {obj.__qualname__}() without arguments: {describe_exception(exc)}",
            ) from None
        except Exception as exc:  # noqa: BLE001
            raise ModelLoadError(
                spec, "interface", f"{obj.__qualname__}() raised {describe_exception(exc)}"
            ) from None
    if callable(obj):
        try:
            model = obj()
        except Exception as exc:  # noqa: BLE001
            raise ModelLoadError(
                spec, "interface", f"{attribute}() raised {describe_exception(exc)}"
            ) from None
        if not isinstance(model, SteeringModel):
            raise ModelLoadError(
                spec, "interface", f"{attribute}() returned {type(model).__name__}; {_HINT}"
            )
        return model
    raise ModelLoadError(spec, "interface", f"{attribute} is a {type(obj).__name__}; {_HINT}")


def _read_model_document(path: str | os.PathLike[str]) -> Any:
    """The JSON document of a model file, read bounded (:data:`MAX_MODEL_FILE_BYTES`)."""
    source = os.fspath(path)
    try:
        text = read_bounded_text(path, "the model file", MAX_MODEL_FILE_BYTES)
    except FileNotFoundError:
        raise ModelFileError(f"{source}: no such model file") from None
    except IsADirectoryError:
        raise ModelFileError(f"{source}: is a directory, not a model file") from None
    except UnicodeDecodeError as exc:
        raise ModelFileError(f"{source}: not a UTF-8 text file ({exc.reason})") from None
    except OSError as exc:  # a FIFO, a device, too large, unreadable
        raise ModelFileError(f"{source}: cannot read it: {exc.strerror or exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelFileError(
            f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    except RecursionError:
        raise ModelFileError(f"{source}: not valid JSON (nested too deeply)") from None
    except ValueError as exc:  # an integer of more than 4300 digits
        raise ModelFileError(f"{source}: cannot be read as JSON: {str(exc)[:200]}") from None


def add_module_folders(*folders: str | os.PathLike[str]) -> None:
    """Put ``folders`` at the front of ``sys.path`` (each once, in the order given): where a
    user's model module is imported from (the command-line tools add the working directory)."""
    for folder in reversed([os.path.abspath(f) for f in folders]):
        if folder not in sys.path:
            sys.path.insert(0, folder)


def load_model_file(path: str | os.PathLike[str], trust_module: bool = False) -> SteeringModel:
    """Read a saved model file of a registered model type.

    A model file is data: its ``"type"`` must be registered (a built-in type,
    or a user type whose class has been defined, i.e. its module imported).
    Reading it never imports anything unless ``trust_module`` is given: then,
    if the type is not registered yet, the module its ``"class"`` field names
    (``"package.module:ClassName"``, written by :meth:`SteeringModel.save`) is
    imported first, searched in the working directory, the model file's folder
    and the installed packages. Importing a module runs its code: a user model
    is code, so trust only files whose module you trust. The file is read
    bounded (a regular file of at most :data:`MAX_MODEL_FILE_BYTES` bytes).

    Raises:
        ModelFileError: the file cannot be read or is invalid (naming the
            file and the field), its type is not registered (saying how to
            import its module), or its class's module does not register it.
    """
    source = os.fspath(path)
    document = _read_model_document(path)
    if isinstance(document, dict):
        model_type, cls = document.get("type"), document.get("class")
        known = isinstance(model_type, str) and model_type in MODEL_TYPES
        if isinstance(model_type, str) and not known and isinstance(cls, str):
            if not CLASS_PATH.fullmatch(cls):  # refused below, naming the field
                return SteeringModel.from_json(document, source)
            if not trust_module:
                raise ModelFileError(
                    f"{source}: model type {model_type!r} is not registered; the file names "
                    f"its class {cls!r}, but a model file never imports code by itself: a "
                    "user model is code; if you trust that module, pass --trust-model-module "
                    "(in Python: load_model_file(path, trust_module=True), or import the "
                    "module first)"
                )
            _import_class_module(source, model_type, cls, Path(source).parent)
    return SteeringModel.from_json(document, source)


def _import_class_module(source: str, model_type: str, cls: str, folder: Path) -> None:
    """Import the module of a trusted model file's ``class`` field (ModelFileError if that
    fails or does not register ``model_type``)."""
    module_name = cls.split(":")[0]
    add_module_folders(os.getcwd(), folder)
    try:
        importlib.import_module(module_name)
    except Exception as exc:  # noqa: BLE001 - any error in the user's module
        raise ModelFileError(
            f"{source}: model type {model_type!r} is not registered and its class's "
            f"module {module_name!r} (field 'class' = {cls!r}) cannot be imported: "
            f"{describe_exception(exc)}"
        ) from None
    if model_type not in MODEL_TYPES:
        raise ModelFileError(
            f"{source}: importing {module_name!r} (field 'class' = {cls!r}) did not "
            f"register the model type {model_type!r}; registered: "
            f"{', '.join(sorted(MODEL_TYPES))}"
        )


def default_steering_ratio(spec: str, fitted: bool) -> float:
    """Steering ratio (model units per recorded road-wheel radian) for a model given by ``spec``.

    The paper's presets (not refitted) work in steering-wheel units: 15; a model
    fitted on recordings, loaded from a file or imported is taken to work in
    road-wheel units: 1.
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


def load_model(spec: str, dt: float = 0.01, trust_module: bool = False) -> SteeringModel:
    """A steering model from any form of :data:`MODEL_SPEC_FORMS`, checked.

    ``dt`` (s) is the sample time the two-point preset is built for (its
    integral term depends on it); the generalized preset's coefficients
    belong to Ts = 0.01 s whatever ``dt`` is, and a file or an imported model
    carries its own. An imported model may be unfitted (``model.is_fitted``).
    ``trust_module``: a model file of a type not registered yet may import the
    module its ``"class"`` field names (:func:`load_model_file`).

    Raises:
        ModelLoadError: an unknown spec, a module or class that does not
            give a steering model, or one whose regressors and design
            disagree (:meth:`SteeringModel.check_regressors`).
        ModelFileError: a model file that cannot be read (naming the field).
    """
    kind = model_spec_kind(spec)
    if kind == "preset":
        return TwoPointModel.paper(dt=dt) if spec == "two-point" else GeneralizedModel.paper()
    model = load_model_file(spec, trust_module) if kind == "file" else import_model(spec)
    try:
        model.check_regressors()
    except ValueError as exc:
        raise ModelLoadError(spec, "interface", str(exc)) from None
    return model

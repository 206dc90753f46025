"""What the ``hasa-drive`` commands share: joystick profiles, force feedback, the estimator.

Used by :mod:`hasa_cli.drive` (the plain session) and :mod:`hasa_cli.study`
(study sessions).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym

from estimators.trust import trusted_filter
from estimators.wrappers import EstimatorInfoWrapper, estimator_wrapper
from hasa_env.devices.calibration import (
    CalibrationError,
    JoystickCalibration,
    load_calibration,
    shipped_calibration,
    user_calibration_path,
)
from hasa_env.devices.force_feedback import Autocentre, ForceFeedbackUnavailable
from hasa_env.devices.sources import InputManager
from hasa_env.drivers import require_lane_keeping
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.steering.base import SteeringModel
from hasa_env.steering.loading import add_module_folders, default_steering_ratio, load_model

__all__ = [
    "estimator_for",
    "estimator_model",
    "joystick_profiles",
    "start_autocentre",
]


def joystick_profiles(path: Path | None, log: Callable[[str], None]) -> list[JoystickCalibration]:
    """The calibration given (or the one ``hasa-drive calibrate`` wrote), then the shipped
    G29 and gamepad profiles."""
    profiles: list[JoystickCalibration] = []
    if path is None and user_calibration_path().exists():
        path = user_calibration_path()
    if path is not None:
        cal = load_calibration(path)
        if not isinstance(cal, JoystickCalibration):
            raise CalibrationError(str(path), "device", "must be 'joystick' for --calibration")
        log(f"hasa-drive: using the calibration {path}")
        profiles.append(cal)
    profiles += [shipped_calibration("g29"), shipped_calibration("gamepad")]  # type: ignore[list-item]
    return profiles


def estimator_model(spec: str, dt: float, trust_module: bool = False) -> SteeringModel:
    """The steering model of ``--estimator``: fitted, with an ARX form (ValueError if not);
    ``trust_module``: ``--trust-model-module`` (a model file may import its class's module)."""
    if ":" in spec:
        add_module_folders(os.getcwd())  # user models in the working directory
    model = load_model(spec, dt, trust_module=trust_module)
    if not model.is_fitted:
        raise ValueError(
            f"--estimator {spec}: the model has no parameters, and the estimator needs a fitted "
            "model: fit it and save it (model.fit(runs).save('model.json')), then pass that "
            "file, or name a function that returns a fitted model"
        )
    if model.arx() is None:
        raise ValueError(
            f"--estimator {spec}: {type(model).__name__}.arx() returns None: the estimator "
            "builds on a model's ARX form (README 'Write a steering model')"
        )
    return model


def estimator_for(
    spec: str,
    probe: LaneKeepingEnv,
    lane_check: bool = True,
    log: Callable[[str], None] | None = None,
    trust_module: bool = False,
) -> Callable[[gym.Env], EstimatorInfoWrapper]:
    """The env wrapper running the estimator with ``spec``'s model (checked on ``probe``;
    with ``lane_check``, ValueError if the model cannot keep the car on the road when it
    steers itself: :func:`hasa_env.drivers.require_lane_keeping`). ``log`` hears where the
    estimator does not listen to the model's steering, and why
    (:func:`estimators.trust.trusted_filter`); ``trust_module``: a model file may import the
    module its ``"class"`` names."""
    model = estimator_model(spec, probe.setup.env_step_duration, trust_module)
    ratio = default_steering_ratio(spec, fitted=False)
    if lane_check:
        require_lane_keeping(model, steering_ratio=ratio, what=f"--estimator {spec!r}")
    wrapper = estimator_wrapper(model, ratio)
    wrapper(probe)  # fail now, not after the countdown
    if log is not None:
        trusted = trusted_filter(model, steering_ratio=ratio)
        log(f"hasa-drive: --estimator {spec}: {trusted.describe()}")
    return wrapper


def start_autocentre(inputs: InputManager, strength: float, log: Callable[[str], None]) -> Any:
    """The wheel's autocentre spring (Linux, evdev), or None with a message why not."""
    inputs.poll()
    if inputs.active is None:
        log("hasa-drive: --autocentre: no wheel connected; driving without force feedback")
        return None
    try:
        return Autocentre(inputs.active.name, strength)
    except ForceFeedbackUnavailable as exc:
        log(f"hasa-drive: --autocentre: {exc}")
        return None

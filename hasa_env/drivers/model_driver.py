"""A driver built from any steering model, and a driver replaying recorded actions."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.drivers.base import (
    LoopBatch,
    SpeedProfile,
    info_arrays,
    speed_command,
    speed_profile_arrays,
)
from hasa_env.sim.road import Road
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.base import SteeringModel
from hasa_env.steering.features import near_far_bearings

__all__ = ["ModelDriver", "ModelBatch", "ReplayDriver"]

_NOISE_BLOCK = 1000


class ModelDriver:
    """Drive with a steering model (two-point, generalized, or a user's) plus noise.

    At each env step k the driver computes the model's bearings phi(k),
    omega(k) (at the model's near/far distances, exact on curved roads) and
    lateral velocity from the true ``info``, and the model's output

        u(k) = model(u(k-1), u(k-2), ..., phi(k), ..., omega(k), ..., v_y(k), ...) + e(k),

    with white noise e ~ N(0, noise_std^2) (rad, model units). The road-wheel
    angle applied over the next step is ``u(k) / steering_ratio``. The past
    u's are the *measured* steering (the env's applied, possibly clipped,
    road-wheel angle times the ratio), as the model's definition requires.
    A recording of this driver therefore follows the model exactly (up to
    clipping): :mod:`hasa_env.steering.features` aligns row k's steering with
    the bearings of row k-1, which is when it was decided.

    A model with a dead time (``decision_lag`` L > 1) sees the bearings and v_y of L - 1
    steps before: u(k) uses phi(k-L+1), ..., so that a recording of it pairs row k's
    steering with row k-L's bearings as its features do.

    At reset the model's memory is filled with the initial steering and the
    initial bearings (a car at rest in the model's sense).

    Args:
        model: a fitted :class:`~hasa_env.steering.base.SteeringModel`.
        noise_std: standard deviation of the equation noise e (rad, model units).
        steering_ratio: model output per road-wheel angle (> 0; 1: the model
            outputs road-wheel angles; e.g. 15 if it outputs steering-wheel angles).
        speed: speed behaviour (default: hold the initial speed).
        name: a label (default: the model's name).
    """

    def __init__(
        self,
        model: SteeringModel,
        noise_std: float = 0.0,
        steering_ratio: float = 1.0,
        speed: SpeedProfile | None = None,
        name: str | None = None,
    ) -> None:
        if not isinstance(model, SteeringModel):
            raise TypeError(f"ModelDriver needs a SteeringModel, got {type(model).__name__}")
        if not model.is_fitted:
            raise ValueError(
                f"ModelDriver: the model {model.name!r} has no parameters; fit it first"
            )
        if not (np.isfinite(noise_std) and noise_std >= 0):
            raise ValueError(f"noise_std must be a finite number >= 0 (rad), got {noise_std!r}")
        if not (np.isfinite(steering_ratio) and steering_ratio > 0):
            raise ValueError(
                f"steering_ratio must be a finite positive number, got {steering_ratio!r}"
            )
        self.model = model
        self.noise_std = float(noise_std)
        self.steering_ratio = float(steering_ratio)
        self.speed = speed if speed is not None else SpeedProfile.hold()
        if self.speed.pedal_noise > 0:
            raise ValueError(
                "ModelDriver: speed.pedal_noise must be 0 (a model driver holds its speed "
                "profile exactly; the pedal remnant belongs to the synthetic humans)"
            )
        self.name = name if name is not None else model.name
        self._batch: ModelBatch | None = None
        self._generic: _GenericModelState | None = None

    @classmethod
    def make_batch(cls, drivers: Sequence[ModelDriver]) -> ModelBatch | LoopBatch:
        """A vectorized batch if every model is an ARX model, else car-by-car."""
        if all(d.model.arx() is not None for d in drivers):
            return ModelBatch(drivers)
        return LoopBatch(drivers)

    def reset(self, seed: int | None = None, *, dt: float = 0.01) -> None:
        if abs(dt - self.model.dt) > 1e-9 * max(1.0, dt):
            raise ValueError(
                f"ModelDriver: the env steps every {dt:g} s but the model {self.model.name!r} "
                f"belongs to Ts = {self.model.dt:g} s"
            )
        if self.model.arx() is not None:
            self._batch = ModelBatch([self])
            self._batch.reset([seed], dt)
        else:
            self._generic = _GenericModelState(self, seed)

    def act(self, info: Mapping[str, Any], road: Road) -> tuple[float, float]:
        if self._batch is not None:
            steering, acceleration = self._batch.act(info_arrays(info, _INFO_NEEDED), road)
            return float(steering[0]), float(acceleration[0])
        if self._generic is None:
            raise RuntimeError("call reset() before act()")
        return self._generic.act(info, road)

    def __repr__(self) -> str:
        return (
            f"ModelDriver({self.model.name!r}, noise_std={self.noise_std:g}, "
            f"steering_ratio={self.steering_ratio:g})"
        )


_INFO_NEEDED = (
    "time",
    "station",
    "lateral_offset",
    "heading",
    "speed",
    "steering",
    "lateral_velocity",
)


def _with_dead_time(form: ARXForm, decision_lag: int) -> ARXForm:
    """The ARX form a driver acting at row k evaluates: ``decision_lag - 1`` leading zero
    coefficients on the bearings and v_y (beta'_{j + L - 1} = beta_j). The steering it
    decides at row k is applied over the step to row k+1, whose features pair it with the
    bearings of row k+1-L (:mod:`hasa_env.steering.features`); lag 1 (the default) and 0
    need no padding (0: the same-row bearings, the closest a driver can come)."""
    pad = max(int(decision_lag) - 1, 0)
    if not pad:
        return form
    zeros = (0.0,) * pad
    return replace(
        form,
        b=zeros + form.b if form.b else (),
        c=zeros + form.c if form.c else (),
        d=zeros + form.d if form.d else (),
    )


class ModelBatch:
    """N model drivers whose models are ARX models, acting on arrays."""

    def __init__(self, drivers: Sequence[ModelDriver]) -> None:
        self.drivers = list(drivers)
        self.num_cars = len(self.drivers)
        maybe_forms = [d.model.arx() for d in self.drivers]
        arx_forms = [f for f in maybe_forms if f is not None]
        if len(arx_forms) != len(maybe_forms):
            raise ValueError("ModelBatch needs ARX models")
        forms = [
            _with_dead_time(f, d.model.decision_lag)
            for f, d in zip(arx_forms, self.drivers, strict=True)
        ]
        self.forms = forms
        n = self.num_cars
        self.order = {k: max(len(getattr(f, k)) for f in forms) for k in ("a", "b", "c", "d")}
        self.coef = {}
        for key, size in self.order.items():
            table = np.zeros((n, size))
            for i, f in enumerate(forms):
                values = getattr(f, key)
                table[i, : len(values)] = values
            self.coef[key] = table
        self.near = np.array([f.near_distance for f in forms])
        self.far = np.array([f.far_distance for f in forms])
        self.noise_std = np.array([d.noise_std for d in self.drivers])
        self.ratio = np.array([d.steering_ratio for d in self.drivers])
        self.profile = speed_profile_arrays([d.speed for d in self.drivers])
        self._ready = False

    def reset(self, seeds: Sequence[int | None], dt: float) -> None:
        if len(seeds) != self.num_cars:
            raise ValueError(f"got {len(seeds)} seeds for {self.num_cars} drivers")
        for d in self.drivers:
            if abs(dt - d.model.dt) > 1e-9 * max(1.0, dt):
                raise ValueError(
                    f"ModelDriver: the env steps every {dt:g} s but the model {d.model.name!r} "
                    f"belongs to Ts = {d.model.dt:g} s"
                )
        self._rngs = [np.random.default_rng(s) for s in seeds]
        self._block = np.zeros((self.num_cars, _NOISE_BLOCK))
        self._pos = _NOISE_BLOCK
        self._fresh = True
        self._ready = True

    def _noise(self) -> np.ndarray:
        if self._pos >= _NOISE_BLOCK:
            for i, rng in enumerate(self._rngs):
                self._block[i] = rng.standard_normal(_NOISE_BLOCK)
            self._pos = 0
        w = self._block[:, self._pos]
        self._pos += 1
        return w

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        if not self._ready:
            raise RuntimeError("call reset() before act()")
        y, theta = info["lateral_offset"], info["heading"]
        station = info["station"]
        if road.is_straight:
            phi = -(theta + np.arctan(y / self.near))
            omega = -(theta + np.arctan(y / self.far))
        else:
            phi = np.empty(self.num_cars)
            omega = np.empty(self.num_cars)
            for distance in np.unique(self.near):
                rows = self.near == distance
                phi[rows] = near_far_bearings(
                    road, station[rows], y[rows], theta[rows], distance, distance
                )[0]
            for distance in np.unique(self.far):
                rows = self.far == distance
                omega[rows] = near_far_bearings(
                    road, station[rows], y[rows], theta[rows], distance, distance
                )[0]
        lateral_velocity = np.asarray(info["lateral_velocity"], dtype=np.float64)
        measured = np.asarray(info["steering"], dtype=np.float64) * self.ratio
        n = self.num_cars
        if self._fresh:
            self._delta = np.repeat(measured[:, None], max(self.order["a"], 1), axis=1)
            self._phi = np.repeat(phi[:, None], max(self.order["b"], 1), axis=1)
            self._omega = np.repeat(omega[:, None], max(self.order["c"], 1), axis=1)
            self._vy = np.repeat(lateral_velocity[:, None], max(self.order["d"], 1), axis=1)
            self._initial_speed = np.asarray(info["speed"], dtype=np.float64).copy()
            self._fresh = False
        else:
            # the measured steering of the step just taken is the newest past value
            for history in (self._delta, self._phi, self._omega, self._vy):
                history[:, 1:] = history[:, :-1].copy()
            self._delta[:, 0] = measured
        self._phi[:, 0] = phi
        self._omega[:, 0] = omega
        self._vy[:, 0] = lateral_velocity
        output = np.zeros(n)
        for key, history in (
            ("a", self._delta),
            ("b", self._phi),
            ("c", self._omega),
            ("d", self._vy),
        ):
            size = self.order[key]
            if size:
                output += np.sum(self.coef[key] * history[:, :size], axis=1)
        output = output + self.noise_std * self._noise()
        acceleration = speed_command(self.profile, self._initial_speed, info, road)
        return output / self.ratio, acceleration


class _GenericModelState:
    """Rolling feature history of a non-ARX model, predicted through ``predict_features``."""

    def __init__(self, driver: ModelDriver, seed: int | None) -> None:
        self.driver = driver
        self.model = driver.model
        self.rng = np.random.default_rng(seed)
        self.window = self.model.max_lag + 1
        self.rows: list[list[float]] = []
        self.initial_speed: float | None = None
        self.profile = speed_profile_arrays([driver.speed])

    def act(self, info: Mapping[str, Any], road: Road) -> tuple[float, float]:
        model = self.model
        phi, omega = near_far_bearings(
            road, info["station"], info["lateral_offset"], info["heading"],
            model.near_distance, model.far_distance,
        )  # fmt: skip
        measured = float(info["steering"]) * self.driver.steering_ratio
        seen = [float(phi), float(omega), float(info["lateral_velocity"]), float(info["speed"])]
        if not self.rows:
            self.rows = [[measured, *seen] for _ in range(self.window)]
            self.initial_speed = float(info["speed"])
        else:
            self.rows[-1][0] = measured
        self.rows.append([np.nan, *seen])
        self.rows = self.rows[-(self.window + 1) :]
        frame = pd.DataFrame(
            self.rows, columns=["delta", "phi", "omega", "lateral_velocity", "speed"]
        )
        frame.attrs = {
            "near_distance": model.near_distance,
            "far_distance": model.far_distance,
            "decision_lag": model.decision_lag,
        }
        output = float(model.predict_features(frame)[-1])
        if not np.isfinite(output):
            raise RuntimeError(
                f"ModelDriver: model {model.name!r} gave a non-finite steering from its history "
                "(does it use delta at lag 0?)"
            )
        output += self.driver.noise_std * float(self.rng.standard_normal())
        arrays = info_arrays(info, ("time", "station", "speed"))
        acceleration = speed_command(self.profile, np.array([self.initial_speed]), arrays, road)
        return output / self.driver.steering_ratio, float(acceleration[0])


class ReplayDriver:
    """Plays back recorded actions, one per env step (then holds the last one).

    Args:
        actions: an (n, 2) array of (steering rad, acceleration m/s^2), or a
            recording DataFrame (its rows 1..n's ``steering`` and
            ``acceleration``: the actions that produced rows 1..n). Replayed
            with the recording's seed and options in an env with
            ``action.type = "physical"``, it reproduces the recording.
    """

    def __init__(
        self, actions: np.ndarray | Sequence[Sequence[float]] | pd.DataFrame, name: str = "replay"
    ) -> None:
        if isinstance(actions, pd.DataFrame):
            missing = [c for c in ("steering", "acceleration") if c not in actions.columns]
            if missing:
                raise ValueError(f"ReplayDriver: the recording lacks the columns {missing}")
            table = actions[["steering", "acceleration"]].to_numpy(dtype=np.float64)[1:]
        else:
            table = np.asarray(actions, dtype=np.float64)
        if table.ndim != 2 or table.shape[1] != 2 or table.shape[0] < 1:
            raise ValueError(
                f"ReplayDriver needs an (n >= 1, 2) array of actions, got shape {table.shape}"
            )
        if not np.all(np.isfinite(table)):
            raise ValueError("ReplayDriver: the actions must be finite")
        self.actions = table
        self.name = name
        self._step = 0

    def reset(self, seed: int | None = None, *, dt: float = 0.01) -> None:
        self._step = 0

    def act(self, info: Mapping[str, Any], road: Road) -> tuple[float, float]:
        row = self.actions[min(self._step, len(self.actions) - 1)]
        self._step += 1
        return float(row[0]), float(row[1])

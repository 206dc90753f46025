"""The estimator protocol and the estimate it returns.

An estimator of the lane-keeping state with ambiguous markings is reset with
the first measurements and the lane hypotheses, then stepped once per sample
with that sample's measurements and IMU inputs. It may hold one run or a
batch of runs (the leading axis of every array).

Measurements (one row per run), in :data:`MEASUREMENT_KEYS` order:

    [speed (m/s), camera lateral offset y + b (m), human steering delta_h (rad)]

Inputs, in :data:`ACCELERATION_KEYS` order: the IMU's road-frame
accelerations (a_x, a_y) (m/s^2) averaged over the sample that *ended* at this
row; predicting state k from k-1 uses row k's IMU, then row k's measurements
update it (paper eq. 4, docs/design.md §4.5). A non-finite measurement
(NaN, +-inf) is missing (that row of the update is skipped); a non-finite
acceleration is treated as zero with a large process noise.

Road points (optional, per run and step): the lane-centre points ahead
(dx_near, dy_near, dx_far, dy_far) (m) in the road-tangent frame at the car,
the known road geometry (:mod:`estimators.road_geometry`); None means a
straight road.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = [
    "ACCELERATION_KEYS",
    "MEASUREMENT_KEYS",
    "Estimate",
    "LaneEstimator",
    "inputs_from_info",
    "measurements_from_info",
    "reset_inputs",
]

MEASUREMENT_KEYS = ("sensor_speed", "sensor_camera_lateral", "sensor_steering")
"""Recording columns / info keys of the measurement vector (m/s, m, rad)."""

ACCELERATION_KEYS = ("sensor_imu_longitudinal", "sensor_imu_lateral")
"""Recording columns / info keys of the IMU input (m/s^2)."""


@dataclass(frozen=True, eq=False)
class Estimate:
    """A Gaussian-mixture estimate: one component per lane hypothesis.

    Shapes use ``...`` for the run axis (absent for a single run), C for the
    number of hypotheses and n for the number of states. Treat the arrays as
    read-only (they may be shared with the estimator's next step input).

    Attributes:
        mean: (..., n) mixture mean ``sum_i w_i x_i`` (paper section 4.2).
        component_means: (..., C, n) per-hypothesis state means x_i.
        component_covariances: (..., C, n, n) per-hypothesis covariances P_i.
        weights: (..., C) hypothesis probabilities w_i (sum 1; 0 once pruned).
        log_weights: (..., C) natural logarithms of ``weights`` (-inf once pruned).
        most_likely: (...) index of the most probable hypothesis (int).
        hypotheses: (..., C) camera bias b of each hypothesis (m).
        state_names: names of the n states (first four: longitudinal_velocity,
            lateral_offset, lateral_velocity, bias).
        decision: (...) the decision state, ``"undecided"``, ``"decided"``
            or ``"model_mismatch"`` (:mod:`estimators.evidence` states the
            rule): a str for a single run, an array of str for a batch.
        model_error: (...) the statistic behind ``"model_mismatch"``: the best
            hypothesis' running mean normalized steering innovation squared
            (1: the steering model is as good as the filter assumes; NaN: no
            steering data yet or no steering model).
        innovation_autocorrelation: (...) the lag-1 autocorrelation of that
            hypothesis' normalized steering innovations (NaN: no data).
        evidence_scale: (...) the factor (>= 1) the steering evidence was
            divided by at the last step.
        covariance: (..., n, n) mixture covariance
            ``sum_i w_i (P_i + (x_i - mean)(x_i - mean)^T)`` (computed on first access).
    """

    mean: np.ndarray
    component_means: np.ndarray
    component_covariances: np.ndarray
    weights: np.ndarray
    log_weights: np.ndarray
    most_likely: np.ndarray | int
    hypotheses: np.ndarray
    state_names: tuple[str, ...]
    decision: np.ndarray | str = "undecided"
    model_error: np.ndarray | float = math.nan
    innovation_autocorrelation: np.ndarray | float = math.nan
    evidence_scale: np.ndarray | float = 1.0

    @classmethod
    def of_fields(cls, **fields: Any) -> Estimate:
        """The estimate of every field by name, as ``Estimate(**fields)`` builds it but without
        the frozen dataclass' ``object.__setattr__`` per field (the single car's filter builds
        one a step; ``tests/test_estimators_single_run_floats.py`` checks the two agree)."""
        estimate = object.__new__(cls)
        estimate.__dict__.update(fields)
        return estimate

    @property
    def decided(self) -> np.ndarray | bool:
        """True where the decision state is ``"decided"`` (a bool for a single run)."""
        decided = np.asarray(self.decision) == "decided"
        return bool(decided) if decided.ndim == 0 else decided

    @cached_property
    def covariance(self) -> np.ndarray:
        """(..., n, n) mixture covariance ``sum_i w_i (P_i + (x_i - mean)(x_i - mean)^T)``."""
        diff = self.component_means - self.mean[..., None, :]
        spread = self.component_covariances + diff[..., :, None] * diff[..., None, :]
        return np.einsum("...c,...cnm->...nm", self.weights, spread)

    @property
    def lateral_offset(self) -> np.ndarray:
        """Mixture estimate of y (m), shape (...)."""
        return self.mean[..., 1]

    @property
    def lateral_offset_std(self) -> np.ndarray:
        """Mixture standard deviation of y (m), shape (...)."""
        return np.sqrt(self.covariance[..., 1, 1])

    @property
    def bias(self) -> np.ndarray:
        """Mixture estimate of the camera bias b (m), shape (...)."""
        return self.mean[..., 3]

    @property
    def std(self) -> np.ndarray:
        """Square roots of the mixture covariance's diagonal, shape (..., n)."""
        return np.sqrt(np.diagonal(self.covariance, axis1=-2, axis2=-1))

    def run(self, index: int) -> Estimate:
        """The estimate of one run of a batch (drops the run axis)."""
        if self.mean.ndim < 2:
            raise ValueError("this estimate holds a single run; it has no run axis")
        return Estimate(
            self.mean[index],
            self.component_means[index],
            self.component_covariances[index],
            self.weights[index],
            self.log_weights[index],
            np.asarray(self.most_likely)[index],
            self.hypotheses[index],
            self.state_names,
            _item(self.decision, index, str),
            _item(self.model_error, index, float),
            _item(self.innovation_autocorrelation, index, float),
            _item(self.evidence_scale, index, float),
        )


def _item(value: Any, index: int, kind: type) -> Any:
    """Run ``index`` of a per-run statistic (a scalar is shared by every run)."""
    array = np.asarray(value)
    return kind(array[index] if array.ndim else array)


@runtime_checkable
class LaneEstimator(Protocol):
    """What every estimator of this package implements.

    ``measurement`` is shape (3,) for one run or (R, 3) for R runs
    (:data:`MEASUREMENT_KEYS` order), ``acceleration`` (2,) or (R, 2)
    (:data:`ACCELERATION_KEYS` order). ``hypotheses`` is (C,) (shared) or
    (R, C). With ``runs`` (an index array into an existing batch) only those
    runs are reset or stepped, the others are left untouched; the returned
    estimate then covers the whole batch. ``true_bias`` is used only by the
    oracle baseline (``uses_true_bias``); others ignore it. ``road_points``
    ((4,) or (R, 4), m; :mod:`estimators.road_geometry`) is the road ahead at
    that sample; None (the default) is a straight road, and callers pass it
    only on curved roads, so an estimator for straight roads may omit it.
    """

    state_names: tuple[str, ...]
    uses_true_bias: bool

    def reset(
        self,
        measurement: np.ndarray,
        hypotheses: Sequence[float] | np.ndarray,
        *,
        prior: np.ndarray | None = None,
        true_bias: np.ndarray | float | None = None,
        runs: np.ndarray | None = None,
        road_points: np.ndarray | None = None,
    ) -> Estimate: ...

    def step(
        self,
        measurement: np.ndarray,
        acceleration: np.ndarray,
        *,
        runs: np.ndarray | None = None,
        road_points: np.ndarray | None = None,
    ) -> Estimate: ...

    def estimate(self) -> Estimate: ...


def reset_inputs(
    measurement: np.ndarray,
    hypotheses: Sequence[float] | np.ndarray,
    prior: np.ndarray | None = None,
) -> tuple[np.ndarray, bool, np.ndarray, np.ndarray]:
    """The checked inputs of a mixture filter's ``reset``: the measurements as (R, 3), whether
    one run was given (a (3,) measurement), the hypotheses as (R, C) and the log prior (R, C)
    (uniform by default; -inf for a zero prior).

    Raises:
        ValueError: naming the shape or value that is wrong.
    """
    measurement = np.asarray(measurement, dtype=np.float64)
    single = measurement.ndim == 1
    z = measurement.reshape(1, -1) if single else measurement
    if z.ndim != 2 or z.shape[1] != 3:
        raise ValueError(f"measurement must have shape (3,) or (R, 3), got {measurement.shape}")
    n_runs = z.shape[0]
    hyp = np.asarray(hypotheses, dtype=np.float64)
    if hyp.ndim == 1:
        hyp = np.broadcast_to(hyp, (n_runs, hyp.size))
    if hyp.ndim != 2 or hyp.shape[0] != n_runs or hyp.shape[1] < 1:
        raise ValueError(
            f"hypotheses must have shape (C,) or ({n_runs}, C), got {np.shape(hypotheses)}"
        )
    if not np.all(np.isfinite(hyp)):
        raise ValueError("hypotheses must be finite")
    n_comp = hyp.shape[1]
    if prior is None:
        return z, single, hyp, np.full((n_runs, n_comp), -math.log(n_comp))
    p = np.broadcast_to(np.asarray(prior, dtype=np.float64), (n_runs, n_comp))
    if np.any(~np.isfinite(p)) or np.any(p < 0) or not np.allclose(p.sum(axis=1), 1.0):
        raise ValueError("prior must be non-negative and sum to 1 over the hypotheses")
    with np.errstate(divide="ignore"):
        log_w = np.log(p / p.sum(axis=1, keepdims=True))
    return z, single, hyp, log_w


def measurements_from_info(info: Mapping[str, Any]) -> np.ndarray:
    """The measurement vector(s) from an env's ``info`` (single: (3,), vector env: (N, 3))."""
    return np.stack([np.asarray(info[k], dtype=np.float64) for k in MEASUREMENT_KEYS], axis=-1)


def inputs_from_info(info: Mapping[str, Any]) -> np.ndarray:
    """The IMU input(s) (a_x, a_y) from an env's ``info`` (single: (2,), vector env: (N, 2))."""
    return np.stack([np.asarray(info[k], dtype=np.float64) for k in ACCELERATION_KEYS], axis=-1)

"""Visual features of the two-point steering models (paper eqs. (5)-(6); docs/design.md §5.1-5.2).

The two-point model sees the lane centre at two points ahead of the car:

- the near point at ``near`` m (6.2 m by default), bearing ``phi``;
- the far point at ``far`` m (20 m by default), bearing ``omega``
  (the paper's Omega).

Both bearings are in radians, measured from the car's heading, positive when
the point lies to the left (ISO 8855). On a straight road they are
``phi = -(theta + atan(y / near))`` and ``omega = -(theta + atan(y / far))``
(the paper's eqs. (5)-(6) with their xi_1/xi_2 typo fixed, docs/design.md §10); on a curved road the
exact bearing of the lane-centre point at that arc length ahead is used
(:func:`hasa_env.sim.road.lane_centre_bearing`). The generalized model also uses
the lateral velocity ``v_y = v sin(theta)`` (m/s, the paper's xi_3).

Sample alignment
----------------
A recording's row k holds the state at time k and the steering that was
*applied over the step ending at row k*; that steering was decided from what
the driver saw at row k-1. :func:`steering_features` therefore pairs the
steering of row k with the bearings and lateral velocity of row
``k - decision_lag`` (default 1 sample): in the steering models' equations
``delta(k)`` is the recorded steering of row k and ``phi(k)``, ``omega(k)``,
``v_y(k)`` are what the driver saw when deciding it. Row 0 of the features has
no bearings (NaN). A driver that acts on the env's info at time k (see
:mod:`hasa_env.drivers`) produces exactly this alignment, so a model fitted on
its recordings recovers the driver's coefficients.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping

import numpy as np
import pandas as pd

from hasa_env.sim.road import Road, lane_centre_bearing, make_road
from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE

__all__ = [
    "FEATURE_COLUMNS",
    "STEERING_SIGNALS",
    "near_far_bearings",
    "steering_features",
    "road_of_frame",
    "is_feature_frame",
]

STEERING_SIGNALS = ("measured", "applied")
"""Which steering a run's features take: ``"measured"``, the recording's
``sensor_steering`` (what the estimator sees; ``steering`` when a frame has no
sensor columns), or ``"applied"``, the true road-wheel angle ``steering``."""

FEATURE_COLUMNS = ("delta", "phi", "omega", "lateral_velocity", "speed")
"""Columns of :func:`steering_features` (rad, rad, rad, m/s, m/s)."""


def near_far_bearings(
    road: Road | None,
    station: np.ndarray | float,
    lateral_offset: np.ndarray | float,
    heading: np.ndarray | float,
    near: float = NEAR_POINT_DISTANCE,
    far: float = FAR_POINT_DISTANCE,
    exact: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Near- and far-point bearings (phi, omega) of the lane centre (rad, left positive).

    Args:
        road: the road; ``None`` means a straight road.
        station: arc length s of the car (m), scalar or array.
        lateral_offset: y (m, left positive), same shape.
        heading: theta relative to the road tangent (rad), same shape.
        near: near-point distance (m), 6.2 in the paper.
        far: far-point distance (m), 20 in the paper's equations.
        exact: True: the exact bearing of the lane-centre point ``near``/``far`` m
            of arc length ahead (:func:`hasa_env.sim.road.lane_centre_bearing`);
            False: the paper's straight-road formula
            ``phi = -(theta + atan(y / near))``, ``omega = -(theta + atan(y / far))``
            (eqs. (5)-(6)), whatever the road. Both agree on a straight road.

    Returns:
        ``(phi, omega)`` as float64 arrays of the broadcast input shape.
    """
    if not (near > 0 and far > 0):
        raise ValueError(f"near and far distances must be positive (m), got near={near}, far={far}")
    y = np.asarray(lateral_offset, dtype=np.float64)
    theta = np.asarray(heading, dtype=np.float64)
    if not exact or road is None or road.is_straight:
        return -(theta + np.arctan(y / near)), -(theta + np.arctan(y / far))
    s = np.asarray(station, dtype=np.float64)
    phi = lane_centre_bearing(road, s, y, theta, near)
    omega = lane_centre_bearing(road, s, y, theta, far)
    return np.asarray(phi, dtype=np.float64), np.asarray(omega, dtype=np.float64)


def road_of_frame(frame: pd.DataFrame) -> Road | None:
    """The road a recording was made on, from its metadata, or None if it does not say.

    Looks at ``frame.attrs["track"]`` or ``frame.attrs["config"]["track"]``
    (and ``["road"]["lane_width"]``), as a recording's metadata may carry them.
    """
    attrs = frame.attrs or {}
    config = attrs.get("config")
    track = attrs.get("track")
    width = 3.6
    if isinstance(config, Mapping):
        track = config.get("track", track)
        road_cfg = config.get("road")
        if isinstance(road_cfg, Mapping) and "lane_width" in road_cfg:
            width = float(road_cfg["lane_width"])
    if track is None:
        return None
    return make_road(str(track), lane_width=width)


def is_feature_frame(frame: pd.DataFrame) -> bool:
    """True if ``frame`` holds steering features (columns delta, phi, omega, lateral_velocity)."""
    return all(c in frame.columns for c in ("delta", "phi", "omega", "lateral_velocity"))


def _road_of_run(frame: pd.DataFrame) -> Road | None:
    """:func:`road_of_frame`, warning (at the caller of :func:`steering_features`) when it
    is None although the frame's ``road_curvature`` is not zero."""
    road = road_of_frame(frame)
    if road is None and "road_curvature" in frame.columns:
        curvature = frame["road_curvature"].to_numpy(dtype=np.float64)
        if np.any(np.abs(curvature[np.isfinite(curvature)]) > 0):
            warnings.warn(
                "the run has non-zero road_curvature but no road was given; using the "
                "straight-road bearing formula (pass road=... for curved tracks)",
                stacklevel=3,
            )
    return road


def _seen_per_row(
    frame: pd.DataFrame, road: Road | None, near: float, far: float, exact: bool
) -> dict[str, np.ndarray]:
    """What the driver sees at each row: ``phi``, ``omega`` (rad, :func:`near_far_bearings`),
    ``lateral_velocity`` (m/s; the frame's, else v sin theta) and ``speed`` (m/s)."""
    y = frame["lateral_offset"].to_numpy(dtype=np.float64)
    theta = frame["heading"].to_numpy(dtype=np.float64)
    speed = frame["speed"].to_numpy(dtype=np.float64)
    if road is not None and not road.is_straight and exact:
        if "station" not in frame.columns:
            raise ValueError(
                "frame lacks the 'station' column needed for bearings on a curved road"
            )
        station = frame["station"].to_numpy(dtype=np.float64)
    else:
        station = np.zeros_like(y)
    phi, omega = near_far_bearings(road, station, y, theta, near, far, exact)
    if "lateral_velocity" in frame.columns:
        lateral_velocity = frame["lateral_velocity"].to_numpy(dtype=np.float64)
    else:
        lateral_velocity = speed * np.sin(theta)
    return {"phi": phi, "omega": omega, "lateral_velocity": lateral_velocity, "speed": speed}


def steering_features(
    frame: pd.DataFrame,
    road: Road | None = None,
    near: float = NEAR_POINT_DISTANCE,
    far: float = FAR_POINT_DISTANCE,
    *,
    decision_lag: int = 1,
    exact: bool = True,
    steering: str = "measured",
) -> pd.DataFrame:
    """Steering features of one recorded run (see the module docstring for the alignment).

    Args:
        frame: one run in the recording format (columns
            :data:`hasa_env.sim.setup.RECORDING_COLUMNS`; at least ``steering``,
            ``lateral_offset``, ``heading``, ``speed``, and ``station`` on curved roads).
        road: the road of the run. ``None``: the road named in the frame's
            metadata (:func:`road_of_frame`), else the straight-road formula
            (with a warning if the frame's ``road_curvature`` is not zero).
        near: near-point distance (m).
        far: far-point distance (m).
        decision_lag: samples between what the driver saw and the steering
            recorded (1 for the env's recordings; 0 pairs each row with itself).
        exact: use the exact bearings on curved roads (see :func:`near_far_bearings`).
        steering: ``"measured"`` (default): delta is the recording's
            ``sensor_steering`` (the steering sensor's reading, what the
            estimator sees), or ``steering`` if the frame has no sensor
            columns; ``"applied"``: the true applied road-wheel angle ``steering``.

    Returns:
        A DataFrame with the frame's index and columns ``delta`` (rad, the
        recorded road-wheel angle of row k, measured or applied), ``phi``, ``omega`` (rad) and
        ``lateral_velocity`` (m/s, v sin theta) seen at row k - decision_lag,
        and ``speed`` (m/s) at that row. ``attrs`` records ``near_distance``,
        ``far_distance``, ``decision_lag`` and ``dt`` (s, when the frame has a
        ``time`` column).
    """
    if (
        isinstance(decision_lag, bool)
        or not isinstance(decision_lag, int | np.integer)
        or decision_lag < 0
    ):
        raise ValueError(f"decision_lag must be a non-negative integer, got {decision_lag!r}")
    needed = ["steering", "lateral_offset", "heading", "speed"]
    missing = [c for c in needed if c not in frame.columns]
    if missing:
        raise ValueError(
            f"frame lacks the recording columns {missing}; steering_features needs "
            f"{needed} (+ station on curved roads); see hasa_env.sim.setup.RECORDING_COLUMNS"
        )
    if road is None:
        road = _road_of_run(frame)
    seen = _seen_per_row(frame, road, near, far, exact)
    lag = int(decision_lag)
    if steering not in STEERING_SIGNALS:
        raise ValueError(
            f"steering must be one of {', '.join(map(repr, STEERING_SIGNALS))}, got {steering!r}"
        )
    column = (
        "sensor_steering" if steering == "measured" and "sensor_steering" in frame else "steering"
    )
    out = {"delta": frame[column].to_numpy(dtype=np.float64)}
    for key, values in seen.items():
        shifted = np.full(values.size, np.nan)
        if lag < values.size:
            shifted[lag:] = values[: values.size - lag]
        out[key] = shifted
    features = pd.DataFrame(out, index=frame.index, columns=list(FEATURE_COLUMNS))
    features.attrs = {
        "near_distance": float(near),
        "far_distance": float(far),
        "decision_lag": lag,
        "steering": column,
    }
    if "time" in frame.columns and len(frame) > 1:
        steps = np.diff(frame["time"].to_numpy(dtype=np.float64))
        if steps.size and np.all(np.isfinite(steps)):
            features.attrs["dt"] = float(np.median(steps))
    return features

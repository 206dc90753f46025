"""The road ahead as a known input of the estimator: lane-centre points in the car's road frame.

A car with a map (or a lane camera that measures the lane's shape) knows
where the lane centre runs ahead of it. The estimator takes that geometry as
an input, per run and step, as the *road points*::

    p = (dx_near, dy_near, dx_far, dy_far)        (m)

the position of the lane-centre point ``near`` (``far``) m of arc length
ahead of the car's station s, relative to the lane centre at s, in the
road-tangent frame at s (x along the tangent, y to the left, ISO 8855). With
the centre line's global pose (X, Y, psi)(s) (:meth:`hasa_env.sim.road.Road.pose_at`)::

    D        = (X(s + d) - X(s), Y(s + d) - Y(s))
    dx_d     =  cos psi(s) D_x + sin psi(s) D_y
    dy_d     = -sin psi(s) D_x + cos psi(s) D_y

A car at lateral offset y (m, left positive) with heading theta (rad,
relative to the tangent at s) sits at (0, y) in that frame, so the bearing
of the point from the car's heading is (:mod:`estimators.arx_state_space`)::

    phi   = atan2(dy_near - y, dx_near) - theta
    Omega = atan2(dy_far  - y, dx_far)  - theta

On a straight road ``p = (near, 0, far, 0)`` and these are the paper's
``-(theta + atan(y / near))``, ``-(theta + atan(y / far))``. For the lane
whose centre is the road's reference line they equal
:func:`hasa_env.sim.road.lane_centre_bearing` exactly (up to rounding):
:func:`lane_centre_bearing_error` is that comparison.

Approximation for the other lane hypotheses: the filter gives every
hypothesis the same road points and its own offset y_i from its own lane
centre. The lane of a hypothesis whose centre lies L m left of the reference
line really has the centre point
``(dx_d - L sin dpsi_d, dy_d + L cos dpsi_d)`` relative to the reference line
at s, with ``dpsi_d = psi(s + d) - psi(s)`` (and arc length d along the
reference line, not along that lane), i.e. relative to its own centre at s::

    (dx_d - L sin dpsi_d,  dy_d - L (1 - cos dpsi_d))

so the filter's bearing for that hypothesis is off by about::

    (y_i - dy_d) L sin(dpsi_d) / dx_d^2 + L (1 - cos dpsi_d) / dx_d      (rad)

Measured over the whole curved track with |L| = 1.8 m
(:func:`lane_centre_bearing_error`): at most 2.4 mrad at the near point
(6.2 m) and 0.8 mrad at the far point (20 m) for |y_i| <= 1 m, under 0.1 mrad
at y_i = 0, against bearings of about y_i / d (160 mrad and 50 mrad at
y_i = 1 m). The lane the road points describe (L = 0) has no such error.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hasa_env.sim.road import Road, lane_centre_bearing
from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE

__all__ = [
    "ROAD_POINT_NAMES",
    "lane_points_ahead",
    "look_ahead_distances",
    "straight_road_points",
    "road_point_bearings",
    "lane_centre_bearing_error",
]

ROAD_POINT_NAMES = ("dx_near", "dy_near", "dx_far", "dy_far")
"""Entries of a road-points row (m), see the module docstring."""


def straight_road_points(near: float, far: float) -> np.ndarray:
    """The road points ``(near, 0, far, 0)`` (m) of a straight road, shape (4,)."""
    return np.array([float(near), 0.0, float(far), 0.0])


def look_ahead_distances(estimator: Any) -> tuple[float, float]:
    """(near, far) (m) of an estimator's model (``estimator.model``), else the defaults 6.2, 20."""
    model = getattr(estimator, "model", None)
    return (
        float(getattr(model, "near_distance", NEAR_POINT_DISTANCE)),
        float(getattr(model, "far_distance", FAR_POINT_DISTANCE)),
    )


def lane_points_ahead(
    road: Road, station: np.ndarray | float, near: float, far: float
) -> np.ndarray:
    """Road points (dx_near, dy_near, dx_far, dy_far) (m) of the lane centre ahead of ``station``.

    Vectorized over stations: see the module docstring for the equations.

    Args:
        road: the road (:class:`hasa_env.sim.road.Road`).
        station: arc length s (m) of the car, scalar or any shape (...).
        near: near-point distance (m of arc length ahead, > 0).
        far: far-point distance (m, > 0).

    Returns:
        (..., 4) float64 array (shape (4,) for a scalar station).
    """
    if not (near > 0 and far > 0):
        raise ValueError(f"near and far distances must be positive (m), got near={near}, far={far}")
    s = np.asarray(station, dtype=np.float64)
    if not np.all(np.isfinite(s)):
        raise ValueError("the stations must be finite (m)")
    x0, y0, psi0 = road.pose_at(s)
    cos0, sin0 = np.cos(psi0), np.sin(psi0)
    out = np.empty(s.shape + (4,))
    for column, distance in ((0, near), (2, far)):
        x1, y1, _ = road.pose_at(s + distance)
        ex, ey = x1 - x0, y1 - y0
        out[..., column] = cos0 * ex + sin0 * ey
        out[..., column + 1] = cos0 * ey - sin0 * ex
    return out


def road_point_bearings(
    points: np.ndarray, lateral_offset: np.ndarray | float, heading: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """(phi, Omega) (rad) of a car at lateral offset y (m) with heading theta (rad) from road points.

    ``phi = atan2(dy_near - y, dx_near) - theta``, ``Omega = atan2(dy_far - y, dx_far) - theta``.
    """
    points = np.asarray(points, dtype=np.float64)
    y = np.asarray(lateral_offset, dtype=np.float64)
    theta = np.asarray(heading, dtype=np.float64)
    phi = np.arctan2(points[..., 1] - y, points[..., 0]) - theta
    omega = np.arctan2(points[..., 3] - y, points[..., 2]) - theta
    return phi, omega


def lane_centre_bearing_error(
    road: Road,
    station: np.ndarray | float,
    lateral_offset: np.ndarray | float,
    heading: np.ndarray | float,
    near: float,
    far: float,
    lane_offset: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """How far the filter's bearings are from the exact ones, (phi error, Omega error) (rad).

    The filter's bearings of a hypothesis whose lane centre lies
    ``lane_offset`` m left of the reference line, with the car at
    ``lateral_offset`` from *that* lane's centre, minus
    :func:`hasa_env.sim.road.lane_centre_bearing` of that lane (the exact bearing
    of its centre point at arc length s + d of the reference line). Zero (up
    to rounding) for ``lane_offset = 0``; otherwise the approximation of the
    module docstring.
    """
    points = lane_points_ahead(road, station, near, far)
    phi, omega = road_point_bearings(points, lateral_offset, heading)
    y_ref = np.asarray(lateral_offset, dtype=np.float64) + lane_offset
    exact = [
        lane_centre_bearing(road, station, y_ref, heading, d, lane_offset) for d in (near, far)
    ]
    wrap = np.pi
    return (
        (phi - exact[0] + wrap) % (2.0 * wrap) - wrap,
        (omega - exact[1] + wrap) % (2.0 * wrap) - wrap,
    )

"""Roads: a lane centre line given by its curvature along the arc length s.

A :class:`Road` stores the curvature kappa(s) (1/m, positive turning left) on a
uniform grid, piecewise linear in s, so straights, circular arcs and clothoid
transitions are represented exactly. The centre line's global pose
(X, Y, psi) is integrated from it once. Beyond the end of the table the road
continues with the last curvature.

Frenet coordinates of a car: station s (m along the centre line), lateral
offset y (m, left positive, ISO 8855) and heading theta (rad, relative to the
road tangent). :meth:`Road.to_global` maps them to the global frame;
:func:`lane_centre_bearing` gives the bearing of a lane-centre point ahead,
the visual angle of the two-point steering model on any road.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

__all__ = [
    "Road",
    "straight_road",
    "curved_road",
    "make_road",
    "TRACKS",
    "lane_centre_bearing",
    "SHIFT_TOWARD",
    "nearest_other_hypothesis",
]

SHIFT_TOWARD = ("left", "other_hypothesis")
"""Allowed values of a lane shift's ``toward`` (config ``road.lane_shifts[i].toward``):
``"left"`` (the sign of ``offset`` as given, the default) or ``"other_hypothesis"``
(``offset`` points toward the nearest other hypothesis's lane centre, per episode)."""


@dataclass(frozen=True, eq=False)
class Road:
    """A centre line sampled on a uniform grid of arc length.

    Attributes:
        name: track name.
        spacing: grid spacing ds (m).
        curvature: kappa at the grid nodes (1/m), float64 array, linear in between.
        lane_width: m.
        lane_shifts: sideways moves of the lane the human drives in, relative to this
            centre line (the markings the camera reads): ``(station, length, offset)``
            in m each, a smooth half-cosine ramp of ``offset`` over
            ``[station, station + length]`` (a construction-zone shift, a planned lane
            change); they add up. :meth:`driven_offset` and :meth:`driven_slope` give
            the driven lane's centre; the car's dynamics and the camera ignore it.
        shifts_toward_other: one flag per entry of ``lane_shifts`` (empty: all False).
            True: the shift's ``offset`` is a size toward the other hypothesis, signed
            per episode by its true bias b (:meth:`shift_signs`); False: ``offset``
            as given (positive = left).
        hypotheses: the episode hypotheses (camera biases b_j, m; config
            ``markings.hypotheses``), needed (at least two) when a shift is toward the
            other hypothesis.
    """

    name: str
    spacing: float
    curvature: np.ndarray
    lane_width: float = 3.6
    lane_shifts: tuple[tuple[float, float, float], ...] = ()
    shifts_toward_other: tuple[bool, ...] = ()
    hypotheses: tuple[float, ...] = ()
    x: np.ndarray = field(init=False, repr=False)
    y: np.ndarray = field(init=False, repr=False)
    psi: np.ndarray = field(init=False, repr=False)
    curvature_list: list[float] = field(init=False, repr=False)
    curvature_slopes: np.ndarray = field(init=False, repr=False)
    """kappa[i + 1] - kappa[i] (1/m per grid cell), read-only: the piecewise-linear
    lookup's slope table (:meth:`curvature_lookup`), computed once."""
    _grid: np.ndarray = field(init=False, repr=False)
    _straight: bool = field(init=False, repr=False)
    _inv_spacing: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        kappa = np.asarray(self.curvature, dtype=np.float64)
        if kappa.ndim != 1 or kappa.size < 2:
            raise ValueError("Road.curvature must be a 1-D array of at least 2 nodes")
        if not np.all(np.isfinite(kappa)):
            raise ValueError("Road.curvature must be finite")
        ds = float(self.spacing)
        # Heading: exact integral of a piecewise-linear curvature.
        psi = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)])
        # Position: Gauss-Legendre quadrature of the exact (quadratic) heading over each cell.
        dx, dy = _cell_displacement(
            psi[:-1], kappa[:-1], kappa[1:], ds, np.full(kappa.size - 1, ds)
        )
        object.__setattr__(self, "curvature", kappa)
        object.__setattr__(self, "psi", psi)
        object.__setattr__(self, "x", np.concatenate([[0.0], np.cumsum(dx)]))
        object.__setattr__(self, "y", np.concatenate([[0.0], np.cumsum(dy)]))
        object.__setattr__(self, "curvature_list", kappa.tolist())
        object.__setattr__(self, "_grid", np.arange(kappa.size) * ds)
        # per-step constants, computed once: the drivers and the env ask for them every step
        object.__setattr__(self, "curvature_slopes", kappa[1:] - kappa[:-1])
        object.__setattr__(self, "_straight", not np.any(kappa))
        object.__setattr__(self, "_inv_spacing", 1.0 / ds)
        for arr in (self.curvature, self.psi, self.x, self.y, self.curvature_slopes):
            arr.setflags(write=False)
        toward = tuple(bool(t) for t in self.shifts_toward_other)
        if toward and len(toward) != len(self.lane_shifts):
            raise ValueError(
                f"Road.shifts_toward_other has {len(toward)} flags for {len(self.lane_shifts)} "
                "lane shifts; give one per shift (or none)"
            )
        hyps = tuple(float(h) for h in self.hypotheses)
        if any(toward) and len(set(hyps)) < 2:
            raise ValueError(
                "a lane shift toward the other hypothesis needs at least two distinct "
                f"Road.hypotheses, got {list(hyps)}"
            )
        object.__setattr__(self, "shifts_toward_other", toward)
        object.__setattr__(self, "hypotheses", hyps)

    @property
    def length(self) -> float:
        """Length (m) of the tabulated part; the road continues beyond it."""
        return self.spacing * (self.curvature.size - 1)

    @property
    def is_straight(self) -> bool:
        """Zero curvature everywhere (computed once, at construction)."""
        return self._straight

    def curvature_lookup(self, station: np.ndarray) -> np.ndarray:
        """kappa(s) (1/m) at the stations ``station`` (m, any shape), piecewise linear between
        the grid nodes and constant beyond the table: :func:`curvature_lookup_array` with the
        road's slope table, the same bits."""
        return curvature_lookup_array(
            self.curvature, self._inv_spacing, station, self.curvature_slopes
        )

    def shift_signs(self, bias: np.ndarray | float) -> np.ndarray:
        """sign(h_near - b) (+1.0 or -1.0, the shape of ``bias``): the direction from the
        true lane's centre toward the centre the nearest other hypothesis puts it at.

        h_near is the hypothesis other than b nearest to b; of two equally near, the
        lower (:func:`nearest_other_hypothesis`, the rule of ``initial_state.between_hypotheses``).
        """
        b = np.asarray(bias, dtype=np.float64)
        hyps = np.sort(np.asarray(self.hypotheses, dtype=np.float64))
        if hyps.size == 0:
            raise ValueError("Road.shift_signs needs Road.hypotheses")
        gap = hyps - b[..., None]
        distance = np.where(gap == 0.0, np.inf, np.abs(gap))
        if not np.all(np.isfinite(distance.min(axis=-1))):
            raise ValueError(f"no hypothesis other than the bias among {list(self.hypotheses)}")
        nearest = np.argmin(distance, axis=-1)  # the first of equals: the lower hypothesis
        return np.sign(np.take_along_axis(gap, nearest[..., None], axis=-1)[..., 0])

    def _signed_shifts(
        self, s: np.ndarray, bias: np.ndarray | float | None
    ) -> list[tuple[float, float, Any]]:
        """(station, length, signed offset) of each shift for the episode with true bias
        ``bias`` (scalar, or one per car along s's leading axis)."""
        if not any(self.shifts_toward_other):
            return list(self.lane_shifts)
        if bias is None:
            raise ValueError(
                "this road's lane shifts move toward the other hypothesis: give the "
                "episode's true bias (bias=info['bias'])"
            )
        signs = self.shift_signs(bias)
        extra = s.ndim - signs.ndim
        if extra > 0:
            signs = signs.reshape(signs.shape + (1,) * extra)
        return [
            (start, length, offset * signs if toward else offset)
            for (start, length, offset), toward in zip(
                self.lane_shifts, self.shifts_toward_other, strict=True
            )
        ]

    def driven_offset(
        self, s: np.ndarray | float, bias: np.ndarray | float | None = None
    ) -> np.ndarray:
        """Lateral offset (m, left positive) of the driven lane's centre at station s::

        offset(s) = sum_j o_j (1 - cos(pi u_j)) / 2,  u_j = clip((s - s_j) / l_j, 0, 1)

        o_j is shift j's ``offset``, or ``offset * sign(h_near - b)`` for a shift toward
        the other hypothesis (:meth:`shift_signs`), b the episode's true bias ``bias``
        (m; a scalar, or an array with one per car that broadcasts along s's leading
        axis; needed only then).
        """
        s = np.asarray(s, dtype=np.float64)
        out = np.zeros(s.shape)
        for start, length, offset in self._signed_shifts(s, bias):
            u = np.clip((s - start) / length, 0.0, 1.0)
            out = out + offset * 0.5 * (1.0 - np.cos(np.pi * u))
        return out

    def driven_slope(
        self, s: np.ndarray | float, bias: np.ndarray | float | None = None
    ) -> np.ndarray:
        """d offset / ds of :meth:`driven_offset` (rad, small-angle: the driven lane's
        heading relative to the centre line; ``bias`` as there)::

            slope(s) = sum_j o_j pi / (2 l_j) sin(pi u_j)
        """
        s = np.asarray(s, dtype=np.float64)
        out = np.zeros(s.shape)
        for start, length, offset in self._signed_shifts(s, bias):
            u = np.clip((s - start) / length, 0.0, 1.0)
            out = out + offset * np.pi / (2.0 * length) * np.sin(np.pi * u)
        return out

    def driven_curvature(
        self, s: np.ndarray | float, bias: np.ndarray | float | None = None
    ) -> np.ndarray:
        """d^2 offset / ds^2 of :meth:`driven_offset` (1/m): the curvature the driven lane
        adds to the road's (small angles; ``bias`` as there)::

            curvature(s) = sum_j o_j (pi / l_j)^2 / 2 cos(pi u_j),  0 < u_j < 1 (else 0)
        """
        s = np.asarray(s, dtype=np.float64)
        out = np.zeros(s.shape)
        for start, length, offset in self._signed_shifts(s, bias):
            u = (s - start) / length
            inside = (u > 0.0) & (u < 1.0)
            out = out + np.where(
                inside, offset * 0.5 * (np.pi / length) ** 2 * np.cos(np.pi * u), 0.0
            )
        return out

    def curvature_at(self, s: np.ndarray | float) -> np.ndarray:
        """kappa(s) (1/m), vectorized; constant beyond the table."""
        return np.interp(s, self._grid, self.curvature)

    def pose_at(self, s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Global (X, Y, psi) of the centre line at station s (m), vectorized.

        Inside the table the heading is the exact integral of the piecewise-linear
        curvature and the position its Gauss-Legendre quadrature from the cell's
        start node (smooth to machine precision, no kinks at the nodes); beyond
        either end the road is extended with its end curvature (exact arcs).
        """
        s = np.asarray(s, dtype=np.float64)
        s_in = np.clip(s, 0.0, self.length)
        ds = self.spacing
        i = np.minimum((s_in / ds).astype(np.int64), self.curvature.size - 2)
        u = s_in - self._grid[i]
        k0, k1 = self.curvature[i], self.curvature[i + 1]
        psi = self.psi[i] + k0 * u + (k1 - k0) * u * u / (2.0 * ds)
        dx, dy = _cell_displacement(self.psi[i], k0, k1, ds, u)
        X, Y = self.x[i] + dx, self.y[i] + dy
        extra = s - s_in
        if np.any(extra != 0.0):
            kappa_end = np.where(extra > 0, self.curvature[-1], self.curvature[0])
            dpsi = kappa_end * extra
            small = np.abs(dpsi) < 1e-9
            safe_k = np.where(small, 1.0, kappa_end)
            fx = np.where(small, extra * np.cos(psi), (np.sin(psi + dpsi) - np.sin(psi)) / safe_k)
            fy = np.where(small, extra * np.sin(psi), (np.cos(psi) - np.cos(psi + dpsi)) / safe_k)
            X, Y, psi = X + fx, Y + fy, psi + dpsi
        return X, Y, psi

    def to_global(
        self,
        station: np.ndarray | float,
        lateral_offset: np.ndarray | float,
        heading: np.ndarray | float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Global (X, Y, yaw) of a point at Frenet (s, y) with relative heading theta."""
        X, Y, psi = self.pose_at(station)
        return X - np.sin(psi) * lateral_offset, Y + np.cos(psi) * lateral_offset, psi + heading


_GAUSS_NODES, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(4)


def _cell_displacement(
    psi0: np.ndarray, k0: np.ndarray, k1: np.ndarray, ds: float, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(dx, dy) travelled from a cell's start node over arc length u (m) inside the cell.

    The heading is psi0 + k0 t + (k1 - k0) t^2 / (2 ds); cos and sin of it are
    integrated over [0, u] with 4-point Gauss-Legendre quadrature (error far
    below 1e-12 m for road curvatures).
    """
    u = np.asarray(u, dtype=np.float64)
    dx = np.zeros(np.broadcast(psi0, u).shape)
    dy = np.zeros_like(dx)
    for node, weight in zip(_GAUSS_NODES, _GAUSS_WEIGHTS, strict=True):
        t = 0.5 * u * (node + 1.0)
        heading = psi0 + k0 * t + (k1 - k0) * t * t / (2.0 * ds)
        dx += weight * np.cos(heading)
        dy += weight * np.sin(heading)
    return 0.5 * u * dx, 0.5 * u * dy


def lane_centre_bearing(
    road: Road,
    station: np.ndarray | float,
    lateral_offset: np.ndarray | float,
    heading: np.ndarray | float,
    distance: np.ndarray | float,
    lane_offset: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Bearing (rad, positive = to the left) of the lane-centre point ``distance`` m ahead.

    The point is the centre of the lane whose centre lies ``lane_offset`` m left
    of the road's reference line, at arc length ``station + distance``; the
    bearing is measured from the car's heading. On a straight road it equals the
    paper's approximation ``-(theta + atan((y - lane_offset) / distance))``
    exactly.
    """
    car_x, car_y, car_yaw = road.to_global(station, lateral_offset, heading)
    px, py, ppsi = road.pose_at(np.asarray(station, dtype=np.float64) + distance)
    px = px - np.sin(ppsi) * lane_offset
    py = py + np.cos(ppsi) * lane_offset
    bearing = np.arctan2(py - car_y, px - car_x) - car_yaw
    return (bearing + np.pi) % (2.0 * np.pi) - np.pi


def _profile(segments: list[tuple[float, float, float]], spacing: float) -> np.ndarray:
    """Curvature nodes from (length m, kappa_start, kappa_end) segments, linear inside each."""
    nodes = [segments[0][1]]
    for length, k0, k1 in segments:
        n = round(length / spacing)
        if abs(n * spacing - length) > 1e-9:
            raise ValueError(f"segment length {length} is not a multiple of the spacing {spacing}")
        nodes.extend((k0 + (k1 - k0) * np.arange(1, n + 1) / n).tolist())
    return np.asarray(nodes)


def straight_road(lane_width: float = 3.6, length: float = 5000.0, spacing: float = 1.0) -> Road:
    """An endless straight road (zero curvature)."""
    return Road("straight", spacing, np.zeros(int(round(length / spacing)) + 1), lane_width)


def curved_road(lane_width: float = 3.6, spacing: float = 0.5) -> Road:
    """The shipped curved track: left and right bends joined by clothoids.

    A 3,000 m course (then straight): 150 m straight, then a sequence of bends
    with radii 250 m (left), 150 m (right), 120 m (left), 300 m (right),
    200 m (left), each entered and left through 50 m clothoids with straights
    in between, so curvature is continuous (a car needs no steering jumps).
    It plays the part of the paper's "strongly curved" track; at 15-20 m/s the
    tightest bend needs about 2-3.3 m/s^2 of lateral acceleration.
    """
    segments: list[tuple[float, float, float]] = [(150.0, 0.0, 0.0)]
    for radius, arc in (
        (250.0, 200.0),
        (-150.0, 150.0),
        (120.0, 120.0),
        (-300.0, 250.0),
        (200.0, 180.0),
    ):
        k = 1.0 / radius
        segments += [(50.0, 0.0, k), (arc, k, k), (50.0, k, 0.0), (120.0, 0.0, 0.0)]
    used = sum(seg[0] for seg in segments)
    segments.append((3000.0 - used, 0.0, 0.0))
    return Road("curved", spacing, _profile(segments, spacing), lane_width)


TRACKS: dict[str, Callable[..., Road]] = {"straight": straight_road, "curved": curved_road}


def make_road(
    track: str,
    lane_width: float = 3.6,
    lane_shifts: Sequence[Mapping[str, Any]] = (),
    hypotheses: Sequence[float] = (),
) -> Road:
    """Build a named track ('straight' or 'curved'), with the driven lane's shifts
    (``{"station", "length", "offset"}`` each, m, and optionally ``"toward"``, one of
    :data:`SHIFT_TOWARD`: config ``road.lane_shifts``) and the episode hypotheses
    (m, config ``markings.hypotheses``; needed by a shift toward the other hypothesis)."""
    try:
        factory = TRACKS[track]
    except KeyError:
        raise ValueError(f"unknown track {track!r}; allowed: {', '.join(TRACKS)}") from None
    road = factory(lane_width=lane_width)
    if lane_shifts:
        shifts = tuple(
            (float(m["station"]), float(m["length"]), float(m["offset"])) for m in lane_shifts
        )
        toward = []
        for i, m in enumerate(lane_shifts):
            value = m.get("toward", SHIFT_TOWARD[0])
            if value not in SHIFT_TOWARD:
                allowed = ", ".join(repr(t) for t in SHIFT_TOWARD)
                raise ValueError(f"lane_shifts[{i}].toward must be one of {allowed}, got {value!r}")
            toward.append(value == "other_hypothesis")
        road = replace(
            road,
            lane_shifts=shifts,
            shifts_toward_other=tuple(toward) if any(toward) else (),
            hypotheses=tuple(float(h) for h in hypotheses),
        )
    return road


def nearest_other_hypothesis(bias: float, hypotheses: Sequence[float]) -> float | None:
    """The hypothesis other than ``bias`` nearest to it (m), the lower of two equally near;
    None when there is none."""
    others = [h for h in hypotheses if h != bias]
    if not others:
        return None
    return min(others, key=lambda h: (abs(h - bias), h))


def curvature_lookup_scalar(curvature: list[float], inv_spacing: float, station: float) -> float:
    """kappa(s) from the node list (pure Python, for the single env's hot path)."""
    top = len(curvature) - 1
    pos = station * inv_spacing
    pos = 0.0 if pos < 0.0 else (top if pos > top else pos)
    i = int(pos)
    i = top - 1 if i >= top else i
    k0 = curvature[i]
    return k0 + (pos - i) * (curvature[i + 1] - k0)


def curvature_lookup_array(
    curvature: np.ndarray,
    inv_spacing: float,
    station: np.ndarray,
    slopes: np.ndarray | None = None,
) -> np.ndarray:
    """kappa(s) from the node array (numpy, for the vector env); same arithmetic as the scalar one::

        pos = clip(s / ds, 0, n - 1),  i = min(floor(pos), n - 2)
        kappa(s) = kappa[i] + (pos - i) (kappa[i + 1] - kappa[i])

    ``slopes``: the table ``kappa[1:] - kappa[:-1]`` (:attr:`Road.curvature_slopes`), read
    instead of subtracting the two nodes at every call (the same difference, the same bits).
    """
    top = curvature.size - 1
    pos = np.minimum(np.maximum(station * inv_spacing, 0.0), top)
    i = np.minimum(pos.astype(np.int64), top - 1)
    k0 = curvature[i]
    if slopes is None:
        return k0 + (pos - i) * (curvature[i + 1] - k0)
    return k0 + (pos - i) * slopes[i]

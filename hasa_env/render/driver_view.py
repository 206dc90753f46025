"""The driver's-eye view: a first-person perspective of the road ahead.

What a participant sees in ``hasa-drive`` (and what ``render.view = "driver"``
renders): sky, grass, the grey road, the true lane markings in white (solid
road edges, dashed lane dividers), roadside posts every 50 m for a sense of
speed, the *ghost* markings of every wrong lane hypothesis b_i (the
camera reads y + b, b the episode's true bias ``info["bias"]``, so b_i puts the lane
centre at y = b_i - b and its markings at y = b_i - b +- lane_width / 2), drawn dashed
and faded, and
optionally the near (6.2 m) and far (20 m) lane-centre points of the
two-point steering model (filled for the lane the driver follows, rings for the
ghost lanes). The HUD (:class:`hasa_env.render.common.Hud`) shows time, speed,
steering angle and, when an estimator runs alongside, the hypothesis weights.

With ``road.lane_shifts`` (a construction-zone shift, a planned lane change) the lane
the driver follows leaves the marked one: its two lines, at ``driven_offset(s) +-
lane_width / 2`` (:meth:`hasa_env.sim.road.Road.driven_offset`, the episode's: a shift
toward the other hypothesis moves to the side of ``info["bias"]``'s nearest other
hypothesis), are drawn solid in
construction-zone yellow (:data:`~hasa_env.render.common.DRIVEN_LANE_COLOUR`) along the
visible stretch wherever its centre is off the marked lane's
(:func:`~hasa_env.render.common.driven_lane_runs`), over the white markings, which stay:
the camera keeps reading them. For a lane change the yellow lines show the planned path
into the other lane and back. They are drawn in every view, the participant's too (the
driver follows them), and the filled near/far points sit on the driven lane's centre.

:class:`hasa_env.render.options.ViewOptions` chooses what is drawn; a study
participant's view (:meth:`ViewOptions.participant`) hides the ghost
markings and the HUD and adds a bonnet and dashboard silhouette and
transverse bands on the road and the grass that stream past at the car's
speed (``hasa-bench perf`` measures it against the 60 fps target).

Camera model: a pinhole camera at the driver's eye, ``EYE_FORWARD`` m ahead
of the rear axle on the car's centre line, ``render.eye_height`` m above the
road, looking along the car's heading with a horizontal field of view
``render.horizontal_field_of_view`` (rad). The horizon sits at
``HORIZON_FRACTION`` of the frame height (a shifted principal point rather
than a pitched camera, so straight road lines stay straight). A ground
point at forward distance X_c and leftward offset Y_c (m, camera frame)
appears at ``(W/2 - f Y_c / X_c, horizon + f h / X_c)`` with the focal length
``f = (W/2) / tan(fov/2)`` in pixels.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from hasa_env.render.common import (
    DRIVEN_LANE_COLOUR,
    GHOST_COLOUR,
    GRASS_COLOUR,
    MARKING_COLOUR,
    ROAD_COLOUR,
    SceneRenderer,
    WeightSource,
    driven_lane_runs,
    ghost_centres,
)
from hasa_env.render.options import ViewOptions
from hasa_env.sim.setup import EnvSetup
from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE

__all__ = [
    "DriverViewRenderer",
    "SKY_COLOUR",
    "GHOST_FADED_COLOUR",
    "NEAR_POINT_COLOUR",
    "FAR_POINT_COLOUR",
    "NEAR_POINT_DISTANCE",
    "FAR_POINT_DISTANCE",
    "EYE_FORWARD",
]

SKY_COLOUR = (150, 190, 230)
FAR_GRASS_COLOUR = (70, 135, 70)
POST_COLOUR = (235, 235, 235)
POST_TOP_COLOUR = (30, 30, 30)
GHOST_FADED_COLOUR = tuple(
    int(round(0.55 * g + 0.45 * r)) for g, r in zip(GHOST_COLOUR, ROAD_COLOUR, strict=True)
)
"""Ghost markings, faded: 55 % ghost yellow over the road grey, (150, 142, 93)."""
NEAR_POINT_COLOUR = (0, 210, 255)
FAR_POINT_COLOUR = (255, 70, 200)

EYE_FORWARD = 1.2
"""Driver's eye ahead of the rear axle (m)."""
HORIZON_FRACTION = 0.4
"""Horizon height as a fraction of the frame height from the top."""
VIEW_DISTANCE = 250.0
"""Road drawn up to this distance ahead (m)."""
NEAR_CLIP = 0.8
"""Points closer than this (m, forward in the camera frame) are not drawn."""
MARKING_WIDTH = 0.15
"""Width of a lane marking (m)."""
DASH_PERIOD = 12.0
"""True lane dividers: 6 m dash, 6 m gap (as in the top-down view)."""
GHOST_DASH_PERIOD = 6.0
"""Ghost markings: 3 m dash, 3 m gap."""
DRIVEN_LANE_SPACING = 5.0
"""The driven lane's lines are sampled at least this often (m of station): far ahead the
road's own samples are up to 20 m apart, too sparse for a 65 m shift; at 5 m a chord
departs from the half-cosine ramp by under 1 cm."""
POST_SPACING = 50.0
"""Roadside posts every this many metres (m)."""
POINT_RADIUS = 0.12
"""Radius (m) of the near / far point discs."""
ROAD_BAND_PERIOD = 8.0
"""Road texture: a lighter band 4 m long every 8 m of road."""
ROAD_BAND_COLOUR = (101, 101, 107)
GRASS_BAND_PERIOD = 20.0
"""Grass texture: a lighter band 10 m long every 20 m."""
GRASS_BAND_COLOUR = (58, 134, 64)
GRASS_BAND_HALF_WIDTH = 40.0
"""The grass bands reach this far (m) either side of the lane centre."""
TEXTURE_DISTANCE = 120.0
"""Road and grass bands are drawn up to this distance ahead (m)."""
BONNET_DISTANCE = 4.0
"""The bonnet's edge hides the road closer than this (m ahead of the eye, at the view's centre)."""
BONNET_COLOUR = (32, 34, 40)
BONNET_EDGE_COLOUR = (70, 74, 84)
DASHBOARD_COLOUR = (16, 16, 19)


class DriverViewRenderer(SceneRenderer):
    """First-person perspective renderer of an env's ``info`` dict; one instance per env.

    Args:
        setup: the env's :class:`hasa_env.sim.setup.EnvSetup` (road, hypotheses, config).
        render_mode: ``"rgb_array"`` (frames as arrays) or ``"human"`` (a window).
        weights: where the HUD takes hypothesis weights from
            (:data:`hasa_env.render.common.WeightSource`); default: look in ``info``.
        steering_ratio: steering-wheel / road-wheel angle, shown in the HUD if given.
        size: frame (width, height) in pixels; default ``render.width``/``height``.
        show_points: draw the near and far points; default ``render.show_points``.
        options: what to draw (:class:`~hasa_env.render.options.ViewOptions`);
            default: everything (ghost markings, full HUD), no bonnet or texture.
    """

    def __init__(
        self,
        setup: EnvSetup,
        render_mode: str = "rgb_array",
        *,
        weights: WeightSource = None,
        steering_ratio: float | None = None,
        size: tuple[int, int] | None = None,
        show_points: bool | None = None,
        options: ViewOptions | None = None,
    ) -> None:
        if render_mode not in ("rgb_array", "human"):
            raise ValueError(f"render_mode must be 'rgb_array' or 'human', got {render_mode!r}")
        rc = setup.config["render"]
        super().__init__(
            setup,
            render_mode,
            size if size is not None else (int(rc["width"]), int(rc["height"])),
            "hasa-env: driver's view",
            weights=weights,
            steering_ratio=steering_ratio,
            options=options,
        )
        self.eye_height = float(rc["eye_height"])
        self.field_of_view = float(rc["horizontal_field_of_view"])
        self.show_points = bool(rc["show_points"]) if show_points is None else bool(show_points)
        self.focal = 0.5 * self.width / math.tan(0.5 * self.field_of_view)
        self.horizon = HORIZON_FRACTION * self.height
        self._bonnet = self._bonnet_surface() if self.options.bonnet else None
        road_cfg = setup.config["road"]
        lane = setup.road.lane_width
        self.right_edge = -lane / 2 - road_cfg["lanes_right"] * lane
        self.left_edge = lane / 2 + road_cfg["lanes_left"] * lane
        n_lanes = road_cfg["lanes_left"] + road_cfg["lanes_right"] + 1
        self.dividers = [self.right_edge + i * lane for i in range(1, n_lanes)]
        self._set_ghosts(None)
        self._road_centre = 0.5 * (self.right_edge + self.left_edge)
        # distances ahead of the car's station at which the continuous lines are sampled:
        # dense near the car, where perspective magnifies
        self._distances = np.geomspace(1.0, VIEW_DISTANCE, 64)
        # the driven lane's lines: the same samples while they are dense enough, then uniform
        gaps = np.diff(self._distances)
        cut = float(self._distances[np.flatnonzero(gaps > DRIVEN_LANE_SPACING)[0]])
        self._driven_distances = np.concatenate(
            [
                self._distances[self._distances <= cut],
                np.arange(cut + DRIVEN_LANE_SPACING, VIEW_DISTANCE, DRIVEN_LANE_SPACING),
                [VIEW_DISTANCE],
            ]
        )

    # ---------------------------------------------------------- geometry
    def _camera(self, info: Mapping[str, Any]) -> tuple[float, float, float, float]:
        """Camera (x, y, cos yaw, sin yaw) in the global frame."""
        gx, gy, yaw = self.setup.road.to_global(
            float(info["station"]), float(info["lateral_offset"]), float(info["heading"])
        )
        c, s = math.cos(float(yaw)), math.sin(float(yaw))
        return float(gx) + EYE_FORWARD * c, float(gy) + EYE_FORWARD * s, c, s

    def _to_camera(
        self, gx: np.ndarray, gy: np.ndarray, camera: tuple[float, float, float, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        ex, ey, c, s = camera
        dx, dy = gx - ex, gy - ey
        return dx * c + dy * s, -dx * s + dy * c

    def project(
        self,
        gx: np.ndarray,
        gy: np.ndarray,
        camera: tuple[float, float, float, float],
        height: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel x, y of global points ``height`` m above the road and their distance ahead (m)."""
        forward, left = self._to_camera(gx, gy, camera)
        safe = np.maximum(forward, NEAR_CLIP)
        sx = 0.5 * self.width - self.focal * left / safe
        sy = self.horizon + self.focal * (self.eye_height - height) / safe
        return sx, sy, forward

    def _offset_points(
        self,
        X: np.ndarray,
        Y: np.ndarray,
        psi_sin: np.ndarray,
        psi_cos: np.ndarray,
        offset: float | np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        return X - psi_sin * offset, Y + psi_cos * offset

    def _strip(
        self,
        poses: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        right: float | np.ndarray,
        left: float | np.ndarray,
        camera: tuple[float, float, float, float],
    ) -> list[tuple[float, float]] | None:
        """Polygon of the band between lateral offsets ``right`` < ``left`` (m; constants or one
        per pose); None if behind."""
        X, Y, sn, cs = poses
        rx, ry = self._offset_points(X, Y, sn, cs, right)
        lx, ly = self._offset_points(X, Y, sn, cs, left)
        rsx, rsy, rf = self.project(rx, ry, camera)
        lsx, lsy, lf = self.project(lx, ly, camera)
        visible = (rf > NEAR_CLIP) & (lf > NEAR_CLIP)
        idx = np.flatnonzero(visible)
        if idx.size < 2:
            return None
        # the first contiguous visible run (a very tight bend could bring points behind again)
        breaks = np.flatnonzero(np.diff(idx) != 1)
        if breaks.size:
            idx = idx[: breaks[0] + 1]
            if idx.size < 2:
                return None
        right_pts = np.stack([rsx[idx], rsy[idx]], axis=1)
        left_pts = np.stack([lsx[idx], lsy[idx]], axis=1)[::-1]
        return [tuple(p) for p in np.concatenate([right_pts, left_pts]).tolist()]

    def _poses(self, stations: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        X, Y, psi = self.setup.road.pose_at(stations)
        return X, Y, np.sin(psi), np.cos(psi)

    def _dashes(
        self,
        station: float,
        period: float,
        offsets: list[float],
        colour: tuple[int, ...],
        width: float,
        camera: tuple[float, float, float, float],
        near: float = 1.0,
        far: float = 160.0,
    ) -> None:
        """Dashes ``[k P, k P + P/2]`` (m of station) of the lines at lateral ``offsets`` (m),
        from ``near`` to ``far`` m ahead of the car's station."""
        if not offsets:
            return
        pg = self._pg
        start, end = station + near, station + min(VIEW_DISTANCE, far)
        first = math.floor(start / period)
        ks = np.arange(first, math.ceil(end / period))
        a = np.maximum(ks * period, start)
        b = np.minimum(ks * period + 0.5 * period, end)
        keep = b > a
        a, b = a[keep], b[keep]
        if a.size == 0:
            return
        # three samples per dash keep dashes on a bend curved
        samples = np.stack([a, 0.5 * (a + b), b], axis=1)
        X, Y, sn, cs = self._poses(samples.ravel())
        n = a.size
        for offset in offsets:
            rx, ry = self._offset_points(X, Y, sn, cs, offset - 0.5 * width)
            lx, ly = self._offset_points(X, Y, sn, cs, offset + 0.5 * width)
            rsx, rsy, rf = self.project(rx, ry, camera)
            lsx, lsy, lf = self.project(lx, ly, camera)
            rsx, rsy, lsx, lsy = (v.reshape(n, 3) for v in (rsx, rsy, lsx, lsy))
            ok = ((rf > NEAR_CLIP) & (lf > NEAR_CLIP)).reshape(n, 3).all(axis=1)
            for i in np.flatnonzero(ok):
                pts = [
                    (rsx[i, 0], rsy[i, 0]),
                    (rsx[i, 1], rsy[i, 1]),
                    (rsx[i, 2], rsy[i, 2]),
                    (lsx[i, 2], lsy[i, 2]),
                    (lsx[i, 1], lsy[i, 1]),
                    (lsx[i, 0], lsy[i, 0]),
                ]
                pg.draw.polygon(self._target, colour, pts)

    # ----------------------------------------------------------- drawing
    def _set_ghosts(self, bias: Any) -> None:
        """``ghost_centres`` and ``ghost_lines`` (m, true-lane coordinates) of the episode whose
        true bias is ``bias`` (:func:`~hasa_env.render.common.ghost_centres`; none when the
        options hide the ghosts)."""
        centres = ghost_centres(self.setup.hypotheses, bias) if self.options.ghosts else []
        lane = self.setup.road.lane_width
        self.ghost_centres = centres
        self.ghost_lines = [c + side * lane for c in centres for side in (-0.5, 0.5)]

    def _draw_scene(self, surf: Any, info: Mapping[str, Any]) -> None:
        """The road ahead from the driver's eye: sky, grass, road, markings, posts, bonnet."""
        self._set_ghosts(info.get("bias"))
        pg = self._pg
        w, h = self.width, self.height
        horizon = int(round(self.horizon))
        surf.fill(SKY_COLOUR, (0, 0, w, horizon))
        surf.fill(GRASS_COLOUR, (0, horizon, w, h - horizon))
        surf.fill(FAR_GRASS_COLOUR, (0, horizon, w, max(1, h // 60)))
        camera = self._camera(info)
        station = float(info["station"])
        texture = self.options.road_texture
        # bands start just beyond the eye (EYE_FORWARD + NEAR_CLIP ahead of the station)
        near = EYE_FORWARD + NEAR_CLIP + 0.2
        if texture:
            self._dashes(station, GRASS_BAND_PERIOD, [self._road_centre], GRASS_BAND_COLOUR,
                         2.0 * GRASS_BAND_HALF_WIDTH, camera, near, TEXTURE_DISTANCE)  # fmt: skip
        poses = self._poses(station + self._distances)
        road = self._strip(poses, self.right_edge, self.left_edge, camera)
        if road is not None:
            pg.draw.polygon(surf, ROAD_COLOUR, road)
        if texture:
            self._dashes(station, ROAD_BAND_PERIOD, [self._road_centre], ROAD_BAND_COLOUR,
                         self.left_edge - self.right_edge, camera, near, TEXTURE_DISTANCE)  # fmt: skip
        ghost_w = 0.7 * MARKING_WIDTH
        self._dashes(
            station, GHOST_DASH_PERIOD, self.ghost_lines, GHOST_FADED_COLOUR, ghost_w, camera
        )
        for edge in (self.right_edge, self.left_edge):
            band = self._strip(
                poses, edge - 0.5 * MARKING_WIDTH, edge + 0.5 * MARKING_WIDTH, camera
            )
            if band is not None:
                pg.draw.polygon(surf, MARKING_COLOUR, band)
        self._dashes(station, DASH_PERIOD, self.dividers, MARKING_COLOUR, MARKING_WIDTH, camera)
        bias = info.get("bias")  # the episode's: a lane shift may move toward its other hypothesis
        bias = None if bias is None else float(bias)
        self._draw_driven_lane(station, camera, bias)
        self._draw_posts(station, camera)
        if self.show_points:
            self._draw_points(station, camera, bias)
        if self._bonnet is not None:
            surf.blit(self._bonnet, (0, self.height - self._bonnet.get_height()))

    def _draw_driven_lane(
        self, station: float, camera: tuple[float, float, float, float], bias: float | None
    ) -> None:
        """The episode's driven lane's lines (yellow, solid) where it is off the marked lane
        (``bias``: the episode's true bias, m, for a shift toward the other hypothesis)."""
        road = self.setup.road
        if not road.lane_shifts:
            return
        stations = station + self._driven_distances
        offsets = road.driven_offset(stations, bias)
        poses = self._poses(stations)
        half, w = 0.5 * road.lane_width, 0.5 * MARKING_WIDTH
        for run in driven_lane_runs(offsets):
            stretch = (poses[0][run], poses[1][run], poses[2][run], poses[3][run])
            for line in (offsets[run] - half, offsets[run] + half):
                band = self._strip(stretch, line - w, line + w, camera)
                if band is not None:
                    self._pg.draw.polygon(self._target, DRIVEN_LANE_COLOUR, band)

    def _bonnet_surface(self) -> Any:
        """The bonnet and dashboard silhouette (drawn once, blitted every frame).

        The bonnet's edge is an arc: at the view's centre it sits where the
        road ``BONNET_DISTANCE`` m ahead of the eye appears, and it falls off
        towards the sides like a rounded bonnet; a dark dashboard strip runs
        along the bottom.
        """
        pg = self._pg
        w, h = self.width, self.height
        edge = self.horizon + self.focal * self.eye_height / BONNET_DISTANCE
        top = int(min(max(edge, self.horizon + 0.05 * h), 0.95 * h))
        surface = pg.Surface((w, h - top), pg.SRCALPHA)
        surface.fill((0, 0, 0, 0))
        drop = 0.09 * h  # the bonnet's edge is this much lower at the frame's sides
        xs = np.linspace(0.0, w, 33)
        ys = drop * ((xs - 0.5 * w) / (0.5 * w)) ** 2
        outline = [(float(x), float(y)) for x, y in zip(xs, ys, strict=True)]
        pg.draw.polygon(surface, BONNET_COLOUR, outline + [(w, h - top), (0, h - top)])
        pg.draw.lines(surface, BONNET_EDGE_COLOUR, False, outline, max(2, h // 240))
        dash = max(8, h // 14)
        surface.fill(DASHBOARD_COLOUR, (0, h - top - dash, w, dash))
        return surface

    def _draw_posts(self, station: float, camera: tuple[float, float, float, float]) -> None:
        ks = np.arange(
            math.ceil((station + 2.0) / POST_SPACING),
            math.floor((station + 200.0) / POST_SPACING) + 1,
        )
        if ks.size == 0:
            return
        X, Y, sn, cs = self._poses(ks * POST_SPACING)
        pg = self._pg
        for offset in (self.right_edge - 1.5, self.left_edge + 1.5):
            px, py = self._offset_points(X, Y, sn, cs, offset)
            sx, base, forward = self.project(px, py, camera)
            _, top, _ = self.project(px, py, camera, height=1.0)
            for x, y0, y1, f in zip(sx, base, top, forward, strict=True):
                if f <= 2.0:
                    continue
                half = max(1.0, 0.06 * self.focal / f)
                rect = pg.Rect(int(x - half), int(y1), max(1, int(2 * half)), max(1, int(y0 - y1)))
                pg.draw.rect(self._target, POST_COLOUR, rect)
                pg.draw.rect(
                    self._target, POST_TOP_COLOUR, (rect.x, rect.y, rect.w, max(1, rect.h // 5))
                )

    def _draw_points(
        self, station: float, camera: tuple[float, float, float, float], bias: float | None = None
    ) -> None:
        distances = np.array([NEAR_POINT_DISTANCE, FAR_POINT_DISTANCE])
        X, Y, sn, cs = self._poses(station + distances)
        pg = self._pg
        colours = (NEAR_POINT_COLOUR, FAR_POINT_COLOUR)
        driven = self.setup.road.driven_offset(station + distances, bias)  # 0 without shifts
        for centre, ring in [(driven, False)] + [(c, True) for c in self.ghost_centres]:
            px, py = self._offset_points(X, Y, sn, cs, centre)
            sx, sy, forward = self.project(px, py, camera)
            for x, y, f, colour in zip(sx, sy, forward, colours, strict=True):
                if f <= NEAR_CLIP:
                    continue
                radius = max(3, int(round(self.focal * POINT_RADIUS / f)))
                if ring:
                    pg.draw.circle(
                        self._target, colour, (int(x), int(y)), radius, max(1, radius // 3)
                    )
                else:
                    pg.draw.circle(self._target, colour, (int(x), int(y)), radius)

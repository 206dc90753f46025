"""The top-down view: the map of the road around the car, following it.

The view follows the car with the road tangent pointing up: grey road,
white lane markings (true), faded yellow "ghost" markings where a wrong
lane-centre hypothesis would put the lane, the car, and the shared HUD
(:class:`hasa_env.render.common.Hud`).

With ``road.lane_shifts`` (a construction-zone shift, a planned lane change) the lane
the driver follows leaves the marked one: its two lines, at ``driven_offset(s) +-
lane_width / 2`` (the episode's: a shift toward the other hypothesis moves to the side
of ``info["bias"]``'s nearest other hypothesis), are drawn solid in construction-zone yellow
(:data:`~hasa_env.render.common.DRIVEN_LANE_COLOUR`) wherever its centre is off the
marked lane's (:func:`~hasa_env.render.common.driven_lane_runs`), over the white
markings, which stay: the camera keeps reading them. For a lane change the yellow
lines show the planned path into the other lane and back. Drawn whatever the
:class:`~hasa_env.render.options.ViewOptions` (the driver follows them).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from hasa_env.render.common import (
    CAR_COLOUR,
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

__all__ = ["TopDownRenderer"]


class TopDownRenderer(SceneRenderer):
    """Draws an env's info dict from above; one instance per env.

    Args:
        setup: the env's :class:`hasa_env.sim.setup.EnvSetup`.
        render_mode: ``"rgb_array"`` or ``"human"``.
        weights: where the HUD takes hypothesis weights from (see :data:`WeightSource`).
        steering_ratio: steering-wheel / road-wheel angle, shown in the HUD if given.
        options: what to draw (:class:`~hasa_env.render.options.ViewOptions`: ghost
            markings, HUD items; the bonnet and road texture belong to the driver's view).
    """

    def __init__(
        self,
        setup: EnvSetup,
        render_mode: str,
        *,
        weights: WeightSource = None,
        steering_ratio: float | None = None,
        options: ViewOptions | None = None,
    ) -> None:
        rc = setup.config["render"]
        size = int(rc["width"]), int(rc["height"])
        super().__init__(
            setup,
            render_mode,
            size,
            "hasa-env lane keeping",
            weights=weights,
            steering_ratio=steering_ratio,
            options=options,
        )
        self.ppm = float(rc["pixels_per_metre"])

    # -------------------------------------------------------------- drawing
    def _to_screen(
        self, gx: np.ndarray, gy: np.ndarray, origin: tuple[float, float, float]
    ) -> np.ndarray:
        ox, oy, psi = origin
        dx, dy = gx - ox, gy - oy
        forward = dx * np.cos(psi) + dy * np.sin(psi)
        left = -dx * np.sin(psi) + dy * np.cos(psi)
        sx = self.width / 2 - left * self.ppm
        sy = self.height * 0.7 - forward * self.ppm
        return np.stack([sx, sy], axis=-1)

    def _line_points(
        self,
        poses: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        offset: float | np.ndarray,
        origin: tuple,
    ) -> list[tuple[float, float]]:
        """Screen points of the line ``offset`` m (a constant or one per pose) left of the
        centre-line ``poses`` (X, Y, sin psi, cos psi)."""
        X, Y, sn, cs = poses
        gx = X - sn * offset
        gy = Y + cs * offset
        return [tuple(p) for p in self._to_screen(gx, gy, origin).tolist()]

    def _draw_scene(self, surf: Any, info: Mapping[str, Any]) -> None:
        """The road from above: grass, road, true and ghost markings, the driven lane, the car."""
        pg = self._pg
        setup = self.setup
        road = setup.road
        width = road.lane_width
        surf.fill(GRASS_COLOUR)
        s0 = float(info["station"])
        behind = self.height * 0.3 / self.ppm + 5.0
        ahead = self.height * 0.7 / self.ppm + 5.0
        stations = np.arange(s0 - behind, s0 + ahead, 1.0)
        X0, Y0, psi0 = road.pose_at(s0)
        origin = (float(X0), float(Y0), float(psi0))
        X, Y, psi = road.pose_at(stations)
        poses = (X, Y, np.sin(psi), np.cos(psi))  # once per frame, shared by every line
        cfg = setup.config["road"]
        right_edge = -width / 2 - cfg["lanes_right"] * width
        left_edge = width / 2 + cfg["lanes_left"] * width
        left_pts = self._line_points(poses, left_edge, origin)
        right_pts = self._line_points(poses, right_edge, origin)
        pg.draw.polygon(surf, ROAD_COLOUR, left_pts + right_pts[::-1])
        line_w = max(1, int(round(0.15 * self.ppm)))
        # true markings: solid edges, dashed lane dividers
        n_lines = cfg["lanes_left"] + cfg["lanes_right"] + 1
        for i in range(n_lines + 1):
            offset = right_edge + i * width
            pts = self._line_points(poses, offset, origin)
            if i in (0, n_lines):
                pg.draw.lines(surf, MARKING_COLOUR, False, pts, line_w)
            else:
                self._dashed(pts, stations, MARKING_COLOUR, line_w)
        # ghost markings where each wrong hypothesis puts the lane (camera reads y + b)
        ghosts = ghost_centres(setup.hypotheses, info.get("bias"))
        for centre in ghosts if self.options.ghosts else ():
            for side in (-0.5, 0.5):
                pts = self._line_points(poses, centre + side * width, origin)
                self._dashed(pts, stations, GHOST_COLOUR, max(1, line_w // 2), period=6.0)
        self._draw_driven_lane(stations, poses, origin, line_w, info.get("bias"))
        self._draw_car(info, origin)

    def _draw_driven_lane(
        self, stations: np.ndarray, poses: tuple, origin: tuple, line_w: int, bias: Any
    ) -> None:
        """The episode's driven lane's lines (yellow, solid) where it is off the marked lane
        (``bias``: the episode's true bias, m, for a shift toward the other hypothesis)."""
        road = self.setup.road
        if not road.lane_shifts:
            return
        offsets = road.driven_offset(stations, None if bias is None else float(bias))
        half = 0.5 * road.lane_width
        for run in driven_lane_runs(offsets):
            stretch = tuple(p[run] for p in poses)
            for side in (-half, half):
                pts = self._line_points(stretch, offsets[run] + side, origin)
                self._pg.draw.lines(self._target, DRIVEN_LANE_COLOUR, False, pts, line_w)

    def _dashed(
        self, pts: list, stations: np.ndarray, colour: tuple, line_w: int, period: float = 12.0
    ) -> None:
        pg = self._pg
        on = (np.floor(stations / (period / 2.0)) % 2) == 0
        for i in range(len(pts) - 1):
            if on[i]:
                pg.draw.line(self._target, colour, pts[i], pts[i + 1], line_w)

    def _draw_car(self, info: Mapping[str, Any], origin: tuple) -> None:
        road = self.setup.road
        gx, gy, yaw = road.to_global(
            float(info["station"]), float(info["lateral_offset"]), float(info["heading"])
        )
        rear_overhang, length, half_w = 1.0, 4.6, 0.9
        corners = np.array(
            [
                [-rear_overhang, -half_w],
                [length - rear_overhang, -half_w],
                [length - rear_overhang, half_w],
                [-rear_overhang, half_w],
            ]
        )
        c, s = np.cos(yaw), np.sin(yaw)
        px = gx + corners[:, 0] * c - corners[:, 1] * s
        py = gy + corners[:, 0] * s + corners[:, 1] * c
        pts = [tuple(p) for p in self._to_screen(px, py, origin).tolist()]
        self._pg.draw.polygon(self._target, CAR_COLOUR, pts)

"""Top-down rendering with pygame.

Frames are drawn on an off-screen ``pygame.Surface`` (works headless, with
``SDL_VIDEODRIVER=dummy`` and no display) and returned as ``(H, W, 3)``
uint8 arrays for ``render_mode="rgb_array"``; ``"human"`` blits the same
surface to a window.

The view follows the car with the road tangent pointing up: grey road, white
lane markings (true), faded yellow "ghost" markings where a wrong lane-centre
hypothesis would put the lane, the car, and a HUD with time, speed and
steering.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

__all__ = ["TopDownRenderer", "ROAD_COLOUR", "MARKING_COLOUR", "GHOST_COLOUR", "GRASS_COLOUR"]

GRASS_COLOUR = (46, 120, 52)
ROAD_COLOUR = (90, 90, 96)
MARKING_COLOUR = (245, 245, 245)
GHOST_COLOUR = (200, 185, 90)
CAR_COLOUR = (200, 40, 40)


class TopDownRenderer:
    """Draws an env's info dict; one instance per env."""

    def __init__(self, setup: Any, render_mode: str) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame

        self._pg = pygame
        self.setup = setup
        self.render_mode = render_mode
        rc = setup.config["render"]
        self.width, self.height = int(rc["width"]), int(rc["height"])
        self.ppm = float(rc["pixels_per_metre"])
        self.fps = int(rc["fps"])
        pygame.font.init()
        self.surface = pygame.Surface((self.width, self.height))
        self.font = pygame.font.Font(None, max(14, self.height // 24))
        self.window = None
        self.clock = None

    # -------------------------------------------------------------- drawing
    def _to_screen(self, gx: np.ndarray, gy: np.ndarray, origin: tuple[float, float, float]) -> np.ndarray:
        ox, oy, psi = origin
        dx, dy = gx - ox, gy - oy
        forward = dx * np.cos(psi) + dy * np.sin(psi)
        left = -dx * np.sin(psi) + dy * np.cos(psi)
        sx = self.width / 2 - left * self.ppm
        sy = self.height * 0.7 - forward * self.ppm
        return np.stack([sx, sy], axis=-1)

    def _line_points(self, stations: np.ndarray, offset: float, origin: tuple) -> list[tuple[float, float]]:
        road = self.setup.road
        X, Y, psi = road.pose_at(stations)
        gx = X - np.sin(psi) * offset
        gy = Y + np.cos(psi) * offset
        return [tuple(p) for p in self._to_screen(gx, gy, origin).tolist()]

    def draw(self, info: dict[str, Any]) -> Any:
        """Draw the scene described by an env ``info`` dict onto the off-screen surface."""
        pg = self._pg
        setup = self.setup
        road = setup.road
        width = road.lane_width
        surf = self.surface
        surf.fill(GRASS_COLOUR)
        s0 = float(info["station"])
        behind = self.height * 0.3 / self.ppm + 5.0
        ahead = self.height * 0.7 / self.ppm + 5.0
        stations = np.arange(s0 - behind, s0 + ahead, 1.0)
        X0, Y0, psi0 = road.pose_at(s0)
        origin = (float(X0), float(Y0), float(psi0))
        cfg = setup.config["road"]
        right_edge = -width / 2 - cfg["lanes_right"] * width
        left_edge = width / 2 + cfg["lanes_left"] * width
        left_pts = self._line_points(stations, left_edge, origin)
        right_pts = self._line_points(stations, right_edge, origin)
        pg.draw.polygon(surf, ROAD_COLOUR, left_pts + right_pts[::-1])
        line_w = max(1, int(round(0.15 * self.ppm)))
        # true markings: solid edges, dashed lane dividers
        n_lines = cfg["lanes_left"] + cfg["lanes_right"] + 1
        for i in range(n_lines + 1):
            offset = right_edge + i * width
            pts = self._line_points(stations, offset, origin)
            if i in (0, n_lines):
                pg.draw.lines(surf, MARKING_COLOUR, False, pts, line_w)
            else:
                self._dashed(pts, stations, MARKING_COLOUR, line_w)
        # ghost markings where each non-zero hypothesis puts the lane (camera reads y + b)
        for b in setup.hypotheses:
            if b == 0.0:
                continue
            for side in (-0.5, 0.5):
                pts = self._line_points(stations, -b + side * width, origin)
                self._dashed(pts, stations, GHOST_COLOUR, max(1, line_w // 2), period=6.0)
        self._draw_car(info, origin)
        self._draw_hud(info)
        return surf

    def _dashed(self, pts: list, stations: np.ndarray, colour: tuple, line_w: int, period: float = 12.0) -> None:
        pg = self._pg
        on = (np.floor(stations / (period / 2.0)) % 2) == 0
        for i in range(len(pts) - 1):
            if on[i]:
                pg.draw.line(self.surface, colour, pts[i], pts[i + 1], line_w)

    def _draw_car(self, info: dict[str, Any], origin: tuple) -> None:
        road = self.setup.road
        gx, gy, yaw = road.to_global(float(info["station"]), float(info["lateral_offset"]), float(info["heading"]))
        rear_overhang, length, half_w = 1.0, 4.6, 0.9
        corners = np.array(
            [[-rear_overhang, -half_w], [length - rear_overhang, -half_w],
             [length - rear_overhang, half_w], [-rear_overhang, half_w]]
        )
        c, s = np.cos(yaw), np.sin(yaw)
        px = gx + corners[:, 0] * c - corners[:, 1] * s
        py = gy + corners[:, 0] * s + corners[:, 1] * c
        pts = [tuple(p) for p in self._to_screen(px, py, origin).tolist()]
        self._pg.draw.polygon(self.surface, CAR_COLOUR, pts)

    def _draw_hud(self, info: dict[str, Any]) -> None:
        text = (
            f"t {info['time']:5.2f} s   v {info['speed']:5.1f} m/s   "
            f"delta {np.degrees(info['steering']):+6.2f} deg   y {info['lateral_offset']:+5.2f} m"
        )
        img = self.font.render(text, True, (255, 255, 255), (0, 0, 0))
        self.surface.blit(img, (8, 8))

    # ----------------------------------------------------------- output
    def render(self, info: dict[str, Any]) -> np.ndarray | None:
        surf = self.draw(info)
        if self.render_mode == "rgb_array":
            return np.transpose(self._pg.surfarray.array3d(surf), (1, 0, 2)).copy()
        pg = self._pg
        if self.window is None:
            pg.display.init()
            self.window = pg.display.set_mode((self.width, self.height))
            pg.display.set_caption("hasa-env lane keeping")
            self.clock = pg.time.Clock()
        self.window.blit(surf, (0, 0))
        pg.event.pump()
        pg.display.flip()
        self.clock.tick(self.fps)
        return None

    def close(self) -> None:
        if self.window is not None:
            self._pg.display.quit()
            self.window = None

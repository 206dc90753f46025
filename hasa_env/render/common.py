"""What both views share: colours, the HUD, hypothesis weights, frames, the human window,
and the renderer's frame of set-up, ``draw``, ``render`` and ``close`` (:class:`SceneRenderer`).

Frames are drawn on an off-screen ``pygame.Surface`` (works headless, with
``SDL_VIDEODRIVER=dummy`` and no display) and returned as ``(H, W, 3)``
uint8 arrays for ``render_mode="rgb_array"``; ``"human"`` blits the same
surface to a window (:class:`HumanWindow`), paced by the *simulation* clock:
each call sleeps until the wall clock has caught up with ``info["time"]``
(so 100 Hz simulation runs in real time) and a frame is only drawn when one
is due at the configured ``render.fps``; the frame rate never changes the
physics.

Both views draw the same HUD (:class:`Hud`): time, speed, steering angle,
and, when an estimator runs alongside, the live weight of every lane
hypothesis. pygame is imported by the functions that draw, never at import.
"""

from __future__ import annotations

import math
import os
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from hasa_env.render.options import HUD_ITEMS, ViewOptions
from hasa_env.sim.setup import EnvSetup

__all__ = [
    "Hud",
    "HumanWindow",
    "SceneRenderer",
    "surface_to_array",
    "resolve_weights",
    "WeightSource",
    "ROAD_COLOUR",
    "MARKING_COLOUR",
    "GHOST_COLOUR",
    "GRASS_COLOUR",
    "CAR_COLOUR",
    "HYPOTHESIS_COLOURS",
    "INFO_WEIGHT_KEYS",
    "DRIVEN_LANE_COLOUR",
    "DRIVEN_LANE_TOLERANCE",
    "driven_lane_runs",
    "ghost_centres",
    "DEFAULT_STEERING_RATIO",
]

GRASS_COLOUR = (46, 120, 52)
ROAD_COLOUR = (90, 90, 96)
MARKING_COLOUR = (245, 245, 245)
GHOST_COLOUR = (200, 185, 90)
CAR_COLOUR = (200, 40, 40)
DRIVEN_LANE_COLOUR = (255, 200, 0)
"""The driven lane's lines where it leaves the marked lane (``road.lane_shifts``): the
yellow of temporary construction-zone markings."""
DRIVEN_LANE_TOLERANCE = 0.01
"""The driven lane's lines are drawn where its centre is more than this (m) off the marked
lane's (:func:`driven_lane_runs`)."""
DEFAULT_STEERING_RATIO = 15.0
"""Steering-wheel / road-wheel angle the HUD assumes where no wheel profile gives one (the
keyboard, an env's own render): a car's, the paper's and the shipped G29 profile's."""
HUD_TEXT_COLOUR = (255, 255, 255)
HYPOTHESIS_COLOURS = (
    (235, 235, 235),
    GHOST_COLOUR,
    (90, 190, 220),
    (220, 120, 200),
    (150, 220, 110),
    (240, 150, 80),
)
"""Colour of hypothesis i (cycled): HUD weight bars; index 0 is usually the true-lane one."""

WeightSource = Mapping[float, float] | Sequence[float] | Callable[[Mapping[str, Any]], Any] | None
"""Where the HUD takes hypothesis weights from: a dict bias (m) -> weight, a
sequence with one weight per ``markings.hypotheses`` entry, a callable
``info -> either of those``, or None (look in ``info``, see :func:`resolve_weights`)."""

INFO_WEIGHT_KEYS = ("estimate_weights", "estimator_weights", "hypothesis_weights")
"""``info`` keys searched, in order, for hypothesis weights when none are passed explicitly
(``estimate_weights``: what an estimator's info wrapper adds, one weight per
``markings.hypotheses`` entry)."""


def surface_to_array(surface: Any) -> np.ndarray:
    """An ``(H, W, 3)`` uint8 RGB copy of a pygame surface (fast path via ``image.tobytes``)."""
    import pygame  # pygame: loaded only when drawing, never on headless paths

    width, height = surface.get_size()
    tobytes = getattr(pygame.image, "tobytes", None) or pygame.image.tostring
    data = tobytes(surface, "RGB")
    return np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3).copy()


def resolve_weights(
    source: WeightSource, info: Mapping[str, Any], hypotheses: Sequence[float]
) -> list[tuple[float, float]] | None:
    """Hypothesis weights to show as ``[(bias m, weight), ...]``, or None if there are none.

    ``source`` may be a dict ``{bias: weight}``, a sequence of weights (one per
    entry of ``hypotheses``, same order), a callable ``info -> dict or
    sequence``, or None; with None the first present key of
    :data:`INFO_WEIGHT_KEYS` in ``info`` is used (a sequence, aligned with
    ``info["estimator_hypotheses"]`` when present, else with ``hypotheses``).
    Weights are shown as given (no renormalisation).

    Raises:
        ValueError: a sequence whose length matches neither the hypotheses nor
            the biases given with it.
    """
    biases: Sequence[float] = hypotheses
    if source is None:
        for key in INFO_WEIGHT_KEYS:
            if key in info and info[key] is not None:
                source = info[key]
                if "estimator_hypotheses" in info:
                    biases = [float(b) for b in np.ravel(info["estimator_hypotheses"])]
                break
        else:
            return None
    elif callable(source):
        source = source(info)
        if source is None:
            return None
    if isinstance(source, Mapping):
        return [(float(b), float(w)) for b, w in source.items()]
    values = [float(w) for w in np.ravel(np.asarray(source, dtype=np.float64))]
    if len(values) != len(biases):
        raise ValueError(
            f"got {len(values)} hypothesis weights for {len(biases)} hypotheses {list(biases)}; "
            "pass one weight per hypothesis or a dict {bias_m: weight}"
        )
    return list(zip((float(b) for b in biases), values, strict=True))


class Hud:
    """Heads-up display: time, speed, steering angle, hypothesis weights, a message.

    Args:
        pygame_module: the imported ``pygame``.
        height: frame height (px); the font scales with it.
        time_limit: episode length (s) shown after the time, or None.
        steering_ratio: steering-wheel angle / road-wheel angle of the steering line,
            which shows the steering-wheel angle (what a person turns) and the road
            wheel's; None: :data:`DEFAULT_STEERING_RATIO`.
        items: which items to show (:data:`hasa_env.render.options.HUD_ITEMS`: ``time``,
            ``speed``, ``steering``, ``weights``); empty: no panel, only messages.
    """

    def __init__(
        self,
        pygame_module: Any,
        height: int,
        time_limit: float | None = None,
        steering_ratio: float | None = None,
        items: Sequence[str] = HUD_ITEMS,
    ) -> None:
        self._pg = pygame_module
        self.items = tuple(items)
        self._pg.font.init()
        self.font = self._pg.font.Font(None, max(16, height // 26))
        self.big_font = self._pg.font.Font(None, max(32, height // 6))
        self.time_limit = time_limit
        self.steering_ratio = steering_ratio
        self._panel_cache: dict[tuple[int, int], Any] = {}

    def lines(self, info: Mapping[str, Any]) -> list[str]:
        """The text lines of the HUD's items (without weights)."""
        out = []
        if "time" in self.items:
            limit = f" / {self.time_limit:.0f}" if self.time_limit else ""
            out.append(f"time {float(info['time']):6.2f}{limit} s")
        if "speed" in self.items:
            v = float(info["speed"])
            out.append(f"speed {v:5.2f} m/s  ({v * 3.6:5.1f} km/h)")
        if "steering" in self.items:
            # the angle a person turns first: the road wheel's is 15 times smaller
            delta_deg = math.degrees(float(info["steering"]))
            ratio = self.steering_ratio or DEFAULT_STEERING_RATIO
            out.append(f"wheel {delta_deg * ratio:+6.1f} deg (road {delta_deg:+.2f})")
        return out

    def _panel(self, width: int, height: int) -> Any:
        key = (width, height)
        panel = self._panel_cache.get(key)
        if panel is None:
            panel = self._pg.Surface(key, self._pg.SRCALPHA)
            panel.fill((0, 0, 0, 150))
            self._panel_cache[key] = panel
        return panel

    def draw(
        self,
        surface: Any,
        info: Mapping[str, Any],
        weights: list[tuple[float, float]] | None = None,
        message: str | None = None,
        hypotheses: Sequence[float] = (),
    ) -> None:
        """Draw the HUD onto ``surface`` (top-left panel; message centred).

        ``weights`` are drawn only when the ``weights`` item is shown; with no
        item to show there is no panel, and ``message`` is still drawn.
        """
        pg = self._pg
        if "weights" not in self.items:
            weights = None
        texts = [self.font.render(s, True, HUD_TEXT_COLOUR) for s in self.lines(info)]
        if not texts and not weights:
            if message:
                self.draw_message(surface, message)
            return
        line_h = self.font.get_linesize()
        bar_w = max(80, surface.get_width() // 8)
        label_w = 0
        labels = []
        if weights:
            for b, w in weights:
                img = self.font.render(f"b {b:+5.2f} m {w:5.3f}", True, HUD_TEXT_COLOUR)
                labels.append(img)
                label_w = max(label_w, img.get_width())
        n_lines = len(texts) + (1 + len(weights) if weights else 0)
        width = max([t.get_width() for t in texts] + [label_w + bar_w + 18]) + 16
        height = n_lines * line_h + 12
        surface.blit(self._panel(width, height), (6, 6))
        y = 12
        for img in texts:
            surface.blit(img, (14, y))
            y += line_h
        if weights:
            surface.blit(
                self.font.render("lane hypotheses (estimator)", True, HUD_TEXT_COLOUR), (14, y)
            )
            y += line_h
            for (b, w), img in zip(weights, labels, strict=True):
                index = _hypothesis_index(b, hypotheses)
                colour = HYPOTHESIS_COLOURS[index % len(HYPOTHESIS_COLOURS)]
                surface.blit(img, (14, y))
                x0 = 14 + label_w + 8
                bar_h = max(4, line_h - 6)
                pg.draw.rect(surface, (60, 60, 60), (x0, y + 2, bar_w, bar_h))
                fill = int(round(bar_w * min(max(w, 0.0), 1.0)))
                if fill > 0:
                    pg.draw.rect(surface, colour, (x0, y + 2, fill, bar_h))
                y += line_h
        if message:
            self.draw_message(surface, message)

    def draw_message(self, surface: Any, message: str) -> None:
        """Centre ``message`` (lines split on newlines; a short first line is drawn large)."""
        lines = message.split("\n")
        big = len(lines[0]) <= 12
        images = [
            (self.big_font if (i == 0 and big) else self.font).render(s, True, HUD_TEXT_COLOUR)
            for i, s in enumerate(lines)
        ]
        total_h = sum(img.get_height() + 6 for img in images)
        width = max(img.get_width() for img in images) + 40
        sw, sh = surface.get_size()
        top = (sh - total_h) // 2
        surface.blit(self._panel(width, total_h + 20), ((sw - width) // 2, top - 10))
        y = top
        for img in images:
            surface.blit(img, ((sw - img.get_width()) // 2, y))
            y += img.get_height() + 6


def driven_lane_runs(offsets: np.ndarray) -> list[slice]:
    """The stretches of samples at which the driven lane's lines are drawn.

    ``offsets`` (m) are the episode's driven lane's centre
    (:meth:`hasa_env.sim.road.Road.driven_offset` with ``info["bias"]``)
    at increasing stations; a run is a contiguous stretch where ``|offset|`` exceeds
    :data:`DRIVEN_LANE_TOLERANCE`, widened by one sample at each end so the lines leave
    the white markings where the shift starts and rejoin them where it ends. Runs of
    fewer than two samples are dropped.
    """
    away = np.abs(np.asarray(offsets, dtype=np.float64)) > DRIVEN_LANE_TOLERANCE
    if not away.any():
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[False], away, [False]]).astype(np.int8)))
    n = away.size
    runs = []
    for start, stop in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
        run = slice(max(start - 1, 0), min(stop + 1, n))
        if run.stop - run.start >= 2:
            runs.append(run)
    return runs


def ghost_centres(hypotheses: Sequence[float], bias: Any) -> list[float]:
    """Where each wrong hypothesis puts the lane centre, in true-lane coordinates (m, left
    positive), for an episode whose true camera bias is ``bias`` (``info["bias"]``).

    The camera reads ``y + bias``; under hypothesis ``b_i`` the car's offset is read as
    ``y + bias - b_i``, so that hypothesis's lane centre lies at ``y = b_i - bias``
    (docs/design.md §3.5). Every hypothesis but the true one is a ghost. ``bias`` None (an
    ``info`` without it) is taken as 0.
    """
    true = 0.0 if bias is None else float(bias)
    return [float(h) - true for h in hypotheses if abs(float(h) - true) > 1e-9]


def _hypothesis_index(bias: float, hypotheses: Sequence[float]) -> int:
    for i, h in enumerate(hypotheses):
        if abs(h - bias) < 1e-9:
            return i
    return len(hypotheses)


class HumanWindow:
    """A window shown in ``render_mode="human"``, paced by the simulation clock.

    :meth:`show` sleeps until the wall-clock time since the episode started
    (``info["time"] == 0``) reaches ``info["time"]`` (real-time simulation,
    the physics step size never depends on the frame rate) and blits a new
    frame only when ``1 / fps`` s have passed since the last one. If the
    simulation falls behind the wall clock it runs as fast as it can.
    """

    def __init__(self, pygame_module: Any, size: tuple[int, int], fps: int, caption: str) -> None:
        self._pg = pygame_module
        self.size = size
        self.frame_interval = 1.0 / float(fps)
        self.caption = caption
        self.window: Any = None  # the pygame display surface, once opened
        self._anchor: float | None = None
        self._last_frame = -math.inf

    def frame_due(self, sim_time: float) -> bool:
        """Pace to ``sim_time`` (s) and say whether a frame should be drawn now."""
        now = time.perf_counter()
        if self._anchor is None or sim_time == 0.0:
            self._anchor = now - sim_time
            self._last_frame = -math.inf
        wait = self._anchor + sim_time - now
        if wait > 0.0:
            time.sleep(wait)
            now = time.perf_counter()
        elif wait < -0.25:  # far behind (e.g. paused in a debugger): re-anchor, do not sprint
            self._anchor = now - sim_time
        return now - self._last_frame >= self.frame_interval or sim_time == 0.0

    def show(self, surface: Any) -> None:
        """Blit ``surface`` to the window (opened on first use) and flip."""
        pg = self._pg
        if self.window is None:
            pg.display.init()
            self.window = pg.display.set_mode(self.size)
            pg.display.set_caption(self.caption)
        self.window.blit(surface, (0, 0))
        pg.event.pump()
        pg.display.flip()
        self._last_frame = time.perf_counter()

    def close(self) -> None:
        if self.window is not None:
            self._pg.display.quit()
            self.window = None


class SceneRenderer(ABC):
    """An env's view: its off-screen surface, the HUD and the human window; one per env.

    A view draws the scene in :meth:`_draw_scene`; :meth:`draw` puts the HUD over it,
    :meth:`render` returns or shows the frame.

    Args:
        setup: the env's :class:`hasa_env.sim.setup.EnvSetup` (road, hypotheses, config).
        render_mode: ``"rgb_array"`` (frames as arrays) or ``"human"`` (a window).
        size: frame (width, height) in pixels.
        caption: the human window's title.
        weights: where the HUD takes hypothesis weights from (:data:`WeightSource`);
            default: look in ``info``.
        steering_ratio: steering-wheel / road-wheel angle, shown in the HUD if given.
        options: what to draw (:class:`~hasa_env.render.options.ViewOptions`); default:
            everything (ghost markings, full HUD), no bonnet or texture.
    """

    def __init__(
        self,
        setup: EnvSetup,
        render_mode: str,
        size: tuple[int, int],
        caption: str,
        *,
        weights: WeightSource = None,
        steering_ratio: float | None = None,
        options: ViewOptions | None = None,
    ) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame  # pygame: loaded only when drawing, never on headless paths

        self._pg = pygame
        self.setup = setup
        self.render_mode = render_mode
        self.width, self.height = size
        self.fps = int(setup.config["render"]["fps"])
        self.weights = weights
        self.options = options if options is not None else ViewOptions()
        self.surface = pygame.Surface((self.width, self.height))
        self._target = self.surface
        self.hud = Hud(
            pygame, self.height, setup.config["time_limit"], steering_ratio, self.options.hud
        )
        self._window = HumanWindow(pygame, (self.width, self.height), self.fps, caption)

    @abstractmethod
    def _draw_scene(self, surface: Any, info: Mapping[str, Any]) -> None:
        """Draw the view of the scene ``info`` describes onto ``surface`` (no HUD)."""

    def draw(
        self,
        info: Mapping[str, Any],
        weights: WeightSource = None,
        message: str | None = None,
        target: Any = None,
    ) -> Any:
        """Draw the scene described by an env ``info`` dict, with the HUD over it.

        Args:
            info: the env's info (keys of :data:`hasa_env.sim.setup.INFO_KEYS`).
            weights: hypothesis weights for the HUD (default: the constructor's).
            message: text centred over the scene (e.g. a countdown), or None.
            target: surface to draw on (same size); default the off-screen surface.

        Returns:
            The surface drawn on.
        """
        surface = self.surface if target is None else target
        self._target = surface
        self._draw_scene(surface, info)
        hypotheses = self.setup.hypotheses
        shown = resolve_weights(self.weights if weights is None else weights, info, hypotheses)
        self.hud.draw(surface, info, shown, message, hypotheses)
        return surface

    def render(self, info: Mapping[str, Any], weights: WeightSource = None) -> np.ndarray | None:
        """``rgb_array``: the (H, W, 3) uint8 frame; ``human``: show it, paced by sim time."""
        if self.render_mode == "rgb_array":
            return surface_to_array(self.draw(info, weights))
        if self._window.frame_due(float(info["time"])):
            self._window.show(self.draw(info, weights))
        return None

    def close(self) -> None:
        self._window.close()

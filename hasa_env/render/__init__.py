"""Rendering with pygame: the top-down view and the driver's-eye view.

Two views exist, chosen with ``config["render"]["view"]`` (see
:func:`make_renderer`):

- ``"top_down"`` (:class:`~hasa_env.render.top_down.TopDownRenderer`): the
  map view following the car;
- ``"driver"`` (:class:`~hasa_env.render.driver_view.DriverViewRenderer`):
  the first-person perspective of the road ahead.

Both are a :class:`~hasa_env.render.common.SceneRenderer` and draw its HUD;
:class:`~hasa_env.render.options.ViewOptions` says what they show (ghost
markings, HUD items, and in the driver's view a bonnet and road texture:
:meth:`ViewOptions.participant` is a study participant's view). Importing
this package does not import pygame; the renderers do when they are created.
"""

from __future__ import annotations

from hasa_env.render.common import (
    GHOST_COLOUR,
    HYPOTHESIS_COLOURS,
    Hud,
    HumanWindow,
    SceneRenderer,
    WeightSource,
    resolve_weights,
    surface_to_array,
)
from hasa_env.render.driver_view import DriverViewRenderer
from hasa_env.render.options import HUD_ITEMS, ViewOptions
from hasa_env.render.top_down import TopDownRenderer
from hasa_env.sim.setup import EnvSetup

__all__ = [
    "DriverViewRenderer",
    "GHOST_COLOUR",
    "HUD_ITEMS",
    "HYPOTHESIS_COLOURS",
    "Hud",
    "HumanWindow",
    "SceneRenderer",
    "TopDownRenderer",
    "ViewOptions",
    "WeightSource",
    "make_renderer",
    "resolve_weights",
    "surface_to_array",
]


def make_renderer(
    setup: EnvSetup,
    render_mode: str,
    *,
    view: str | None = None,
    weights: WeightSource = None,
    steering_ratio: float | None = None,
    options: ViewOptions | None = None,
) -> SceneRenderer:
    """The renderer of ``view`` (default ``setup.config["render"]["view"]``) for an env set-up.

    ``options`` (:class:`ViewOptions`, default: everything shown) says what it
    draws. Returns a :class:`TopDownRenderer` or a :class:`DriverViewRenderer`;
    both are a :class:`SceneRenderer`, with ``draw(info, weights, message, target)``,
    ``render(info, weights)`` and ``close()``.
    """
    view = setup.config["render"]["view"] if view is None else view
    if view == "top_down":
        return TopDownRenderer(
            setup, render_mode, weights=weights, steering_ratio=steering_ratio, options=options
        )
    if view == "driver":
        return DriverViewRenderer(
            setup, render_mode, weights=weights, steering_ratio=steering_ratio, options=options
        )
    raise ValueError(f"unknown view {view!r}; allowed: 'top_down', 'driver'")

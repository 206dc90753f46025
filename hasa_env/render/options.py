"""What a view shows: :class:`ViewOptions` (ghost markings, HUD items, bonnet, road texture).

The env's renders show everything that helps a developer (ghost markings of
the wrong lane hypotheses, the full HUD). A participant of a study should
see an ordinary road: in the paper's protocol the marking ambiguity exists
for the estimator only. :meth:`ViewOptions.participant` is that view: no
ghost markings, no HUD (messages such as instructions and the countdown
are still shown), a bonnet and dashboard silhouette, and transverse bands
on the road and the grass that stream past and give a sense of speed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["HUD_ITEMS", "ViewOptions"]

HUD_ITEMS = ("time", "speed", "steering", "weights")
"""HUD items: elapsed time, speed, steering angle, the estimator's lane-hypothesis weights."""


@dataclass(frozen=True)
class ViewOptions:
    """What the driver's view (and, where it applies, the top-down view) draws.

    Attributes:
        ghosts: draw the faded ghost markings (and the ghost near/far rings)
            where the wrong lane hypotheses put the lane.
        hud: HUD items to show, a subset of :data:`HUD_ITEMS` in any order;
            empty: no HUD panel (messages are still drawn).
        bonnet: driver's view only: a bonnet and dashboard silhouette at the
            bottom of the frame (the road is visible from 4 m ahead of the eye).
        road_texture: driver's view only: lighter transverse bands on the road
            (4 m every 8 m) and on the grass (10 m every 20 m) that stream past
            at the car's speed.
    """

    ghosts: bool = True
    hud: tuple[str, ...] = HUD_ITEMS
    bonnet: bool = False
    road_texture: bool = False

    def __post_init__(self) -> None:
        for name in ("ghosts", "bonnet", "road_texture"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(
                    f"view option '{name}' must be true or false, got {getattr(self, name)!r}"
                )
        if isinstance(self.hud, str) or not isinstance(self.hud, Sequence):
            raise ValueError(
                f"view option 'hud' must be a list of items from {', '.join(HUD_ITEMS)}, "
                f"got {self.hud!r}"
            )
        items = tuple(self.hud)
        for item in items:
            if item not in HUD_ITEMS:
                raise ValueError(
                    f"view option 'hud' has the unknown item {item!r}; allowed: "
                    f"{', '.join(HUD_ITEMS)}"
                )
        if len(set(items)) != len(items):
            raise ValueError(f"view option 'hud' lists an item twice: {list(items)}")
        object.__setattr__(self, "hud", items)

    @classmethod
    def participant(cls) -> ViewOptions:
        """A study participant's view: no ghosts, no HUD, bonnet, road texture."""
        return cls(ghosts=False, hud=(), bonnet=True, road_texture=True)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ViewOptions:
        """Options from a mapping with any of the attribute names (unknown keys are refused)."""
        unknown = sorted(set(data) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(
                f"unknown view option {unknown[0]!r}; allowed: "
                f"{', '.join(cls.__dataclass_fields__)}"
            )
        values = dict(data)
        if "hud" in values and isinstance(values["hud"], list):
            values["hud"] = tuple(values["hud"])
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (for session files and sidecar metadata)."""
        return {
            "ghosts": self.ghosts,
            "hud": list(self.hud),
            "bonnet": self.bonnet,
            "road_texture": self.road_texture,
        }

"""Variants of a population with its loop ranges scaled, for trying a recalibration.

:class:`LoopScales` (factors on the lateral-loop bandwidth, the two-point damping, the LQR
velocity weight and the command noise) and :func:`population_variant` (a copy of a population
with those ranges scaled and the same drivers otherwise, registered in
:data:`hasa_env.drivers.POPULATIONS` while in use), behind the ``--*-scale`` options of
``python -m benchmarks.population_check`` (docs/design.md §7.8).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

from hasa_env.drivers import POPULATIONS

__all__ = ["LoopScales", "population_variant"]


@dataclass(frozen=True)
class LoopScales:
    """Factors on a population's ranges, for trying a recalibration without changing it.

    Attributes:
        bandwidth: the lateral-loop bandwidth of every archetype.
        damping: the two-point drivers' loop damping.
        velocity_weight: the preview and intermittent drivers' LQR velocity weight.
        command: the command noise before the neuromuscular lag (``command_scale``).
    """

    bandwidth: float = 1.0
    damping: float = 1.0
    velocity_weight: float = 1.0
    command: float = 1.0

    def __post_init__(self) -> None:
        for name in ("bandwidth", "damping", "velocity_weight", "command"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"LoopScales.{name} must be a finite factor > 0, got {value!r}")

    @property
    def is_identity(self) -> bool:
        return self == LoopScales()


def _scaled(bounds: Any, factor: float) -> Any:
    return replace(bounds, low=bounds.low * factor, high=bounds.high * factor)


@contextlib.contextmanager
def population_variant(name: str, scales: LoopScales) -> Iterator[str]:
    """The name of a copy of population ``name`` with its ranges scaled (the same drivers
    otherwise: same seed key), registered in ``POPULATIONS`` while in use."""
    if scales.is_identity:
        yield name
        return
    spec = POPULATIONS[name]
    variant = (
        f"{name}@bandwidth={scales.bandwidth:g},damping={scales.damping:g},"
        f"velocity_weight={scales.velocity_weight:g},command={scales.command:g}"
    )
    changes: dict[str, Any] = {
        "two_point": replace(
            spec.two_point,
            bandwidth=_scaled(spec.two_point.bandwidth, scales.bandwidth),
            damping=_scaled(spec.two_point.damping, scales.damping),
        ),
        "command_scale": spec.command_scale * scales.command,
        "seed_key": spec.seed_key or name,
    }
    for archetype in ("preview", "intermittent"):
        ranges = getattr(spec, archetype)
        if ranges is not None:
            changes[archetype] = replace(
                ranges,
                bandwidth=_scaled(ranges.bandwidth, scales.bandwidth),
                velocity_weight=_scaled(ranges.velocity_weight, scales.velocity_weight),
            )
    POPULATIONS[variant] = replace(spec, **changes)
    try:
        yield variant
    finally:
        del POPULATIONS[variant]

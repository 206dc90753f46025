"""The synthetic drivers' archetypes: parameters -> driver, batch and JSON.

============  ================================================  =====================
archetype     parameters                                        driver
============  ================================================  =====================
two-point     :class:`~hasa_env.drivers.two_point.TwoPointParams`  :class:`~hasa_env.drivers.two_point.TwoPointDriver`
preview       :class:`~hasa_env.drivers.preview.PreviewParams`   :class:`~hasa_env.drivers.preview.PreviewDriver`
intermittent  :class:`~hasa_env.drivers.intermittent.IntermittentParams`  :class:`~hasa_env.drivers.intermittent.IntermittentDriver`
noisy-corrections  :class:`~hasa_env.drivers.noisy_corrections.NoisyCorrectionsParams`  :class:`~hasa_env.drivers.noisy_corrections.NoisyCorrectionsDriver`
============  ================================================  =====================

:func:`make_driver` turns parameters of any archetype into its driver,
:func:`params_from_dict` reads back any ``params.to_dict()`` (the
``"archetype"`` field says which; dicts without it are two-point, as written
before the other archetypes existed), and :func:`~hasa_env.drivers.human.human_batch` vectorizes
a mixed list of parameters (one batch per archetype). :class:`SyntheticDriver`
drives parameters of any archetype.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hasa_env.drivers import intermittent, noisy_corrections, preview, two_point
from hasa_env.drivers.base import Driver
from hasa_env.drivers.human import HumanBatch, HumanDriver, human_batch

__all__ = [
    "ARCHETYPES",
    "Archetype",
    "HumanParams",
    "SyntheticDriver",
    "archetype_of",
    "human_batch",
    "make_driver",
    "params_from_dict",
]

HumanParams = (
    two_point.TwoPointParams
    | preview.PreviewParams
    | intermittent.IntermittentParams
    | noisy_corrections.NoisyCorrectionsParams
)
"""Parameters of any synthetic driver archetype."""


@dataclass(frozen=True)
class Archetype:
    """One kind of synthetic driver: its parameters, single-car driver and batch classes."""

    name: str
    params: type[HumanParams]
    driver: type[HumanDriver]
    batch: type[HumanBatch]


ARCHETYPES: dict[str, Archetype] = {
    a.name: a
    for a in (
        Archetype(
            two_point.ARCHETYPE,
            two_point.TwoPointParams,
            two_point.TwoPointDriver,
            two_point.TwoPointBatch,
        ),
        Archetype(
            preview.ARCHETYPE, preview.PreviewParams, preview.PreviewDriver, preview.PreviewBatch
        ),  # fmt: skip
        Archetype(
            intermittent.ARCHETYPE,
            intermittent.IntermittentParams,
            intermittent.IntermittentDriver,
            intermittent.IntermittentBatch,
        ),
        Archetype(
            noisy_corrections.ARCHETYPE,
            noisy_corrections.NoisyCorrectionsParams,
            noisy_corrections.NoisyCorrectionsDriver,
            noisy_corrections.NoisyCorrectionsBatch,
        ),
    )
}
"""The archetypes by name: "two-point", "preview", "intermittent", "noisy-corrections"."""


class SyntheticDriver(HumanDriver):
    """A synthetic human driver of any archetype, seeded and reproducible.

    ``SyntheticDriver(params)`` drives parameters of any archetype:
    :class:`~hasa_env.drivers.two_point.TwoPointParams` (two-point PI),
    :class:`~hasa_env.drivers.preview.PreviewParams`,
    :class:`~hasa_env.drivers.intermittent.IntermittentParams` or
    :class:`~hasa_env.drivers.noisy_corrections.NoisyCorrectionsParams`, so every
    member of a :func:`~hasa_env.drivers.populations.population` is a
    ``SyntheticDriver``. ``reset(seed, dt=0.01)`` then ``act(info, road)``
    each env step. Runs are identical whether the driver acts alone or
    vectorized with others (:meth:`make_batch`, one part per archetype).
    """

    accepts = tuple(a.params for a in ARCHETYPES.values())


def archetype_of(params: Any) -> Archetype:
    """The :class:`Archetype` of a parameter object (TypeError for anything else)."""
    for archetype in ARCHETYPES.values():
        if type(params) is archetype.params:
            return archetype
    allowed = ", ".join(a.params.__name__ for a in ARCHETYPES.values())
    raise TypeError(
        f"not synthetic driver parameters: {type(params).__name__} (allowed: {allowed})"
    )


def make_driver(params: HumanParams) -> Driver:
    """The driver of ``params`` (any archetype): TwoPointDriver, PreviewDriver,
    IntermittentDriver or NoisyCorrectionsDriver."""
    return archetype_of(params).driver(params)


def params_from_dict(data: Mapping[str, Any]) -> HumanParams:
    """Parameters of any archetype from their ``to_dict()`` (no "archetype": two-point)."""
    name = data.get("archetype", two_point.ARCHETYPE)
    try:
        archetype = ARCHETYPES[name]
    except KeyError:
        raise ValueError(
            f"unknown driver archetype {name!r}; allowed: {', '.join(ARCHETYPES)}"
        ) from None
    return archetype.params.from_dict(data)

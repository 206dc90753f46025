"""Named scenarios: road, markings and drivers under which a lane estimate is scored.

A scenario is the env config it sets (under the user's own keys: ``gym.make(id,
config={"scenario": "lane_shift"})``, ``hasa-bench paper --scenario lane_shift``, a
study file's ``[runs] scenario = ...``) and, for the drivers, the lateral
offset they prefer to keep (:func:`scenario_drivers`). docs/design.md §14 says why each
exists; what they need from the env:

- ``road.lane_shifts``: the lane the human drives in moves sideways relative to the
  markings the camera reads (:meth:`hasa_env.sim.road.Road.driven_offset`); synthetic
  drivers follow it, the camera and a lane estimate do not know it. ``"toward":
  "other_hypothesis"`` points a shift toward where the episode's nearest other
  hypothesis puts the lane centre, so it is equally hard under every true bias;
- ``markings.hypotheses``: the camera biases the estimator must choose between;
- ``initial_state``: where the car starts;
- drivers' ``preferred_offset`` (m, left positive): the offset from the driven lane's
  centre a driver keeps.

=====================  ===================================================================
scenario               what changes (everything else: the paper's protocol)
=====================  ===================================================================
paper                  nothing: hypotheses [0, -1.8] m, start 0.5 m right of the centre
lane_shift             a construction-zone shift: the driven lane moves 1.8 m over 65 m
                       from station 150 m toward where the other hypothesis puts the
                       lane centre (onto the ghost centre, under either true bias); the
                       old markings carry straight on; a lane on either side
late_ambiguity         the ambiguity starts at speed (25 m/s) with the car halfway
                       between the true centre and the ghost's, drifting toward the
                       ghost at 0.02 rad
close_hypotheses       hypotheses 0.3 m apart (worn paint, tar seams); start centred
                       +- 0.25 m (std)
off_centre_drivers     each driver keeps a preferred offset of 0.2-0.5 m, left or right;
                       hypotheses [0, -0.8] m (a tar seam)
lane_change            the driver moves to the neighbouring lane (3.6 m) on the other
                       hypothesis's side over 80 m from station 120 m and back over 80 m
                       from station 300 m (an overtaking); a lane on either side
=====================  ===================================================================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

__all__ = ["SCENARIOS", "Scenario", "scenario_drivers", "scenario_names", "scenario_spec"]

P = TypeVar("P")

LATE_AMBIGUITY_DRIFT = 0.02
"""Heading (rad) toward the ghost centre at the start of ``late_ambiguity``: 0.5 m/s of
lateral drift at 25 m/s, the lateral speed of an unintended lane departure (docs/design.md
§14.8)."""


@dataclass(frozen=True)
class Scenario:
    """One named scenario.

    Attributes:
        name: its name (the ``scenario`` config key).
        summary: what changes, in one line.
        why: why it exists: what a steering-free estimator cannot do in it.
        config: the env config keys it sets (deep-merged under the user's).
        preferred_offset: (low, high) of the drivers' preferred lateral offset
            magnitude (m); each driver's sign and size are drawn from the population
            seed (:func:`scenario_drivers`). (0, 0): drivers keep to the centre.
    """

    name: str
    summary: str
    why: str
    config: Mapping[str, Any] = field(default_factory=dict)
    preferred_offset: tuple[float, float] = (0.0, 0.0)


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario(
            "paper",
            "the paper's protocol: hypotheses [0, -1.8] m, start 0.5 m right of the centre",
            "the reference; a lane-centring prior alone solves it (README, 'The scenarios').",
        ),
        Scenario(
            "lane_shift",
            "construction zone: the driven lane moves 1.8 m over 65 m from 150 m, toward the "
            "other hypothesis",
            "after the shift the car sits where the other hypothesis puts the lane centre, "
            "whichever hypothesis is true: a prior that the car keeps to the marked lane's "
            "centre picks the wrong one. (Shifted 1.8 m left, as first designed, that held "
            "only when the true bias was -1.8 m: half of the runs were easy.)",
            {
                "road": {
                    "lanes_right": 1,
                    "lane_shifts": [
                        {
                            "station": 150.0,
                            "length": 65.0,
                            "offset": 1.8,
                            "toward": "other_hypothesis",
                        }
                    ],
                }
            },
        ),
        Scenario(
            "late_ambiguity",
            "the ambiguity starts at 25 m/s, the car halfway between the true and the ghost "
            "centre and drifting toward the ghost (0.02 rad)",
            "the ghost markings appear as the car, halfway between its lane's centre and the "
            "ghost's (0.9 m from each), drifts toward the ghost: where the car sits first "
            "points to the ghost until the driver's correction, which the steering shows "
            "before the position, turns it. (Started centred, as first designed, a "
            "lane-centring prior decided every run right at once; started halfway without the "
            "drift, in a median 2.5 s: docs/design.md §14.8.)",
            {
                "initial_state": {
                    "between_hypotheses": True,
                    "speed": 25.0,
                    "heading_toward_other": LATE_AMBIGUITY_DRIFT,
                }
            },
        ),
        Scenario(
            "close_hypotheses",
            "hypotheses 0.3 m apart (worn paint, tar seams); start centred, std 0.25 m",
            "the hypotheses lie inside the drivers' own lateral wander, so where the car "
            "sits says little about which is true. (0.6 m apart, as first designed, a "
            "lane-centring prior decided in a median 0.5-2 s: the spacing was still 2-4 "
            "drivers' lateral standard deviations.)",
            {
                "markings": {"hypotheses": [0.0, -0.3]},
                "initial_state": {"lateral_offset": 0.0, "lateral_offset_std": 0.25},
            },
        ),
        Scenario(
            "off_centre_drivers",
            "drivers keep 0.2-0.5 m left or right of the centre; hypotheses 0.8 m apart",
            "people do not drive on the lane centre; a prior that they do is biased by "
            "their offset, by up to more than half the spacing of a tar seam 0.8 m away. (With the "
            "paper's 1.8 m spacing a lane-centring prior decided every run right at once.)",
            {"markings": {"hypotheses": [0.0, -0.8]}},
            preferred_offset=(0.2, 0.5),
        ),
        Scenario(
            "lane_change",
            "overtaking: to the lane on the other hypothesis's side (3.6 m) over 80 m from "
            "120 m, back from 300 m",
            "during and after a deliberate lane change the car is far from the marked "
            "lane's centre under every hypothesis, and it moves toward where the other "
            "hypothesis puts the lane whichever is true (to the left lane only, as first "
            "designed, it moved away from the ghost lane when the true bias was 0 m).",
            {
                "road": {
                    "lanes_right": 1,
                    "lane_shifts": [
                        {
                            "station": 120.0,
                            "length": 80.0,
                            "offset": 3.6,
                            "toward": "other_hypothesis",
                        },
                        {
                            "station": 300.0,
                            "length": 80.0,
                            "offset": -3.6,
                            "toward": "other_hypothesis",
                        },
                    ],
                }
            },
        ),
    )
}
"""Every scenario by name (the module docstring's table)."""


def scenario_names() -> tuple[str, ...]:
    """The scenarios' names, ``paper`` first."""
    return tuple(SCENARIOS)


def scenario_drivers(params: Sequence[P], scenario: str, seed: int) -> list[P]:
    """The drivers ``params`` as they drive in ``scenario`` (their ``preferred_offset``).

    A scenario with a preferred-offset range gives driver i the offset
    ``sign_i * u_i`` with u_i uniform in the range and the sign +-1 with equal
    probability, both from ``numpy.random.default_rng([seed, 51, i])``: the same
    driver of the same population seed keeps the same offset in every run. Other
    scenarios return the drivers unchanged.

    Raises:
        ValueError: an unknown scenario (naming the allowed ones).
    """
    spec = scenario_spec(scenario)
    low, high = spec.preferred_offset
    if high <= 0.0:
        return list(params)
    out = []
    for i, p in enumerate(params):
        rng = np.random.default_rng([int(seed), 51, i])
        size = float(rng.uniform(low, high))
        sign = 1.0 if rng.random() < 0.5 else -1.0
        out.append(dataclasses.replace(p, preferred_offset=sign * size))  # type: ignore[type-var]
    return out


def scenario_spec(name: str) -> Scenario:
    """The scenario ``name``.

    Raises:
        ValueError: an unknown name, naming the allowed ones.
    """
    try:
        return SCENARIOS[name]
    except KeyError:
        raise ValueError(f"unknown scenario {name!r}; allowed: {', '.join(SCENARIOS)}") from None

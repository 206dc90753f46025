"""Seeded populations of synthetic drivers, regenerable anywhere by (name, seed, size).

- "paper" (default): nine drivers like the paper's participants, "Ill" and
  1-8, three of each archetype (two-point PI, preview optimal control,
  intermittent control), each archetype with one driver holding 15 m/s, one
  ramping to 25-38 m/s and one ramping to 45 m/s; which name gets which
  archetype, speed and traits is drawn from the seed. Every driver has the
  human-like output stage (remnant after the lag, G29 wheel quantization).
- "paper-pi": the original all-PI population, exactly as it was drawn before
  the archetypes existed (same drivers, same runs): no remnant after the lag,
  no quantization. For comparison.
- "paper-pi-human": the same PI drivers as "paper-pi" with the output stage
  of "paper".
- "paper-with-delay": the drivers of "paper" (same draws: delays, lags, look-ahead
  times, noise, speeds) with gains designed with their own delay and
  neuromuscular lag (:mod:`hasa_env.drivers.loop_design`, docs/design.md
  §7.10): two-point drivers for a target crossover and phase margin, preview
  and intermittent drivers for a target phase margin. An experiment (issue 23).
- "mixed": the archetypes of "paper" and a fourth, noisy corrections
  (:mod:`hasa_env.drivers.noisy_corrections`: intermittent corrections whose
  remnant is the execution noise on each correction, no command noise before
  the lag), in the study conditions of "paper".

:attr:`PopulationSpec.remnant_scale` multiplies every remnant standard
deviation (and the signal-dependent gain) of a population; with
``seed_key`` a recalibrated copy keeps the drivers of the population it
copies: ``replace(POPULATIONS["paper"], remnant_scale=2.0, seed_key="paper")``.

Why this module is long: every population's trait ranges and the one drawing order that keeps
each existing population's drivers bit for bit the same live together, so that a new
population is a new entry here and cannot shift another's draws unnoticed.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, TypedDict

import numpy as np

from hasa_env.drivers.archetypes import ARCHETYPES, HumanParams
from hasa_env.drivers.base import SpeedProfile
from hasa_env.drivers.intermittent import IntermittentParams
from hasa_env.drivers.loop_design import redesign
from hasa_env.drivers.lqr import PreviewCost
from hasa_env.drivers.motor import G29_RESOLUTION, MotorParams
from hasa_env.drivers.noisy_corrections import NoisyCorrectionsParams
from hasa_env.drivers.preview import PreviewParams
from hasa_env.drivers.two_point import TwoPointParams
from hasa_env.scenarios import scenario_drivers

__all__ = [
    "IntermittentRanges",
    "LoopTargets",
    "NoisyCorrectionsRanges",
    "MotorRanges",
    "POPULATIONS",
    "PopulationSpec",
    "PreviewRanges",
    "TwoPointRanges",
    "population",
]


@dataclass(frozen=True)
class _Range:
    low: float
    high: float

    def draw(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low, self.high))


@dataclass(frozen=True)
class TwoPointRanges:
    """Trait ranges of two-point PI drivers (see :meth:`TwoPointParams.from_loop`)."""

    bandwidth: _Range
    damping: _Range
    integral_share: _Range
    near_time: _Range
    far_time: _Range
    speed_exponent: _Range
    noise_std: _Range
    noise_time_constant: _Range
    white_noise_probability: float


@dataclass(frozen=True)
class PreviewRanges:
    """Trait ranges of preview drivers (see :meth:`PreviewCost.from_bandwidth`)."""

    bandwidth: _Range
    velocity_weight: _Range
    preview_time: _Range
    persistence: _Range


@dataclass(frozen=True)
class IntermittentRanges:
    """Trait ranges of intermittent drivers (their underlying law: like :class:`PreviewRanges`)."""

    bandwidth: _Range
    velocity_weight: _Range
    preview_time: _Range
    persistence: _Range
    accumulator_gain: _Range
    accumulator_leak: _Range
    accumulator_noise: _Range
    correction_duration: _Range
    refractory_period: _Range


@dataclass(frozen=True)
class NoisyCorrectionsRanges(IntermittentRanges):
    """Trait ranges of noisy-corrections drivers: those of intermittent drivers and the
    execution noise of each correction (coefficient of variation, and rad)."""

    amplitude_noise: _Range
    amplitude_floor: _Range


@dataclass(frozen=True)
class MotorRanges:
    """Ranges of the output stage's remnant (rad at the road wheel) and the wheel."""

    broadband_std: _Range
    broadband_time_constant: _Range
    tremor_std: _Range
    tremor_frequency: _Range
    tremor_damping: _Range
    signal_dependent_gain: _Range
    steering_ratio: float = 15.0
    wheel_resolution: float = G29_RESOLUTION
    command_std: _Range = _Range(0.0, 0.0)
    command_time_constant: _Range = _Range(0.3, 0.3)

    def draw(
        self,
        rng: np.random.Generator,
        scale: float,
        command_scale: float = 1.0,
        command_rng: np.random.Generator | None = None,
    ) -> MotorParams:
        """The output stage of one driver; ``command_rng`` (default ``rng``) draws the
        command noise, so adding it left every other trait's stream as it was."""
        after_lag = {
            "broadband_std": self.broadband_std.draw(rng),
            "broadband_time_constant": self.broadband_time_constant.draw(rng),
            "tremor_std": self.tremor_std.draw(rng),
            "tremor_frequency": self.tremor_frequency.draw(rng),
            "tremor_damping": self.tremor_damping.draw(rng),
            "signal_dependent_gain": self.signal_dependent_gain.draw(rng),
        }
        other = rng if command_rng is None else command_rng
        before_lag = {
            "command_std": self.command_std.draw(other),
            "command_time_constant": self.command_time_constant.draw(other),
        }
        return MotorParams(
            **after_lag,
            **before_lag,
            steering_ratio=self.steering_ratio,
            wheel_resolution=self.wheel_resolution,
        ).scaled(scale, command_scale)


_SpeedBehaviour = tuple[_Range | None, _Range, _Range]


@dataclass(frozen=True)
class LoopTargets:
    """Targets of gains designed with the driver's delay and lag (docs/design.md §7.10).

    Attributes:
        crossover: two-point drivers' target crossover w_c (rad/s).
        phase_margin: two-point drivers' target phase margin (deg).
        preview_phase_margin: preview and intermittent drivers' target phase margin (deg).
        preview_velocity_weight: their LQR velocity weight (:meth:`PreviewCost.from_bandwidth`).
    """

    crossover: _Range
    phase_margin: _Range
    preview_phase_margin: _Range
    preview_velocity_weight: _Range

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        return {f.name: getattr(self, f.name).draw(rng) for f in fields(self)}


@dataclass(frozen=True)
class PedalRanges:
    """Ranges of the pedal remnant (:class:`~hasa_env.drivers.base.SpeedProfile`
    ``pedal_noise`` m/s^2, ``pedal_time_constant`` s)."""

    noise: _Range
    time_constant: _Range

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        return {
            "pedal_noise": self.noise.draw(rng),
            "pedal_time_constant": self.time_constant.draw(rng),
        }

    def scaled(self, factor: float) -> PedalRanges:
        """The same ranges with the noise std times ``factor`` (same draws otherwise)."""
        return replace(self, noise=_Range(self.noise.low * factor, self.noise.high * factor))


@dataclass(frozen=True)
class PopulationSpec:
    """How a named population is drawn.

    Driver slot i gets archetype ``archetypes[i % A]`` and speed behaviour
    ``speed_behaviours[(i // A) % B]`` (all pairs once for A x B drivers); the
    seed shuffles the slots over the names. A speed behaviour is (target
    speed range or None for "hold 15 m/s", ramp-rate range m/s^2, start-time
    range s).

    Attributes:
        description: one paragraph.
        archetypes: names of :data:`~hasa_env.drivers.archetypes.ARCHETYPES`.
        speed_behaviours: see above.
        delay, neuromuscular_frequency, neuromuscular_damping,
        max_lateral_acceleration: ranges of the traits every archetype has.
        two_point, preview, intermittent, noisy_corrections: the archetypes' trait ranges.
        motor: the output stage's ranges; None: no remnant, no quantization.
        pedal: the pedal remnant's ranges; None: every driver holds its speed
            profile exactly.
        remnant_scale: multiplies every remnant std after the lag of the drawn
            drivers (>= 0).
        command_scale: multiplies the command noise before the lag (>= 0).
        env_config: the env settings the population is studied under (deep-merged
            onto the env defaults by the benchmark): e.g. the disturbances and
            the steering-sensor noise of a wheel study.
        seed_key: the name whose hash seeds the draws (None: the population's
            own name); a copy with another remnant_scale and the original's
            key has the same drivers.
        legacy: draw two-point drivers in the original population's order
            (the drivers of "paper" before the archetypes existed).
        loop_targets: None (gains from the delay-free designs), or the targets of gains
            designed with each driver's own delay and lag, drawn from a stream of their
            own after the driver (:func:`~hasa_env.drivers.loop_design.redesign`), so every other draw is as without.
    """

    description: str
    archetypes: tuple[str, ...]
    speed_behaviours: tuple[_SpeedBehaviour, ...]
    delay: _Range
    neuromuscular_frequency: _Range
    neuromuscular_damping: _Range
    max_lateral_acceleration: _Range
    two_point: TwoPointRanges
    preview: PreviewRanges | None = None
    intermittent: IntermittentRanges | None = None
    noisy_corrections: NoisyCorrectionsRanges | None = None
    motor: MotorRanges | None = None
    pedal: PedalRanges | None = None
    remnant_scale: float = 1.0
    command_scale: float = 1.0
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed_key: str | None = None
    legacy: bool = False
    loop_targets: LoopTargets | None = None

    def __post_init__(self) -> None:
        unknown = [a for a in self.archetypes if a not in ARCHETYPES]
        if unknown or not self.archetypes:
            raise ValueError(
                f"PopulationSpec.archetypes must name archetypes of {', '.join(ARCHETYPES)}, "
                f"got {list(self.archetypes)}"
            )
        for name in ("preview", "intermittent", "noisy-corrections"):
            attribute = name.replace("-", "_")
            if name in self.archetypes and getattr(self, attribute) is None:
                raise ValueError(f"PopulationSpec.{attribute} ranges are needed for {name} drivers")
        if self.legacy and set(self.archetypes) != {"two-point"}:
            raise ValueError("PopulationSpec.legacy draws two-point drivers only")
        for name in ("remnant_scale", "command_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(
                    f"PopulationSpec.{name} must be a finite number >= 0, got {value!r}"
                )


_HOLD = (None, _Range(1.0, 1.0), _Range(0.0, 0.0))
_MODERATE = (_Range(25.0, 38.0), _Range(1.0, 2.0), _Range(1.0, 6.0))
_FAST = (_Range(45.0, 45.0), _Range(1.8, 3.0), _Range(1.0, 4.0))

_TWO_POINT = TwoPointRanges(
    bandwidth=_Range(0.9, 1.25),
    damping=_Range(0.5, 0.75),
    integral_share=_Range(0.2, 0.4),
    near_time=_Range(0.35, 0.5),
    far_time=_Range(0.9, 1.5),
    speed_exponent=_Range(0.85, 1.15),
    noise_std=_Range(0.0004, 0.0012),
    noise_time_constant=_Range(0.2, 0.4),
    white_noise_probability=1.0 / 3.0,
)


class _SharedRanges(TypedDict):
    delay: _Range
    neuromuscular_frequency: _Range
    neuromuscular_damping: _Range
    max_lateral_acceleration: _Range


_SHARED: _SharedRanges = {
    "delay": _Range(0.15, 0.25),
    "neuromuscular_frequency": _Range(8.0, 14.0),
    "neuromuscular_damping": _Range(0.6, 0.85),
    "max_lateral_acceleration": _Range(2.5, 4.0),
}
_HUMAN_MOTOR = MotorRanges(
    broadband_std=_Range(2e-4, 5e-4),
    broadband_time_constant=_Range(0.1, 0.3),
    tremor_std=_Range(8e-5, 1.5e-4),
    tremor_frequency=_Range(8.0, 12.0),
    tremor_damping=_Range(0.1, 0.3),
    signal_dependent_gain=_Range(0.01, 0.04),
    command_std=_Range(0.004, 0.012),
    command_time_constant=_Range(0.028, 0.052),
)
# A foot on a pedal is no cruise control: a held speed wanders by a few tenths of a m/s
# (about +-1 km/h) over a 30 s run (docs/design.md §7.4). Chosen as a plain human figure, not
# fitted to any benchmark number; the sensitivity to it is in docs/population_tuning.md.
_HUMAN_PEDAL = PedalRanges(noise=_Range(0.2, 0.5), time_constant=_Range(1.0, 3.0))
_WHEEL_STUDY = {
    # what a G29 study measures: the wheel's own (quantized) reading, no automotive sensor noise
    "noise": {"steering": 0.0},
    # external excitation of the closed loop, as identification experiments with people use
    "disturbance": {"crosswind": 0.1, "camber": 0.1},
}
_PI_DESCRIPTION = (
    "Nine two-point PI drivers: 'Ill' and 1-8, differing in gains (lateral-loop bandwidth "
    "0.9-1.25 rad/s, damping 0.5-0.75), look-ahead times, delay 0.15-0.25 s, neuromuscular "
    "lag, command noise (white or OU) and speed: three hold 15 m/s, three ramp to 25-38 m/s, "
    "three ramp to 45 m/s."
)

POPULATIONS: dict[str, PopulationSpec] = {
    "paper": PopulationSpec(
        description=(
            "Nine drivers like the paper's participants, 'Ill' and 1-8: three two-point PI, three "
            "preview optimal control (LQR with 1-1.5 s of curvature preview), three intermittent "
            "control (accumulated prediction errors against the LQR's positional law trigger "
            "0.3-0.5 s minimum-jerk corrections); "
            "delay 0.15-0.25 s, neuromuscular lag, remnant after the lag (broadband OU "
            "2e-4-5e-4 rad, 8-12 Hz tremor 8e-5-1.5e-4 rad, signal-dependent), G29 wheel "
            "quantization at steering ratio 15; per archetype one holds 15 m/s, one ramps to "
            "25-38 m/s, one to 45 m/s, each with a pedal remnant (OU, 0.2-0.5 m/s^2, 1-3 s: "
            "a held speed wanders by a std of 0.1-0.4 m/s)."
        ),
        archetypes=("two-point", "preview", "intermittent"),
        speed_behaviours=(_HOLD, _MODERATE, _FAST),
        **_SHARED,
        two_point=_TWO_POINT,
        preview=PreviewRanges(
            bandwidth=_Range(1.0, 1.4),
            velocity_weight=_Range(0.5, 2.0),
            preview_time=_Range(1.0, 1.5),
            persistence=_Range(2.0, 5.0),
        ),
        intermittent=IntermittentRanges(
            bandwidth=_Range(0.9, 1.1),
            velocity_weight=_Range(1.0, 2.0),
            preview_time=_Range(1.0, 1.5),
            persistence=_Range(2.0, 5.0),
            accumulator_gain=_Range(20.0, 50.0),
            accumulator_leak=_Range(0.5, 1.5),
            accumulator_noise=_Range(0.1, 0.4),
            correction_duration=_Range(0.3, 0.5),
            refractory_period=_Range(0.1, 0.25),
        ),
        motor=_HUMAN_MOTOR,
        pedal=_HUMAN_PEDAL,
        remnant_scale=0.1,
        env_config=_WHEEL_STUDY,
    ),
    "paper-pi": PopulationSpec(
        description=_PI_DESCRIPTION + " No remnant after the lag, no quantization: the original "
        "population, drawn exactly as before the archetypes existed.",
        archetypes=("two-point",),
        speed_behaviours=(_HOLD,) * 3 + (_MODERATE,) * 3 + (_FAST,) * 3,
        **_SHARED,
        two_point=_TWO_POINT,
        seed_key="paper",
        legacy=True,
    ),
    "paper-pi-human": PopulationSpec(
        description=_PI_DESCRIPTION + " The drivers of 'paper-pi' with the output stage of "
        "'paper' (remnant after the lag, G29 quantization).",
        archetypes=("two-point",),
        speed_behaviours=(_HOLD,) * 3 + (_MODERATE,) * 3 + (_FAST,) * 3,
        **_SHARED,
        two_point=_TWO_POINT,
        motor=_HUMAN_MOTOR,
        seed_key="paper",
        legacy=True,
    ),
}
"""Named population definitions (see :func:`population`)."""

# ---- "mixed": the archetypes of "paper" and noisy corrections (issue 23, item 3) ----
_PAPER = POPULATIONS["paper"]
POPULATIONS["mixed"] = replace(
    _PAPER,
    description=(
        "The three archetypes of 'paper' (same trait ranges, output stage and study "
        "conditions) and a fourth, noisy corrections: intermittent control with no command "
        "noise before the lag, each correction's amplitude carrying execution noise "
        "(coefficient of variation 0.1-0.3, signal-independent std 1e-4-3e-4 rad). "
        "Archetypes cycle two-point, preview, intermittent, noisy-corrections; 12 drivers "
        "give each archetype each speed behaviour once."
    ),
    archetypes=(*_PAPER.archetypes, "noisy-corrections"),
    noisy_corrections=NoisyCorrectionsRanges(
        **{f.name: getattr(_PAPER.intermittent, f.name) for f in fields(IntermittentRanges)},
        amplitude_noise=_Range(0.1, 0.3),
        amplitude_floor=_Range(1e-4, 3e-4),
    ),
)


# ---- "paper-with-delay": the drivers of "paper", gains designed with delay and lag (§7.10) ----
POPULATIONS["paper-with-delay"] = replace(
    _PAPER,
    description=(
        "The drivers of 'paper' (same draws, seed key 'paper') with gains designed with each "
        "driver's own delay and neuromuscular lag: two-point drivers for a crossover of 1.8-2.2 "
        "rad/s (lowered where the lag and delay do not allow the margin) with a phase margin "
        "of 30-38 deg (a double real zero) and speed exponent 1; preview and intermittent drivers' LQR bandwidth "
        "chosen for a phase margin of 25-30 deg at velocity weight 20-40."
    ),
    two_point=replace(_TWO_POINT, speed_exponent=_Range(1.0, 1.0)),
    seed_key="paper",
    loop_targets=LoopTargets(
        crossover=_Range(1.8, 2.2),
        phase_margin=_Range(30.0, 38.0),
        preview_phase_margin=_Range(25.0, 30.0),
        preview_velocity_weight=_Range(20.0, 40.0),
    ),
)


def _driver_names(size: int) -> list[str]:
    return ["Ill", *(str(i) for i in range(1, size))]


def _stable_hash(text: str) -> int:
    """A hash of a string that is the same in every Python process (unlike hash())."""
    return zlib.crc32(text.encode("utf-8"))


def population(
    name: str = "paper", seed: int = 0, size: int = 9, scenario: str = "paper"
) -> list[HumanParams]:
    """A seeded population of synthetic drivers, regenerable anywhere by name and seed.

    Args:
        name: a key of :data:`POPULATIONS` ("paper", "paper-pi", "paper-pi-human", "paper-with-delay", "mixed").
        seed: the seed; the same (name, seed, size) gives the same drivers.
        size: number of drivers; they are named "Ill", "1", ..., str(size - 1).
            Archetypes and speed behaviours cycle through the population's lists.
        scenario: the scenario they drive in (:data:`hasa_env.scenarios.SCENARIOS`):
            their preferred lateral offsets, :func:`hasa_env.scenarios.scenario_drivers`
            with the same seed (``paper``: none).

    Returns:
        The drivers' parameters (of their archetypes), in name order; drive
        them with :func:`~hasa_env.drivers.archetypes.make_driver` or
        :class:`~hasa_env.drivers.archetypes.SyntheticDriver`, in the population's
        study conditions ``POPULATIONS[name].env_config`` (crosswind, camber, steering
        sensor) as the benchmark does: pass them as ``config=`` to
        :func:`~hasa_env.drivers.runner.run_driver` or ``run_population``, which
        otherwise drive in the env's defaults (other numbers for the same drivers).

    Raises:
        ValueError: an unknown population or scenario, a bad seed or size.
    """
    return scenario_drivers(_population(name, seed, size), scenario, int(seed))


def _population(name: str, seed: int, size: int) -> list[HumanParams]:
    """:func:`population` before its scenario."""
    try:
        spec = POPULATIONS[name]
    except KeyError:
        raise ValueError(
            f"unknown population {name!r}; allowed: {', '.join(sorted(POPULATIONS))}"
        ) from None
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ValueError(f"population size must be a positive integer, got {size!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"population seed must be a non-negative integer, got {seed!r}")
    key = _stable_hash(spec.seed_key or name)
    if spec.legacy:
        return _legacy_population(spec, int(seed), key, size)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), key]))
    arch, speeds = len(spec.archetypes), len(spec.speed_behaviours)
    slots = [
        (spec.archetypes[i % arch], spec.speed_behaviours[(i // arch) % speeds])
        for i in range(size)
    ]
    order = rng.permutation(size)
    drivers: list[HumanParams] = []
    for index, driver_name in enumerate(_driver_names(size)):
        archetype, behaviour = slots[int(order[index])]
        own = np.random.default_rng(np.random.SeedSequence([int(seed), key, 1 + index]))
        command = np.random.default_rng(np.random.SeedSequence([int(seed), key, 1 + index, 2]))
        # the pedal remnant from a stream of its own: adding it left every other draw as it was
        pedal_rng = np.random.default_rng(np.random.SeedSequence([int(seed), key, 1 + index, 3]))
        pedal = {} if spec.pedal is None else spec.pedal.draw(pedal_rng)
        common = {
            "name": driver_name,
            "speed": _draw_speed(behaviour, spec, own, pedal),
            "delay": spec.delay.draw(own),
            "neuromuscular_frequency": spec.neuromuscular_frequency.draw(own),
            "neuromuscular_damping": spec.neuromuscular_damping.draw(own),
            "motor": MotorParams()
            if spec.motor is None
            else spec.motor.draw(own, spec.remnant_scale, spec.command_scale, command),
        }
        driver = _DRAW[archetype](spec, own, common)
        if spec.loop_targets is not None:
            targets_rng = np.random.default_rng(
                np.random.SeedSequence([int(seed), key, 1 + index, 4])
            )
            driver = redesign(driver, spec.loop_targets.draw(targets_rng))
        drivers.append(driver)
    return drivers


def _draw_speed(
    behaviour: _SpeedBehaviour,
    spec: PopulationSpec,
    rng: np.random.Generator,
    pedal: Mapping[str, float] | None = None,
) -> SpeedProfile:
    target, rate, start = behaviour
    return SpeedProfile(
        target_speed=None if target is None else target.draw(rng),
        ramp_rate=rate.draw(rng),
        start_time=start.draw(rng),
        max_lateral_acceleration=spec.max_lateral_acceleration.draw(rng),
        **(pedal or {}),
    )


def _two_point_traits(r: TwoPointRanges, rng: np.random.Generator) -> dict:
    """Noise kind and loop design of a two-point driver, drawn in the original order."""
    white = bool(rng.random() < r.white_noise_probability)
    tau = r.noise_time_constant.draw(rng)
    return {
        "noise_time_constant": 0.0 if white else tau,
        "bandwidth": r.bandwidth.draw(rng),
        "damping": r.damping.draw(rng),
        "integral_share": r.integral_share.draw(rng),
        "near_time": r.near_time.draw(rng),
        "far_time": r.far_time.draw(rng),
        "speed_exponent": r.speed_exponent.draw(rng),
    }


def _draw_two_point(spec: PopulationSpec, rng: np.random.Generator, common: dict) -> TwoPointParams:
    traits = _two_point_traits(spec.two_point, rng)
    return TwoPointParams.from_loop(
        **traits, noise_std=spec.two_point.noise_std.draw(rng), **common
    )


def _draw_preview(spec: PopulationSpec, rng: np.random.Generator, common: dict) -> PreviewParams:
    r = spec.preview
    assert r is not None  # checked by PopulationSpec
    return PreviewParams(cost=_draw_cost(r, rng), **common)


def _draw_cost(r: PreviewRanges | IntermittentRanges, rng: np.random.Generator) -> PreviewCost:
    return PreviewCost.from_bandwidth(
        bandwidth=r.bandwidth.draw(rng),
        velocity_weight=r.velocity_weight.draw(rng),
        preview_time=round(r.preview_time.draw(rng), 1),  # whole preview steps of 0.1 s
        persistence=r.persistence.draw(rng),
    )


def _draw_intermittent(
    spec: PopulationSpec, rng: np.random.Generator, common: dict
) -> IntermittentParams:
    r = spec.intermittent
    assert r is not None  # checked by PopulationSpec
    return IntermittentParams(
        cost=_draw_cost(r, rng),
        accumulator_gain=r.accumulator_gain.draw(rng),
        accumulator_leak=r.accumulator_leak.draw(rng),
        accumulator_noise=r.accumulator_noise.draw(rng),
        correction_duration=r.correction_duration.draw(rng),
        refractory_period=r.refractory_period.draw(rng),
        **common,
    )


def _draw_noisy_corrections(
    spec: PopulationSpec, rng: np.random.Generator, common: dict
) -> NoisyCorrectionsParams:
    """An intermittent driver's traits, then the execution noise; no command noise."""
    r = spec.noisy_corrections
    assert r is not None  # checked by PopulationSpec
    drawn = _draw_intermittent(replace(spec, intermittent=r), rng, common)
    traits = {f.name: getattr(drawn, f.name) for f in fields(drawn)}
    return NoisyCorrectionsParams(
        **{**traits, "motor": replace(common["motor"], command_std=0.0)},
        amplitude_noise=r.amplitude_noise.draw(rng),
        amplitude_floor=r.amplitude_floor.draw(rng),
    )


_DRAW: dict[str, Callable[[PopulationSpec, np.random.Generator, dict], HumanParams]] = {
    "two-point": _draw_two_point,
    "preview": _draw_preview,
    "intermittent": _draw_intermittent,
    "noisy-corrections": _draw_noisy_corrections,
}


def _legacy_population(spec: PopulationSpec, seed: int, key: int, size: int) -> list[HumanParams]:
    """Two-point drivers drawn in the original population's order (bit for bit the old drivers).

    The output stage, if the spec has one, is drawn afterwards from each
    driver's own stream, so it leaves the PI traits unchanged.
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, key]))
    r = spec.two_point
    behaviours = [spec.speed_behaviours[i % len(spec.speed_behaviours)] for i in range(size)]
    order = rng.permutation(size)
    drivers: list[HumanParams] = []
    for index, driver_name in enumerate(_driver_names(size)):
        speed = _draw_speed(behaviours[int(order[index])], spec, rng)
        traits = _two_point_traits(r, rng)
        params = TwoPointParams.from_loop(
            **traits,
            name=driver_name,
            delay=spec.delay.draw(rng),
            neuromuscular_frequency=spec.neuromuscular_frequency.draw(rng),
            neuromuscular_damping=spec.neuromuscular_damping.draw(rng),
            noise_std=r.noise_std.draw(rng),
            speed=speed,
        )
        if spec.motor is not None:
            own = np.random.default_rng(np.random.SeedSequence([seed, key, 1 + index]))
            command = np.random.default_rng(np.random.SeedSequence([seed, key, 1 + index, 2]))
            motor = spec.motor.draw(own, spec.remnant_scale, spec.command_scale, command)
            params = replace(params, motor=motor)
        drivers.append(params)
    return drivers

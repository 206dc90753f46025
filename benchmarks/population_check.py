"""Does the synthetic population steer like people? Its drivers beside published human data.

``python -m benchmarks.population_check [--population paper] [--seeds 2000,2001]
[--drivers 9] [--runs 2] [--duration 120] [--speeds 15,25,45] [--rows rows.csv]
[--write docs/population.md]``; ``--from-rows rows.csv --write FILE`` writes the document
from rows saved with ``--rows`` without simulating
(:func:`benchmarks.population_document.read_rows`); ``--bandwidth-scale``,
``--damping-scale``, ``--velocity-weight-scale`` and ``--command-scale`` check a variant of
the population with those ranges scaled (:class:`benchmarks.population_variants.LoopScales`;
the same drivers otherwise), for trying a recalibration without changing the population.

Every driver of the population (each seed draws its own drivers) drives a straight road
at each of the study's speeds (:data:`SPEEDS`: 15, 25 and 45 m/s, held, with the driver's
pedal remnant) in two kinds of run of ``--duration`` s (the first :data:`SETTLE` s left out):

- **study runs**, in the population's study conditions (``POPULATIONS[name].env_config``:
  the benchmark's crosswind and camber): SDLP, steering-wheel SD and rate, steering reversal
  rate against gap size (Markkula & Engstrom 2006 / SAE J2944), time to line crossing.
- **identification runs**, without the study's crosswind and camber but with a known
  multisine added to the driver's steering (a steering-input injection, :class:`Injection`):
  the loop broken at the steering input is ``L(jw) = -U_driver(jw) / U_car(jw)`` at the
  multisine's frequencies (``U_car = U_driver + W``, no vehicle model needed; a crosswind
  enters at the vehicle and gives only closed-loop responses, from which the loop needs the
  vehicle's transfer). Crossover frequency, phase margin, effective delay (the crossover
  model ``L = w_c exp(-j w tau_e) / (j w)`` at the crossover: ``tau_e = (pi/2 - PM) / w_c``)
  and the remnant share (the steering variance not linearly coherent with the multisine).

Per driver the values are means over its runs; the mix and each archetype are summarized by
the median over drivers (mean over population seeds), with 95 % hierarchical bootstrap
intervals over seeds and drivers (:func:`benchmarks.protocol.intervals.hierarchical_bootstrap`).
Each statistic stands beside the published human values in
:data:`benchmarks.population_document.HUMAN_REFERENCES` (with the source; None where no number
was found); nothing is fitted here. ``--write`` writes the Markdown document
(:func:`benchmarks.population_document.write_document`).
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import signal

from benchmarks.population_document import (
    CAR_WIDTH,
    GAPS,
    GROUPS,
    HUMAN_REFERENCES,
    INJECTION_ACCELERATION,
    INJECTION_HARMONICS,
    RATE_CUTOFF,
    REVERSAL_CUTOFF,
    ROW_COLUMNS,
    RUN_COLUMNS,
    SETTLE,
    STATISTICS,
    STEERING_RATIO,
    read_rows,
    write_document,
)
from benchmarks.population_variants import LoopScales, population_variant
from benchmarks.protocol.intervals import hierarchical_bootstrap, percentile_interval
from hasa_env.drivers import POPULATIONS, make_driver, population
from hasa_env.drivers.archetypes import archetype_of
from hasa_env.drivers.base import BatchDriver, make_batch
from hasa_env.drivers.runner import run_drivers, run_seeds
from hasa_env.sim.config import deep_merge

__all__ = [
    "GAPS",
    "HUMAN_REFERENCES",
    "SPEEDS",
    "STATISTICS",
    "ROW_COLUMNS",
    "RUN_COLUMNS",
    "Injection",
    "InjectedDriver",
    "LoopScales",
    "check_population",
    "command_parser",
    "loop_response",
    "main",
    "population_variant",
    "read_rows",
    "reversal_rate",
    "run_statistics",
    "summarize",
    "write_document",
]

SPEEDS = (15.0, 25.0, 45.0)
"""m/s: the study's speeds (its drivers hold 15, ramp to 25-38 or to 45 m/s)."""


# ----------------------------------------------------------------------- injection
@dataclass(frozen=True)
class Injection:
    """A multisine added to a driver's road-wheel angle: ``sum_k a sin(w_k t + p_k)`` (rad).

    Attributes:
        frequencies: w_k (rad/s).
        amplitude: a (rad) of every sine.
        phases: p_k (rad).
    """

    frequencies: tuple[float, ...]
    amplitude: float
    phases: tuple[float, ...]

    @classmethod
    def draw(
        cls, speed: float, window: float, wheelbase: float, rng: np.random.Generator
    ) -> Injection:
        """The multisine of a run at ``speed`` (m/s) analysed over ``window`` s."""
        n = len(INJECTION_HARMONICS)
        std = INJECTION_ACCELERATION * wheelbase / speed**2
        return cls(
            frequencies=tuple(2.0 * math.pi * k / window for k in INJECTION_HARMONICS),
            amplitude=std * math.sqrt(2.0 / n),
            phases=tuple(float(p) for p in rng.uniform(0.0, 2.0 * math.pi, n)),
        )

    def __call__(self, time: np.ndarray) -> np.ndarray:
        t = np.asarray(time, dtype=np.float64)[..., None]
        return self.amplitude * np.sin(
            np.asarray(self.frequencies) * t + np.asarray(self.phases)
        ).sum(axis=-1)


class InjectedDriver:
    """A driver whose road-wheel angle gets an :class:`Injection` added (the car steers
    ``driver + injection``; the driver's own state never sees the injection)."""

    def __init__(self, driver: Any, injection: Injection) -> None:
        self.driver = driver
        self.injection = injection
        self.name = getattr(driver, "name", type(driver).__name__)

    @classmethod
    def make_batch(cls, drivers: Sequence[InjectedDriver]) -> BatchDriver:
        return _InjectedBatch(
            make_batch([d.driver for d in drivers]), [d.injection for d in drivers]
        )


class _InjectedBatch:
    def __init__(self, inner: BatchDriver, injections: Sequence[Injection]) -> None:
        self.inner = inner
        self.injections = list(injections)
        self.num_cars = len(self.injections)

    def reset(self, seeds: Sequence[int | None], dt: float, cars: Any = None) -> None:
        self.inner.reset(seeds, dt)

    def act(self, info: Mapping[str, np.ndarray], road: Any) -> tuple[np.ndarray, np.ndarray]:
        steering, acceleration = self.inner.act(info, road)
        time = np.asarray(info["time"], dtype=np.float64)
        added = np.array([inj(time[i]) for i, inj in enumerate(self.injections)])
        return steering + added, acceleration


# ----------------------------------------------------------------------- statistics
def _lowpass(x: np.ndarray, cutoff: float, dt: float) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth low-pass at ``cutoff`` Hz (a J2944 filter)."""
    b, a = signal.butter(2, cutoff, fs=1.0 / dt)
    return signal.filtfilt(b, a, x)


def reversal_rate(wheel_deg: np.ndarray, dt: float, gap: float) -> float:
    """Steering reversals per minute of a steering-wheel angle (deg) for a ``gap`` (deg).

    Markkula & Engstrom (2006), as standardized in SAE J2944: low-pass the angle (2nd-order
    Butterworth, :data:`REVERSAL_CUTOFF` Hz), take its stationary points, and count a
    reversal each time the angle has risen (fallen) by more than ``gap`` from the last
    minimum (maximum); upward and downward reversals are counted separately and summed.
    The same steps as the authors' reference code (github.com/gmarkkula/
    SteeringWheelReversalRate, ``metric_ReversalRate_VTEC.m``).
    """
    if gap <= 0:
        raise ValueError(f"reversal gap must be > 0 deg, got {gap}")
    theta = _lowpass(np.asarray(wheel_deg, dtype=np.float64), REVERSAL_CUTOFF, dt)
    d = np.concatenate(([0.0], np.diff(theta)))
    # stationary points as the reference code (metric_ReversalRate_VTEC.m) finds them
    extrema = np.flatnonzero((np.abs(np.sign(d[:-1]) - np.sign(d[1:])) == 2) | (d[:-1] == 0))
    count = 0
    for values in (theta[extrema], -theta[extrema]):
        k = 0
        for j in range(values.size):
            if values[j] - values[k] > gap:
                count += 1
                k = j
            elif values[j] <= values[k]:
                k = j
    return count / ((theta.size - 1) * dt) * 60.0


def time_to_line_crossing(
    offset: np.ndarray, lateral_speed: np.ndarray, lane_width: float
) -> np.ndarray:
    """s: first-order TLC per sample (distance of the car's edge to the line it moves
    towards / its lateral speed); inf where it moves along the road."""
    half = lane_width / 2.0 - CAR_WIDTH / 2.0
    towards = np.where(lateral_speed > 0, half - offset, half + offset)
    with np.errstate(divide="ignore"):
        tlc = np.where(
            np.abs(lateral_speed) > 1e-6, np.maximum(towards, 0.0) / np.abs(lateral_speed), np.inf
        )
    return tlc


def run_statistics(frame: pd.DataFrame, dt: float, lane_width: float) -> dict[str, float]:
    """The study-run statistics of one run after :data:`SETTLE` s (see the module docstring);
    NaN (and ``left_road`` 1) for a run that left the road before."""
    kept = frame[frame["time"] >= SETTLE]
    if len(kept) < 10:  # off the road before the settling time ended: nothing to measure
        empty = ["sdlp", "wheel_sd", "wheel_rate_rms", "tlc_median", "tlc_p15"]
        return dict.fromkeys(empty + [f"srr_{g:g}" for g in GAPS], math.nan) | {"left_road": 1.0}
    wheel = np.degrees(kept["steering"].to_numpy() * STEERING_RATIO)
    rate = np.gradient(_lowpass(wheel, RATE_CUTOFF, dt), dt)
    offset = kept["lateral_offset"].to_numpy()
    lateral_speed = kept["speed"].to_numpy() * np.sin(kept["heading"].to_numpy())
    tlc = time_to_line_crossing(offset, lateral_speed, lane_width)
    out = {
        "sdlp": float(np.std(offset)),
        "wheel_sd": float(np.std(wheel)),
        "wheel_rate_rms": float(np.sqrt(np.mean(rate**2))),
        "tlc_median": float(np.median(tlc)),
        "tlc_p15": float(np.percentile(tlc, 15)),
        "left_road": float(bool(frame["terminated"].any())),
    }
    for gap in GAPS:
        out[f"srr_{gap:g}"] = reversal_rate(wheel, dt, gap)
    return out


def _window(frame: pd.DataFrame, window: float, dt: float) -> pd.DataFrame:
    """The last ``window`` s of a run (whole samples)."""
    n = int(round(window / dt))
    if len(frame) < n:
        raise ValueError(f"run of {len(frame)} rows is shorter than the analysis window {window} s")
    return frame.iloc[-n:]


def loop_response(
    frames: Sequence[pd.DataFrame], injections: Sequence[Injection], window: float, dt: float
) -> dict[str, float]:
    """Crossover frequency (rad/s), phase margin (deg), effective delay (s) and remnant share
    of a driver at one speed from its identification runs (see the module docstring), and
    the share of those runs that left the road before the window ended (left out).

    The cross spectra with the known multisine, summed over runs, give
    ``L = -sum U_d W* / sum U_c W*`` at the multisine's DFT bins; the crossover is where
    ``|L|`` crosses 1 (log-log interpolation, the first crossing from below), the phase there
    is interpolated linearly in log frequency.
    """
    n = int(round(window / dt))
    kept_runs = [(f, i) for f, i in zip(frames, injections, strict=True) if len(f) >= n]
    lost = 1.0 - len(kept_runs) / len(frames) if frames else math.nan
    if not kept_runs:  # every run left the road before the window ended
        return dict.fromkeys(("crossover", "phase_margin", "effective_delay"), math.nan) | {
            "remnant_share": math.nan,
            "ident_left_road": lost,
        }
    frames, injections = [f for f, _ in kept_runs], [i for _, i in kept_runs]
    bins = np.asarray(INJECTION_HARMONICS)
    cross_d = np.zeros(bins.size, complex)
    cross_c = np.zeros(bins.size, complex)
    linear, total = 0.0, 0.0
    spectra = []
    for frame, inj in zip(frames, injections, strict=True):
        kept = _window(frame, window, dt)
        applied = kept["steering"].to_numpy()
        # row k's steering was chosen at row k-1's time
        w = inj(kept["time"].to_numpy() - dt)
        own = applied - w
        fw, fc, fd = (np.fft.rfft(x - x.mean())[bins] for x in (w, applied, own))
        cross_d += fd * np.conj(fw)
        cross_c += fc * np.conj(fw)
        spectra.append((fd, fw))
        total += float(np.var(own))
    loop = -cross_d / cross_c
    gain = np.sqrt(np.mean([np.abs(fw) ** 2 for _, fw in spectra], axis=0))
    response = cross_d / np.sum([np.abs(fw) ** 2 for _, fw in spectra], axis=0)
    # power of the linear part at the bins: 2 |H W|^2 / n^2 per bin (one-sided spectrum)
    linear = float(np.sum(2.0 * np.abs(response * gain) ** 2) / n**2)
    crossover, phase = _crossover(2.0 * math.pi * bins / window, loop)
    # the margin in (-180, 180] deg whatever the unwrapped phase's branch
    margin = (phase + 360.0) % 360.0 - 180.0 if math.isfinite(phase) else math.nan
    delay = (
        (math.pi / 2.0 - math.radians(margin)) / crossover if math.isfinite(crossover) else math.nan
    )
    share = 1.0 - linear / (total / len(frames)) if total > 0 else math.nan
    return {
        "crossover": crossover,
        "phase_margin": margin,
        "effective_delay": delay,
        "remnant_share": float(np.clip(share, 0.0, 1.0)),
        "ident_left_road": lost,
    }


def _crossover(omega: np.ndarray, loop: np.ndarray) -> tuple[float, float]:
    """(rad/s, deg): where ``|loop|`` first falls through 1 and the phase there."""
    magnitude = np.log(np.abs(loop))
    phase = np.degrees(np.unwrap(np.angle(loop)))
    logw = np.log(omega)
    for i in range(omega.size - 1):
        if magnitude[i] >= 0.0 > magnitude[i + 1]:
            f = magnitude[i] / (magnitude[i] - magnitude[i + 1])
            return (
                float(np.exp(logw[i] + f * (logw[i + 1] - logw[i]))),
                float(phase[i] + f * (phase[i + 1] - phase[i])),
            )
    return math.nan, math.nan


# ----------------------------------------------------------------------- runs
def _held(params: Any) -> Any:
    """The driver holding the speed it starts with (its pedal remnant kept)."""
    return replace(params, speed=replace(params.speed, target_speed=None, start_time=0.0))


def _config(spec_config: Mapping[str, Any], speed: float, duration: float, study: bool) -> dict:
    """The env settings of a run at ``speed``: the study's, or without its disturbances."""
    base = (
        dict(spec_config)
        if study
        else deep_merge(dict(spec_config), {"disturbance": {"crosswind": 0.0, "camber": 0.0}})
    )
    return deep_merge(
        base,
        {
            "time_limit": duration,
            "initial_state": {"speed": speed, "speed_std": 0.0, "lateral_offset": 0.0},
        },
    )


def _runs(
    drivers: Sequence[Any],
    seed: int,
    runs: int,
    key: str,
    config: Mapping[str, Any],
    injections: Sequence[Injection] | None = None,
) -> list[pd.DataFrame]:
    """``runs`` runs of every driver (car order: driver-major)."""
    cars: list[Any] = []
    seeds: list[tuple[int, int]] = []
    for index, driver in enumerate(drivers):
        for r, pair in enumerate(run_seeds(seed, runs, f"{driver.name}/{key}")):
            injection = None if injections is None else injections[index * runs + r]
            cars.append(driver if injection is None else InjectedDriver(driver, injection))
            seeds.append(pair)
    return run_drivers(cars, seeds, config=config)


def _seed_rows(
    name: str, seed: int, size: int, runs: int, duration: float, speed: float
) -> list[dict[str, Any]]:
    """One row per driver of population ``name`` drawn with ``seed`` at ``speed``."""
    spec = POPULATIONS[name]
    params = [_held(p) for p in population(name, seed, size)]
    drivers = [make_driver(p) for p in params]
    study_config = _config(spec.env_config, speed, duration, study=True)
    study = _runs(drivers, seed, runs, f"study/{speed:g}", study_config)
    ident_config = _config(spec.env_config, speed, duration, study=False)
    window = duration - SETTLE
    rng = np.random.default_rng([seed, int(speed * 100), 7])
    wheelbase = float(study[0].attrs["config"]["vehicle"]["wheelbase"])
    injections = [Injection.draw(speed, window, wheelbase, rng) for _ in range(size * runs)]
    ident = _runs(drivers, seed, runs, f"identification/{speed:g}", ident_config, injections)
    lane_width = float(study[0].attrs["config"]["road"]["lane_width"])
    dt = float(study[0]["time"].iloc[1] - study[0]["time"].iloc[0])
    rows = []
    for i, p in enumerate(params):
        mine = slice(i * runs, (i + 1) * runs)
        per_run = pd.DataFrame([run_statistics(f, dt, lane_width) for f in study[mine]])
        row: dict[str, Any] = {
            "seed": seed,
            "driver": p.name,
            "archetype": archetype_of(p).name,
            "speed": speed,
            **{str(k): v for k, v in per_run.mean().items()},
            **loop_response(ident[mine], injections[mine], window, dt),
        }
        rows.append(row)
    return rows


def check_population(
    name: str = "paper",
    seeds: Sequence[int] = (2000,),
    size: int = 9,
    runs: int = 2,
    duration: float = 120.0,
    speeds: Sequence[float] = SPEEDS,
) -> pd.DataFrame:
    """One row per (seed, driver, speed) with every statistic (means over the driver's runs).

    Args:
        name: a population of :data:`hasa_env.drivers.POPULATIONS`.
        seeds: population seeds (each draws its own drivers).
        size: drivers per seed; runs: runs per driver, speed and kind of run.
        duration: s of every run (> :data:`SETTLE` + 20).
        speeds: m/s held by every driver.
    """
    check_arguments(name, runs, duration)
    rows = [
        row
        for seed in seeds
        for speed in speeds
        for row in _seed_rows(name, int(seed), size, runs, duration, float(speed))
    ]
    return pd.DataFrame(rows)


def check_arguments(name: str, runs: int, duration: float) -> None:
    """Raise ValueError naming the first argument of :func:`check_population` out of range."""
    if name not in POPULATIONS:
        raise ValueError(f"unknown population {name!r}; allowed: {', '.join(sorted(POPULATIONS))}")
    if not duration > SETTLE + 20.0:
        raise ValueError(f"duration must be > {SETTLE + 20.0:g} s, got {duration}")
    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")


# ----------------------------------------------------------------------- summary
def summarize(rows: pd.DataFrame) -> pd.DataFrame:
    """Per (statistic, speed, group): the mean over seeds of the median over drivers, with
    a 95 % hierarchical bootstrap interval; group "mix" is every driver, the others one
    archetype each. Columns: statistic, speed, group, value, low, high, drivers."""
    out = []
    columns = [c for c in STATISTICS if c in rows.columns]
    for speed, at_speed in rows.groupby("speed"):
        for group in GROUPS:
            mine = at_speed if group == "mix" else at_speed[at_speed["archetype"] == group]
            if mine.empty:
                continue
            per_seed = [g[columns].to_numpy(dtype=float) for _, g in mine.groupby("seed")]
            with warnings.catch_warnings():  # a statistic without any value: NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                point = np.nanmean([np.nanmedian(v, axis=0) for v in per_seed], axis=0)
            low, high = percentile_interval(hierarchical_bootstrap(per_seed, median=True))
            for j, name in enumerate(columns):
                out.append(
                    {
                        "statistic": name,
                        "speed": float(speed),  # type: ignore[arg-type]
                        "group": group,
                        "value": float(point[j]),
                        "low": float(low[j]),
                        "high": float(high[j]),
                        "drivers": len(mine),
                    }
                )
    return pd.DataFrame(out)


# ----------------------------------------------------------------------- command line
def command_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.population_check`` (the document's header
    names one; tests parse it)."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.population_check", allow_abbrev=False
    )
    parser.add_argument("--population", default="paper")
    parser.add_argument("--seeds", default="2000", help="population seeds (comma-separated)")
    parser.add_argument("--drivers", type=int, default=9, help="drivers per seed")
    parser.add_argument("--runs", type=int, default=2, help="runs per driver, speed and kind")
    parser.add_argument("--duration", type=float, default=120.0, help="s per run")
    parser.add_argument("--speeds", default=",".join(f"{v:g}" for v in SPEEDS), help="m/s")
    for option, what in (
        ("bandwidth", "every archetype's lateral-loop bandwidth"),
        ("damping", "the two-point drivers' loop damping"),
        ("velocity-weight", "the preview / intermittent drivers' LQR velocity weight"),
        ("command", "the command noise before the neuromuscular lag"),
    ):
        parser.add_argument(
            f"--{option}-scale", type=float, default=1.0, help=f"factor on {what} (a variant)"
        )
    parser.add_argument("--rows", metavar="CSV", help="also save the per-driver rows here")
    parser.add_argument(
        "--from-rows",
        metavar="CSV",
        help="write the document from rows saved with --rows (no runs; the other run "
        "options are taken from the file)",
    )
    parser.add_argument("--write", metavar="FILE", help="write the Markdown document here")
    return parser


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces a document (what its header says)."""
    parts = [
        "python -m benchmarks.population_check",
        f"--population {args.population}",
        f"--seeds {args.seeds}",
        f"--drivers {args.drivers}",
        f"--runs {args.runs}",
        f"--duration {args.duration:g}",
        f"--speeds {args.speeds}",
    ]
    for option in ("bandwidth", "damping", "velocity_weight", "command"):
        factor = getattr(args, f"{option}_scale")
        if factor != 1.0:
            parts.append(f"--{option.replace('_', '-')}-scale {factor:g}")
    if args.rows:
        parts.append(f"--rows {args.rows}")
    if args.write:
        parts.append(f"--write {args.write}")
    return " ".join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    args = command_parser().parse_args(argv)
    if args.from_rows:
        if args.rows:
            print("python -m benchmarks.population_check: --rows and --from-rows: give one",
                  file=sys.stderr)  # fmt: skip
            return 2
        try:
            rows, made_by = read_rows(Path(args.from_rows))
        except ValueError as error:
            print(f"python -m benchmarks.population_check: {error}", file=sys.stderr)
            return 2
        made_by.write = args.write
        return _report(rows, made_by)
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
        speeds = [float(s) for s in args.speeds.split(",") if s.strip()]
    except ValueError as error:
        print(f"--seeds / --speeds: comma-separated numbers expected ({error})", file=sys.stderr)
        return 2
    factors = {
        o: getattr(args, f"{o}_scale")
        for o in ("bandwidth", "damping", "velocity_weight", "command")
    }
    for option, factor in factors.items():
        if not (math.isfinite(factor) and factor > 0):
            print(f"--{option.replace('_', '-')}-scale must be a finite factor > 0, got {factor}",
                  file=sys.stderr)  # fmt: skip
            return 2
    scales = LoopScales(**factors)
    try:  # before any run: a refused argument costs nothing
        check_arguments(args.population, args.runs, args.duration)
    except ValueError as error:
        print(f"python -m benchmarks.population_check: {error}", file=sys.stderr)
        return 2
    with population_variant(args.population, scales) as name:
        rows = check_population(name, seeds, args.drivers, args.runs, args.duration, speeds)
    rows = rows.assign(
        population=args.population,
        runs=args.runs,
        duration=args.duration,
        **{f"{o}_scale": f for o, f in factors.items()},
    )
    if args.rows:
        rows.to_csv(args.rows, index=False)
    return _report(rows, args)


def _report(rows: pd.DataFrame, args: argparse.Namespace) -> int:
    """Print the mix's summary of ``rows`` and write the document if ``args.write``."""
    summary = summarize(rows)
    print(summary[summary["group"] == "mix"].round(3).to_string(index=False))
    if args.write:
        rewrite = (
            f"python -m benchmarks.population_check --from-rows {args.rows} --write {args.write}"
            if args.rows
            else None
        )
        write_document(
            rows, summary, Path(args.write), _command(args), args.duration, rewrite=rewrite
        )
        print(f"wrote {args.write}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

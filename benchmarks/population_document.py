"""What the population check measures, the published human values beside it, and its document.

The constants of :mod:`benchmarks.population_check` (reversal gaps, filters, the multisine),
:data:`STATISTICS` (what each measured statistic is), :data:`HUMAN_REFERENCES` (the published
human values and their sources, None where none was found) and :func:`write_document` (the
Markdown document ``python -m benchmarks.population_check --write`` writes).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

__all__ = [
    "GAPS",
    "GROUPS",
    "HUMAN_REFERENCES",
    "INJECTION_ACCELERATION",
    "INJECTION_HARMONICS",
    "ROW_COLUMNS",
    "RUN_COLUMNS",
    "STATISTICS",
    "TABLE_HEADER",
    "TITLE",
    "Reference",
    "read_rows",
    "write_document",
]

GAPS = (0.5, 1.0, 2.0, 3.0, 5.0)
"""deg of steering-wheel angle: the reversal gaps."""
SETTLE = 20.0
"""s left out at the start of every run (the start-up transient)."""
STEERING_RATIO = 15.0
"""Steering-wheel angle / road-wheel angle of the population's G29 wheel."""
CAR_WIDTH = 1.8
"""m: the car's width for the time to line crossing."""
REVERSAL_CUTOFF = 0.6
"""Hz: the low-pass filter before counting reversals (Markkula & Engstrom 2006; SAE J2944)."""
RATE_CUTOFF = 2.0
"""Hz: the low-pass filter before differentiating the steering-wheel angle for its rate."""
INJECTION_HARMONICS = (5, 8, 12, 17, 24, 33, 45, 61, 82, 110, 150)
"""Multisine frequencies as multiples of 1 / (analysis window) (0.31-9.4 rad/s for 100 s)."""
INJECTION_ACCELERATION = 0.1
"""m/s^2: std of the lateral acceleration the injected steering would give on its own
(v^2 / L delta at wheelbase L), the size of the study's crosswind; the road-wheel std is
``INJECTION_ACCELERATION * L / v^2``."""


STATISTICS: dict[str, str] = {
    "crossover": "crossover frequency (rad/s), loop broken at the steering input",
    "phase_margin": "phase margin (deg)",
    "effective_delay": "effective delay tau_e (s), crossover model",
    "remnant_share": "remnant share of the driver's steering variance",
    "sdlp": "SDLP (m)",
    "wheel_sd": "steering-wheel angle SD (deg)",
    "wheel_rate_rms": f"steering-wheel rate RMS (deg/s, {RATE_CUTOFF:g} Hz low-pass)",
    **{
        f"srr_{g:g}": f"steering reversal rate (1/min), gap {g:g} deg, {REVERSAL_CUTOFF:g} Hz"
        for g in GAPS
    },
    "tlc_median": "time to line crossing, median (s)",
    "tlc_p15": "time to line crossing, 15th percentile (s)",
    "left_road": "share of study runs off the road",
    "ident_left_road": "share of identification runs off the road (left out of the loop)",
}
"""The statistics of a row of :func:`check_population` and what they are."""
GROUPS = ("mix", "two-point", "preview", "intermittent")


# ----------------------------------------------------------------------- human data
@dataclass(frozen=True)
class Reference:
    """Published human values of one statistic: ``low``-``high`` (None: no source found)."""

    statistic: str
    condition: str
    low: float | None
    high: float | None
    source: str


_NOT_FOUND = (
    "No published number found: two searches with the project's search tool (corpora pages, "
    "docs, issues and code, and exact-string search of public repositories; the second on "
    "2026-12-03, its queries in docs/design.md §7.8.1) reached titles, abstracts and the first "
    "pages of papers, none of which gives this value for human drivers; the tool returns the "
    "opening of each page, and the values sit in the papers' results sections."
)
_REVERSAL_METHOD = (
    "Method: Markkula & Engstrom (2006), 13th ITS World Congress; SAE J2944 (2015); the "
    "authors' reference code (github.com/gmarkkula/SteeringWheelReversalRate) recommends 0.6 Hz "
    "with a 3 deg gap (large reversals) and 2 Hz with 0.1 deg (small ones). Macdonald & Hoffmann "
    "(1980), Human Factors 22(6):733-739 and McLean & Hoffmann (1975), Human Factors "
    "17(3):248-256: the rate rises with task demand and reflects control frequency "
    "(qualitative); He & McCarley (2011), HFES 55:1894-1898 and Wang et al. (2019), Accid. Anal. "
    "Prev. 125:98-105: cognitive load or visual distraction raise it (abstracts without "
    "baseline values). "
)
HUMAN_REFERENCES: tuple[Reference, ...] = (
    Reference(
        "crossover",
        "driver-vehicle describing functions, crosswind gusts on a straight road (simulator)",
        None,
        None,
        "Weir & Wojcik (1971), 'The measurement of driver describing functions in simulated "
        "steering control tasks', 7th Annual Conference on Manual Control, pp. 209-218; "
        "Weir & McRuer, 'A theory for driver steering control of motor vehicles' (Highway "
        "Research Record 247, 1968); Weir & McRuer (1973), SAE 730098 (crosswind-gust simulator "
        "describing functions); McRuer & Klein (1976), SAE 760778 (gust regulation in a "
        "variable-stability car: drivers keep bandwidth and damping about constant); Delp, "
        "Crossman & Szostak (1972), 7th Annual Conference on Manual Control (highway describing "
        "functions of 3 drivers through a double steering wheel, ntrs.nasa.gov 19730001405); "
        "all reached as abstracts or first pages only. " + _NOT_FOUND,
    ),
    Reference(
        "phase_margin",
        "as for the crossover frequency",
        None,
        None,
        "the same sources as the crossover frequency. " + _NOT_FOUND,
    ),
    Reference(
        "effective_delay",
        "crossover model L = w_c exp(-j w tau_e) / (j w) (compensatory tracking)",
        None,
        None,
        "McRuer & Jex (1967), 'A review of quasi-linear pilot models', IEEE Trans. Human "
        "Factors in Electronics HFE-8(3) (the model used here); McRuer, 'Man-Machine Systems', "
        "The Electrical Engineering Handbook ch. 105 (CRC 2000; crossover frequency and remnant "
        "of full-attention operations: first page only). Not used: simulation-software "
        "documentation of pilot models (a default 'pilot time delay' of aircraft pilots, not a "
        "measured effective delay of drivers). " + _NOT_FOUND,
    ),
    Reference(
        "remnant_share",
        "share of the operator's output not linearly coherent with the forcing function",
        None,
        None,
        "McRuer & Jex (1967) define the remnant; van der El et al. (2019), IFAC HMS "
        "(remnant relative to the linear output in compensatory, pursuit and preview tracking) "
        "and Allen, Jex, McRuer & DiMarco (1975) (driver remnant rises under alcohol in a "
        "simulator): abstracts without values. " + _NOT_FOUND,
    ),
    Reference(
        "sdlp",
        "on-the-road highway test, 95 km/h (26 m/s), normal traffic, placebo",
        None,
        None,
        "Verster & Roth (2011), 'Standard operation procedures for conducting the on-the-road "
        "driving test, and measurement of the standard deviation of lateral position (SDLP)', "
        "Int. J. Gen. Med. 4:359-371 (method; 268 placebo drives pooled); Zhou, Peng & Gordon "
        "(2008), SAE 2008-01-0561 (naturalistic highway driving, norms per speed range); Brown et "
        "al. (2023), pooled NADS simulator baselines (SDLP rises with speed limit, traffic, lane "
        "count). Abstracts of the on-road studies give only changes from placebo, e.g. +2.5 cm "
        "(95 % CI 2.0-2.9) at a blood alcohol concentration of 0.5 g/L over 182 drivers in nine "
        "studies, against a 2.4 cm criterion of clinical relevance (Jongen et al. 2017, "
        "Psychopharmacology 234:837-844, cris.maastrichtuniversity.nl), not the placebo level. "
        + _NOT_FOUND,
    ),
    Reference(
        "wheel_sd",
        "straight-road lane keeping",
        None,
        None,
        "Xu et al. (2021), FISITA APAC-21-190 (SD of steering angle and SDLP over a 1 h "
        "monotonous simulator drive); Green et al. (2009), UMTRI-2006-35 (steering-wheel angle "
        "distributions in the ACAS naturalistic study); abstracts without values. " + _NOT_FOUND,
    ),
    Reference(
        "wheel_rate_rms",
        "straight-road lane keeping",
        None,
        None,
        "Benderius & Markkula (2014), 'Evidence for a fundamental property of steering', HFES "
        "58(1):884-888: corrections have bell-shaped rate profiles, peak rate proportional to "
        "amplitude (qualitative). " + _NOT_FOUND,
    ),
    *(
        Reference(
            f"srr_{g:g}",
            f"reversal rate at a {g:g} deg gap, 0.6 Hz low-pass",
            None,
            None,
            _REVERSAL_METHOD + _NOT_FOUND,
        )
        for g in GAPS
    ),
    Reference(
        "tlc_median",
        "first-order TLC (distance to the line / lateral speed) while in lane",
        None,
        None,
        "van Winsum, Brookhuis & de Waard (2000), Accid. Anal. Prev. 32(1):47-56: the "
        "first-order approximation used here fits TLC minima poorly while in lane; Zhou, Peng "
        "& Gordon (2008), SAE 2008-01-0561 (TLC norms per speed range); Godthelp, Milgram & "
        "Blaauw (1984), Human Factors 26(3) (TLC on a straight road against self-chosen "
        "occlusion times): abstracts without values. " + _NOT_FOUND,
    ),
    Reference("tlc_p15", "as for the median", None, None, "as for the median. " + _NOT_FOUND),
    Reference("left_road", "lane keeping on a straight road", 0.0, 0.0, "none are expected"),
    Reference("ident_left_road", "lane keeping on a straight road", 0.0, 0.0, "none are expected"),
)
"""Published human values of each statistic of :data:`STATISTICS` (None: none found)."""


# ----------------------------------------------------------------------- saved rows
RUN_COLUMNS = (
    "population",
    "runs",
    "duration",
    "bandwidth_scale",
    "damping_scale",
    "velocity_weight_scale",
    "command_scale",
)
"""Columns of the saved rows that hold the run settings (one value in every row)."""
ROW_COLUMNS = ("seed", "driver", "archetype", "speed", *STATISTICS, *RUN_COLUMNS)
"""Columns a rows file needs for :func:`read_rows` (what ``--rows`` saves)."""


def read_rows(path: Path) -> tuple[pd.DataFrame, argparse.Namespace]:
    """The rows saved with ``--rows`` and the arguments of the command that made them.

    Raises ValueError naming the file and what is wrong with it: unreadable, a missing
    column of :data:`ROW_COLUMNS`, a run setting that differs between rows, or a different
    number of drivers per (seed, speed).
    """
    try:
        rows = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as error:
        raise ValueError(f"rows file {path}: cannot be read as CSV ({error})") from error
    missing = [c for c in ROW_COLUMNS if c not in rows.columns]
    if missing:
        raise ValueError(
            f"rows file {path}: missing column(s) {', '.join(missing)} "
            "(save the rows with --rows of this version)"
        )
    if rows.empty:
        raise ValueError(f"rows file {path}: no rows")
    settings = {}
    for column in RUN_COLUMNS:
        values = rows[column].unique()
        if len(values) != 1:
            raise ValueError(f"rows file {path}: column {column} differs between rows")
        settings[column] = values[0]
    drivers = rows.groupby(["seed", "speed"]).size().unique()
    if len(drivers) != 1:
        raise ValueError(f"rows file {path}: the number of drivers differs between seeds/speeds")
    args = argparse.Namespace(
        population=str(settings["population"]),
        seeds=",".join(str(int(s)) for s in dict.fromkeys(rows["seed"])),
        drivers=int(drivers[0]),
        runs=int(settings["runs"]),
        duration=float(settings["duration"]),
        speeds=",".join(f"{v:g}" for v in dict.fromkeys(rows["speed"])),
        rows=str(path),
        **{c: float(settings[c]) for c in RUN_COLUMNS[3:]},
    )
    return rows, args


# ----------------------------------------------------------------------- document
TITLE = "# Does the synthetic population steer like people?"
TABLE_HEADER = "| statistic | {speeds} | human range | source |"


def _cell(summary: pd.DataFrame, statistic: str, speed: float, group: str) -> str:
    row = summary[
        (summary["statistic"] == statistic)
        & (summary["speed"] == speed)
        & (summary["group"] == group)
    ]
    if row.empty or not math.isfinite(row["value"].iloc[0]):
        return "-"
    value, low, high = (float(row[c].iloc[0]) for c in ("value", "low", "high"))
    digits = 2 if abs(value) < 10 else 1
    return f"{value:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _reference(statistic: str) -> Reference:
    return next(r for r in HUMAN_REFERENCES if r.statistic == statistic)


def _range_text(ref: Reference) -> str:
    if ref.low is None or ref.high is None:
        return "none found"
    return f"{ref.low:g}-{ref.high:g}"


def _table(summary: pd.DataFrame, group: str) -> list[str]:
    """One row per statistic, one column per speed: median [95 % interval], human range."""
    speeds = sorted(summary["speed"].unique())
    header = TABLE_HEADER.format(speeds=" | ".join(f"{v:g} m/s" for v in speeds))
    lines = [header, "|" + "---|" * (len(speeds) + 3)]
    for statistic, label in STATISTICS.items():
        if statistic not in set(summary["statistic"]):
            continue
        ref = _reference(statistic)
        cells = " | ".join(_cell(summary, statistic, v, group) for v in speeds)
        lines.append(f"| {label} | {cells} | {_range_text(ref)} | [{statistic}](#{statistic}) |")
    return lines


def _outside(summary: pd.DataFrame) -> list[str]:
    """The mix's statistics outside their cited ranges, and those without a range."""
    mix = summary[summary["group"] == "mix"]
    outside, unranked = [], []
    for statistic in dict.fromkeys(mix["statistic"]):
        ref = _reference(statistic)
        if ref.low is None or ref.high is None:
            unranked.append(statistic)
            continue
        rows = mix[mix["statistic"] == statistic]
        for _, r in rows.iterrows():
            if not ref.low <= r["value"] <= ref.high:
                outside.append(f"{statistic} at {r['speed']:g} m/s ({r['value']:.3g})")
    ranked = [s for s in dict.fromkeys(mix["statistic"]) if s not in unranked]
    lines = [
        f"Outside their cited ranges (mix, median over drivers), of the {len(ranked)} statistics "
        f"that have one ({', '.join(ranked)}): "
        + (", ".join(outside) if outside else "none")
        + ".",
    ]
    if unranked:
        lines += [
            "",
            f"Without a published range to compare with ({len(unranked)} of "
            f"{len(ranked) + len(unranked)}): " + ", ".join(unranked) + ". Two searches found no "
            "published human value for these (what was searched: the sources below and "
            "docs/design.md §7.8.1), so this document does not say whether they are human-like: "
            "the comparison with people covers only staying on the road. What was tried to bring "
            "the loop closer to people's, and why the population was left as it is: "
            "docs/design.md §7.8.",
        ]
    return lines


_METHOD = """**How it is measured.** Every driver of the population (each seed draws its own nine)
holds each of the study's speeds on a straight road (its pedal remnant kept) in two kinds of
run; the first {settle:g} s of every run are left out.

- *Study runs*, in the population's study conditions (its crosswind and camber): SDLP,
  steering-wheel angle (road-wheel angle x {ratio:g}) SD and RMS rate (after a {rate:g} Hz
  2nd-order Butterworth low-pass), steering reversal rate at gaps of {gaps} deg (Markkula &
  Engstrom 2006 / SAE J2944, 2nd-order Butterworth low-pass at {cutoff:g} Hz, the same steps as
  the authors' reference code), and the first-order time to line crossing (distance of the
  car's edge, {width:g} m wide, to the line it moves towards / its lateral speed) per sample.
- *Identification runs*, without the study's crosswind and camber, with a known multisine
  added to the driver's road-wheel angle: {n} sines on the analysis window's DFT bins,
  {low:.2f}-{high:.1f} rad/s, random phases per run, of a size that would give a lateral
  acceleration of std {acc:g} m/s^2 on its own (the study crosswind's size). **Why a
  steering-input injection and not the crosswind:** the loop broken at the steering input is
  then `L = -U_driver / U_car` at the multisine's frequencies (U_car = U_driver + W), measured
  from the two signals alone; a crosswind enters at the vehicle and gives closed-loop responses
  from which L needs the vehicle's transfer function, and its sines are not on the window's DFT
  bins. Crossover frequency: where |L| falls through 1 (log-log interpolation); phase margin
  there; effective delay from the crossover model, `tau_e = (pi/2 - PM) / w_c`; remnant
  share: 1 - (power of the driver's steering linearly coherent with the multisine, from the
  cross spectra over the runs) / (its total variance).

Per driver the values are means over its runs. Each cell is the mean over population seeds
of the median over drivers, with a 95 % hierarchical bootstrap interval (seeds, then drivers
within seeds; `benchmarks.protocol.intervals`). The per-archetype tables use the same
statistic over the archetype's drivers (three per seed)."""


def write_document(
    rows: pd.DataFrame,
    summary: pd.DataFrame,
    path: Path,
    command: str,
    duration: float = 120.0,
    rewrite: str | None = None,
) -> None:
    """The Markdown document (header: the command that wrote it, and ``rewrite``, the command
    that writes it again from the saved rows without simulating; runs of ``duration`` s)."""
    spec_seeds = ", ".join(str(s) for s in sorted(rows["seed"].unique()))
    window = INJECTION_HARMONICS
    lines = [
        TITLE,
        "",
        f"Written by `{command}`; rerun it to check every number here."
        + (
            f" `{rewrite}` writes this document again from the rows that command saved, "
            "without simulating (after a change to the references or the layout)."
            if rewrite
            else ""
        ),
        "",
        f"Population seeds {spec_seeds}; {rows['driver'].nunique()} drivers per seed; "
        f"{len(rows)} (seed, driver, speed) rows.",
        "",
        _METHOD.format(
            settle=SETTLE,
            ratio=STEERING_RATIO,
            rate=RATE_CUTOFF,
            cutoff=REVERSAL_CUTOFF,
            gaps=", ".join(f"{g:g}" for g in GAPS),
            width=CAR_WIDTH,
            n=len(window),
            low=2 * math.pi * window[0] / (duration - SETTLE),
            high=2 * math.pi * window[-1] / (duration - SETTLE),
            acc=INJECTION_ACCELERATION,
        ),
        "",
        "## The mix (every driver)",
        "",
        *_table(summary, "mix"),
        "",
        *_outside(summary),
        "",
    ]
    for group in GROUPS[1:]:
        if (summary["group"] == group).any():
            lines += [f"## Archetype {group}", "", *_table(summary, group), ""]
    lines += ["## Sources", ""]
    for ref in HUMAN_REFERENCES:
        if ref.statistic in STATISTICS:
            lines.append(
                f'- <a id="{ref.statistic}"></a>**{ref.statistic}** ({ref.condition}): '
                f"range {_range_text(ref)}. {ref.source}"
            )
    lines.append("")
    path.write_text("\n".join(lines), encoding="utf-8")

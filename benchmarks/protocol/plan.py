"""Which runs the protocol drives or loads: run references, plans, frames.

Why this module is long: a plan of recorded runs is made of what every file, quality gate,
sample time, scenario and study session file says, and each of those decisions is named
in the plan's notes or skipped files; they are kept next to the plan they decide.
"""

from __future__ import annotations

import hashlib
import json
import zlib
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.config import ILLUSTRATIVE, TRACK_ENV_IDS, BenchmarkError, ProtocolConfig
from hasa_env.drivers import SpeedProfile, SyntheticDriver, population, run_drivers, run_seeds
from hasa_env.recording import Recording, load_notes, load_paths, warn_load_notes
from hasa_env.recording.reader import load_any
from hasa_env.session.session_file import SessionError, SessionFile, find_session_files
from hasa_env.sim.config import deep_merge

PROTOCOL_DT = 0.01
"""Sample time (s) of the recordings the protocol scores: the paper's generalized preset's
coefficients belong to it, and the baselines' filters step at it."""

__all__ = [
    "PROTOCOL_DT",
    "Plan",
    "RunRef",
    "chunks",
    "load_frames",
    "make_plan",
    "quality_problem",
    "recording_plan",
    "synthetic_plan",
    "training_frames",
]


@dataclass(frozen=True)
class RunRef:
    """One run: synthetic (seeds) or recorded (path).

    Attributes:
        driver: driver name; track: "straight" or "curved"; index: run index
            of this driver on this track; env_seed/driver_seed: seeds of a
            synthetic run; path: CSV of a recorded run; seed: the population
            seed the run belongs to (None for recordings).
    """

    driver: str
    track: str
    index: int
    env_seed: int | None = None
    driver_seed: int | None = None
    path: str | None = None
    seed: int | None = None

    @property
    def key(self) -> tuple[int | None, str, str, int]:
        return (self.seed, self.driver, self.track, self.index)


def chunks(items: Sequence[RunRef], size: int) -> list[list[RunRef]]:
    """``items`` in order, cut into the fewest chunks of at most ``size`` items,
    ``n = ceil(len(items) / size)``, of near-equal lengths (they differ by at most one: 97
    runs in chunks of 48 are 33, 32, 32, not 48, 48, 1), so no task is a tiny tail."""
    if size < 1:
        raise ValueError(f"chunk size must be >= 1, got {size}")
    count = -(-len(items) // size)
    if count == 0:
        return []
    base, extra = divmod(len(items), count)
    out, start = [], 0
    for i in range(count):
        end = start + base + (1 if i < extra else 0)
        out.append(list(items[start:end]))
        start = end
    return out


@dataclass(frozen=True)
class Plan:
    """The runs the protocol scores for one population seed, or for a folder of recordings.

    One type for both sources: a synthetic plan (:func:`synthetic_plan`) has a ``seed``,
    the drivers' parameters and the env config its runs are generated with; a recording
    plan (:func:`recording_plan`) has ``seed`` None, no parameters and no env config (each
    recording carries its own), and may have ``notes`` and ``skipped`` files.

    Attributes:
        seed: the population seed (None: recordings).
        track: the main track (``"straight"`` or ``"curved"``).
        illustrative: the driver whose run ``training_run`` on the main track trains the models.
        training_run: index of that run among the illustrative driver's main-track runs.
        training_runs: how many of its runs, from ``training_run`` on, train the models.
        main: every run on the main track (the training run among them).
        curved: the extra curved-track runs (empty when the main track is curved).
        params: driver name -> :class:`hasa_env.drivers.DriverParams` (synthetic only).
        env_config: the env config of the synthetic runs (``{}`` for recordings).
        training_env_config: the env config of the synthetic training run: ``env_config``
            in the ``paper`` scenario (models and baselines are fitted on ordinary lane
            keeping and scored in the scenario; the drivers keep their own preferred
            offsets). ``{}`` for recordings.
        drivers: per driver its description in the results (``seed``, ``driver``, ``runs``,
            ``curved_runs``, and ``parameters`` or ``recordings``, ``study_session``).
        driver_order: the drivers in the order of the tables (the illustrative one first
            for recordings, the population's order otherwise).
        notes: what the plan wants said in the results (recordings only).
        skipped: recordings left out, ``{"file", "reason"}`` each.
        scenario: the scenario of the scored runs (:data:`hasa_env.scenarios.SCENARIOS`):
            ``config.scenario`` for synthetic runs, the training recording's for recordings.
        training_speeds: start speeds (m/s) of the extra training runs of the illustrative
            driver (:meth:`speed_trainings`; synthetic only).
        training_drivers: the parameters of the extra training drivers
            (:func:`training_population`; :meth:`driver_trainings`; synthetic only).
    """

    seed: int | None
    track: str
    illustrative: str
    training_run: int
    main: list[RunRef]
    curved: list[RunRef]
    params: dict[str, Any]
    env_config: dict[str, Any]
    drivers: list[dict[str, Any]]
    driver_order: list[str]
    notes: list[str] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    training_env_config: dict[str, Any] = field(default_factory=dict)
    scenario: str = "paper"
    training_runs: int = 1
    training_speeds: tuple[float, ...] = ()
    training_drivers: tuple[Any, ...] = ()

    @property
    def recorded(self) -> bool:
        """Recorded drives (not a synthetic population)."""
        return self.seed is None

    def training(self) -> RunRef:
        """The run that trains the models.

        Raises:
            BenchmarkError: the illustrative driver has no such run.
        """
        found = next(
            (
                r
                for r in self.main
                if r.driver == self.illustrative and r.index == self.training_run
            ),
            None,
        )
        if found is None:
            raise BenchmarkError(
                f"no run {self.training_run} of the illustrative driver {self.illustrative!r} on "
                f"the {self.track} track to train on{self._where()}"
            )
        return found

    def trainings(self) -> list[RunRef]:
        """The runs that train the models: the illustrative driver's main-track runs
        ``training_run`` .. ``training_run + training_runs - 1``, in order.

        Raises:
            BenchmarkError: the illustrative driver has not that many runs from there.
        """
        first, count = self.training(), self.training_runs
        if count == 1:
            return [first]
        wanted = range(self.training_run, self.training_run + count)
        runs = sorted(
            (r for r in self.main if r.driver == self.illustrative and r.index in wanted),
            key=lambda r: r.index,
        )
        if len(runs) < count:
            raise BenchmarkError(
                f"{count} training runs wanted from run {self.training_run} of the illustrative "
                f"driver {self.illustrative!r} on the {self.track} track, found "
                f"{len(runs)}{self._where()}"
            )
        return runs

    def speed_trainings(self) -> list[tuple[RunRef, float]]:
        """The extra training runs and their start speeds (m/s): one run of the illustrative
        driver per ``training_speeds`` entry, its seeds drawn for that purpose
        (``run_seeds(seed, n, "<driver>/<track>/training-speeds")``, so they are no main
        run's), indexed -1, -2, ... (no main-track run has a negative index). Empty for
        recordings."""
        if self.seed is None or not self.training_speeds:
            return []
        key = f"{self.illustrative}/{self.track}/training-speeds"
        pairs = run_seeds(self.seed, len(self.training_speeds), key)
        return [
            (RunRef(self.illustrative, self.track, -(i + 1), env, drv, seed=self.seed), speed)
            for i, ((env, drv), speed) in enumerate(zip(pairs, self.training_speeds, strict=True))
        ]

    def driver_trainings(self) -> list[RunRef]:
        """The extra training drivers' runs, one each on the main track, indexed 0, their
        seeds drawn for that purpose (``run_seeds(seed, n, "training-drivers/<track>")``, so
        they are no main run's). Drive them with :attr:`training_drivers` as the parameters
        (their names are no scored driver's). Empty for recordings."""
        if self.seed is None or not self.training_drivers:
            return []
        pairs = run_seeds(self.seed, len(self.training_drivers), f"training-drivers/{self.track}")
        return [
            RunRef(p.name, self.track, 0, env, drv, seed=self.seed)
            for p, (env, drv) in zip(self.training_drivers, pairs, strict=True)
        ]

    def validation(self) -> list[RunRef]:
        """The main-track runs the models are scored on: all but the training runs.

        Raises:
            BenchmarkError: there is no training run, or no other run.
        """
        trainings = self.trainings()
        validation = [r for r in self.main if all(r is not t for t in trainings)]
        if not validation:
            raise BenchmarkError(
                f"no validation runs: found only the training run ({len(self.main)} run(s) on "
                f"the {self.track} track){self._where()}; the protocol scores the models on the "
                "other runs"
            )
        return validation

    def _where(self) -> str:
        return "" if self.seed is None else f" (seed {self.seed})"


def make_plan(config: ProtocolConfig, seed: int | None) -> Plan:
    """The plan of one entry of ``config.run_seeds``: a population seed, or None (recordings)."""
    return recording_plan(config) if seed is None else synthetic_plan(config, seed)


TRAINING_DRIVER_PREFIX = "train-"
"""Prefix of the extra training drivers' names (``train-1``, ...): no scored driver's name."""


def training_population(config: ProtocolConfig, seed: int) -> list[Any]:
    """The extra training drivers of population seed ``seed`` (``config.training_drivers`` of
    them; empty for 0): a draw of the same population and scenario with a seed of its own,

        population(config.population, s, n, scenario=config.scenario),
        s = SeedSequence([seed, crc32("training-drivers")]).generate_state(1)[0],

    each renamed ``train-<name>``, so that no scored driver (of this or any seed's draw) is
    one of them by construction of the seed, and the same ``seed`` gives the same drivers."""
    count = config.training_drivers
    if not count:
        return []
    key = zlib.crc32(b"training-drivers")
    draw = int(np.random.SeedSequence([int(seed), key]).generate_state(1, np.uint32)[0])
    try:
        params = population(config.population, draw, count, scenario=config.scenario)
    except ValueError as exc:
        raise BenchmarkError(str(exc)) from None
    return [replace(p, name=TRAINING_DRIVER_PREFIX + p.name) for p in params]


def synthetic_plan(config: ProtocolConfig, seed: int) -> Plan:
    """The runs of population seed ``seed``: drivers, main-track and curved runs, env config."""
    try:
        params = population(config.population, seed, config.drivers, scenario=config.scenario)
    except ValueError as exc:
        raise BenchmarkError(str(exc)) from None
    by_name = {p.name: p for p in params}
    main: list[RunRef] = []
    for p in params:
        count = config.illustrative_runs if p.name == ILLUSTRATIVE else config.runs
        for i, (env_seed, driver_seed) in enumerate(
            run_seeds(seed, count, f"{p.name}/{config.track}")
        ):
            main.append(RunRef(p.name, config.track, i, env_seed, driver_seed, seed=seed))
    curved: list[RunRef] = []
    if config.track != "curved":
        for i, (env_seed, driver_seed) in enumerate(
            run_seeds(seed, config.curved_runs, f"{ILLUSTRATIVE}/curved")
        ):
            curved.append(RunRef(ILLUSTRATIVE, "curved", i, env_seed, driver_seed, seed=seed))
    drivers = [
        {
            "seed": seed,
            "driver": p.name,
            "runs": config.illustrative_runs if p.name == ILLUSTRATIVE else config.runs,
            "curved_runs": len(curved) if p.name == ILLUSTRATIVE else 0,
            "parameters": p.to_dict(),
        }
        for p in params
    ]
    return Plan(
        seed=seed,
        track=config.track,
        illustrative=ILLUSTRATIVE,
        training_run=config.training_run,
        training_runs=config.training_runs,
        main=main,
        curved=curved,
        params=by_name,
        env_config=config.env_config(),
        training_env_config=config.env_config(training=True),
        training_speeds=config.training_speeds,
        training_drivers=tuple(training_population(config, seed)),
        drivers=drivers,
        driver_order=[p.name for p in params],
        scenario=config.scenario,
    )


def quality_problem(rec: Recording, config: ProtocolConfig) -> str | None:
    """Why a recording is not scored (``config``'s quality gates), or None.

    Gates: complete (unless ``allow_incomplete``: its writer stopped before
    finalizing it, a crash or a failed write), and at least ``min_duration``
    long (a run that left the road or was stopped early is named as such).
    """
    duration = float(rec.data["time"].iloc[-1])
    if not rec.complete and not config.allow_incomplete:
        return (
            f"incomplete: its writer stopped after {duration:.2f} s without finalizing it "
            "(a crash or a failed write); --allow-incomplete scores it anyway"
        )
    if duration < config.min_duration:
        last = rec.data.iloc[-1]
        how = (
            "left the road after"
            if bool(last["terminated"])
            else "was stopped after"
            if rec.meta.get("end_reason") == "stopped"
            else "lasts"
        )
        return (
            f"{how} {duration:.2f} s, shorter than the minimum of {config.min_duration:g} s "
            "(--min-duration)"
        )
    return None


def _rate_problem(rec: Recording) -> str | None:
    """Why a recording's sample time cannot be scored by the protocol, or None: the paper's
    generalized preset and the baselines' filters step every :data:`PROTOCOL_DT` s."""
    if abs(rec.dt - PROTOCOL_DT) <= 1e-12:
        return None
    rate = (float(rec.config["sim_frequency"]), int(rec.config["action_repeat"]))
    return (
        f"sampled {_rate_text(rate)}; the protocol's models and filters step every "
        f"{PROTOCOL_DT:g} s (record at 100 Hz with action_repeat 1, or score it with "
        "hasa-replay --fit)"
    )


def _driver_of(rec: Recording, root: Path) -> str:
    metadata = rec.meta.get("metadata") or {}
    driver = metadata.get("driver") or metadata.get("participant")
    if isinstance(driver, str) and driver:
        return driver
    assert rec.path is not None
    relative = rec.path.parent.relative_to(root)
    return relative.parts[0] if relative.parts else "driver"


PROTOCOL_SECTIONS = ("runs", "practice", "measured", "schedule", "env", "view")
"""The sections of a study file that shape the drives (not its texts or questions): sessions
whose sections differ follow different protocols, which one verdict does not pool."""


@dataclass(frozen=True)
class _Protocol:
    """A session's protocol: equal when the sections that shape the drives are
    (:data:`PROTOCOL_SECTIONS`, by digest), whatever the study file is called."""

    digest: str
    label: str = field(compare=False)

    def __str__(self) -> str:
        return self.label


@dataclass
class _Sessions:
    """What the study session files under a folder say (:func:`_study_sessions`)."""

    measured: dict[Path, str] = field(default_factory=dict)
    """Each completed measured run's recording -> its participant."""
    excluded: dict[Path, str] = field(default_factory=dict)
    """Recordings to leave out -> why ("": said in the notes): practice runs, aborted
    attempts, files the session does not list, every recording of a folder whose session
    file cannot be used."""
    details: dict[str, Any] = field(default_factory=dict)
    """Per participant: the session's details (results.json ``drivers[].study_session``)."""
    notes: list[str] = field(default_factory=list)
    missing: list[dict[str, str]] = field(default_factory=list)
    """The completed measured runs a session file lists whose recording is missing,
    ``{"file", "reason"}`` as a skipped file."""
    protocols: dict[Path, _Protocol] = field(default_factory=dict)
    """Each completed measured run's recording -> its session's protocol (:func:`_protocol`)."""


def _study_sessions(root: Path) -> _Sessions:
    """What the study session files under ``root`` say (``hasa-drive study``). A session
    file that cannot be read or is invalid is named, and its folder's recordings are all
    left out: without it practice runs cannot be told from measured ones."""
    sessions = _Sessions()
    for path in find_session_files(root):
        try:
            _one_session(path, sessions)
        except (SessionError, KeyError, TypeError, AttributeError, ValueError) as exc:
            text = str(exc) if isinstance(exc, SessionError) else f"{path}: {exc!s:.200}"
            sessions.notes.append(f"skipped the session file {text}")
            reason = (
                f"its folder's session file cannot be used ({text}): practice and measured "
                "runs cannot be told apart"
            )
            for csv in path.parent.glob("*.csv"):
                sessions.excluded[csv.resolve()] = reason
    return sessions


def _protocol(study: dict[str, Any]) -> _Protocol:
    """A session's protocol: a digest of its study's :data:`PROTOCOL_SECTIONS`, labelled with
    the study's name and file."""
    spec = {name: study["spec"].get(name) for name in PROTOCOL_SECTIONS}
    digest = hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()
    source = Path(str(study.get("file") or "?")).name
    return _Protocol(digest, f"study {study['name']!r} of {source} (protocol {digest[:12]})")


def _one_session(path: Path, into: _Sessions) -> None:
    """Add what the session file ``path`` says to ``into`` (nothing when it raises).

    Raises:
        SessionError: the file cannot be read or is invalid (or KeyError, TypeError, ...:
            a field holds something else than a session file's).
    """
    session = SessionFile.open(path)
    measured: dict[Path, str] = {}
    excluded: dict[Path, str] = {}
    notes: list[str] = []
    folder = path.parent
    who = session.participant
    listed: set[Path] = set()
    practice = aborted = 0
    for attempt in session.attempts:
        if not attempt.get("file"):
            continue
        csv = (folder / attempt["file"]).resolve()
        listed.add(csv)
        if attempt["status"] == "completed" and attempt["block"] == "measured":
            measured[csv] = who
            continue
        excluded[csv] = ""
        if attempt["block"] == "practice":
            practice += 1
        if attempt["status"] != "completed":
            aborted += 1
            how = (
                f"{attempt['end_reason']}, {attempt['steps']} steps"
                if attempt["status"] == "aborted"
                else "its session stopped in it and was not resumed"
            )
            notes.append(
                f"aborted run not analysed: {who} {attempt['block']} run "
                f"{attempt['number']} attempt {attempt['attempt']} ({how}): "
                f"{folder / attempt['file']}"
            )
    unlisted = {c.resolve() for c in folder.glob("*.csv")} - listed
    excluded.update(dict.fromkeys(unlisted, ""))
    summary = session.summary()
    protocol = _protocol(session.doc["study"])
    detail = {
        "session_file": str(path),
        "study": session.doc["study"]["name"],
        "participant_metadata": session.doc["participant"]["metadata"],
        "session_state": summary["state"],
        "measured_runs": summary["measured_completed"],
        "measured_scheduled": summary["measured_scheduled"],
        "practice_runs_excluded": practice,
        "aborted_runs": aborted,
    }
    text = (
        f"study session {who} ({session.doc['study']['name']}, {summary['state']}): "
        f"{summary['measured_completed']}/{summary['measured_scheduled']} measured runs, "
        f"{practice} practice run(s) left out, {aborted} aborted"
    )
    if unlisted:
        text += f", {len(unlisted)} recording(s) the session file does not list left out"
    missing = [
        {"file": str(csv), "reason": "a completed measured run of its session file, missing"}
        for csv in measured
        if not csv.exists()
    ]
    if missing:
        text += f"; {len(missing)} of its measured recordings missing (listed as skipped)"
    into.measured.update(measured)
    into.excluded.update(excluded)
    into.details[who] = detail
    into.notes += [*notes, text]
    into.missing += missing
    into.protocols.update(dict.fromkeys(measured, protocol))


@dataclass
class _Scan:
    """What a folder of recordings holds: the usable recordings per (driver, track), the
    files skipped with their reasons, the training file's (driver, track), and what the
    study session files say (:func:`_study_sessions`)."""

    found: dict[tuple[str, str], list[Path]]
    skipped: list[dict[str, str]]
    training: tuple[str, str] | None
    session_details: dict[str, Any]
    session_notes: list[str]
    scenarios: dict[Path, str] = field(default_factory=dict)
    """Each found recording's scenario (its env config's; ``paper`` when it has none)."""
    rates: dict[Path, tuple[float, int]] = field(default_factory=dict)
    """Each found recording's (``sim_frequency`` (Hz), ``action_repeat``)."""
    load_notes: list[str] = field(default_factory=list)
    """What loading repaired or tolerated in the recordings (:func:`hasa_env.recording.
    load_notes`: e.g. a crashed recording's partly written last line dropped), each naming
    its file."""
    protocols: dict[Path, _Protocol | None] = field(default_factory=dict)
    """Each found recording's study protocol (:func:`_protocol`; None: no session file)."""


def _scan_recordings(root: Path, config: ProtocolConfig, training_file: Path | None) -> _Scan:
    """Load and check every recording under ``root`` (quality gates, study sessions); what
    loading repaired in each is shown as a :class:`~hasa_env.recording.RecordingWarning`
    (:func:`hasa_env.recording.warn_load_notes`) and kept in the scan's ``load_notes``."""
    loaded = load_paths([root])
    warn_load_notes(loaded)  # e.g. a crashed recording's cut last line, dropped
    skipped = [
        {"file": str(e.path) if e.path is not None else str(root), "reason": e.located or str(e)}
        for e in loaded.errors
        if not (e.path == root and not loaded)  # "no recordings here" is said below
    ]
    found: dict[tuple[str, str], list[Path]] = defaultdict(list)
    scenarios: dict[Path, str] = {}
    rates: dict[Path, tuple[float, int]] = {}
    training: tuple[str, str] | None = None
    sessions = _study_sessions(root)
    session_runs, session_excluded = sessions.measured, sessions.excluded
    skipped += sessions.missing  # named like a file that does not load: the verdict lacks it
    for rec in loaded:
        assert rec.path is not None
        if rec.path.resolve() in session_excluded:
            why = session_excluded[rec.path.resolve()]
            if why:  # (practice runs and aborted attempts are in the notes)
                skipped.append({"file": str(rec.path), "reason": why})
            continue
        problem = quality_problem(rec, config) or _rate_problem(rec)
        if problem is not None:
            if training_file is not None and rec.path.resolve() == training_file:
                raise BenchmarkError(f"the training file {rec.path} is not usable: {problem}")
            skipped.append({"file": str(rec.path), "reason": problem})
            continue
        driver = session_runs.get(rec.path.resolve()) or _driver_of(rec, root)
        track = str(rec.config["track"])
        found[(driver, track)].append(rec.path)
        scenarios[rec.path] = str(rec.config.get("scenario") or "paper")
        rates[rec.path] = (float(rec.config["sim_frequency"]), int(rec.config["action_repeat"]))
        if training_file is not None and rec.path.resolve() == training_file:
            training = (driver, track)
    if not found:
        if skipped:
            raise BenchmarkError(
                f"no usable recordings in {str(root)!r}: all {len(skipped)} were skipped:\n"
                + "\n".join(f"  {s['file']}: {s['reason']}" for s in skipped)
            )
        raise BenchmarkError(f"no recordings (*.csv with a .json sidecar) in {str(root)!r}")
    repaired = [note for rec in loaded for note in load_notes(rec)]
    protocols = {
        path: sessions.protocols.get(path.resolve()) for ps in found.values() for path in ps
    }
    return _Scan(
        found, skipped, training, sessions.details, sessions.notes, scenarios, rates, repaired,
        protocols,
    )  # fmt: skip


def _keep_one_scenario(
    scan: _Scan, illustrative: str, track: str, training_index: int
) -> tuple[str, int]:
    """Leave in ``scan`` the recordings of the training run's scenario and sample time
    (``sim_frequency`` and ``action_repeat``) only (the others go to ``scan.skipped`` with
    the reason: a model fitted at one sample time cannot score another); the scenario scored and the training run's index
    among the illustrative driver's remaining runs. Without that run (an index past the
    driver's runs: :meth:`Plan.training` says so) the scenario is that of the driver's first
    run (of the first recording found, if it has none on ``track``)."""
    own = scan.found.get((illustrative, track)) or [p for ps in scan.found.values() for p in ps]
    training = own[training_index] if training_index < len(own) else None
    scenario = scan.scenarios[training if training is not None else own[0]]
    rate = scan.rates[training if training is not None else own[0]]
    protocol = scan.protocols.get(training if training is not None else own[0])
    for key in list(scan.found):
        kept = []
        for path in scan.found[key]:
            other = scan.scenarios[path]
            theirs = scan.protocols.get(path)
            same_protocol = protocol is None or theirs is None or theirs == protocol
            if other == scenario and scan.rates[path] == rate and same_protocol:
                kept.append(path)
                continue
            if other != scenario:
                reason = f"scenario {other}, not the training run's {scenario}"
            elif scan.rates[path] != rate:
                reason = (
                    f"sampled {_rate_text(scan.rates[path])}, not as the training run "
                    f"({_rate_text(rate)}): the models' coefficients belong to one sample time"
                )
            else:
                reason = (
                    f"a session of {theirs}, not of the training run's {protocol}: one "
                    "verdict does not pool two protocols"
                )
            scan.skipped.append(
                {"file": str(path), "reason": reason + " (score it with a folder of its own)"}
            )
        if kept:
            scan.found[key] = kept
        else:
            del scan.found[key]
    if training is not None:
        training_index = scan.found[(illustrative, track)].index(training)
    return scenario, training_index


def _rate_text(rate: tuple[float, int]) -> str:
    """``every 0.02 s (50 Hz, action_repeat 1)`` of a (sim_frequency, action_repeat)."""
    frequency, repeat = rate
    return f"every {repeat / frequency:g} s ({frequency:g} Hz, action_repeat {repeat})"


def _training_choice(
    config: ProtocolConfig, root: Path, scan: _Scan, training_file: Path | None
) -> tuple[str, int]:
    """The illustrative driver and the index of its training run: ``training_file``'s, else
    ``config.illustrative`` (default "Ill" if it drove, else the first driver by name) and
    ``config.training_run``."""
    names = sorted({d for d, _ in scan.found})
    illustrative = config.illustrative or (ILLUSTRATIVE if ILLUSTRATIVE in names else names[0])
    training_index = config.training_run
    if config.training_file is not None:
        training = scan.training
        if training is None or training_file is None:  # (training is found with the file)
            where = "" if training_file is None else f" ({training_file})"
            raise BenchmarkError(
                f"the training file {config.training_file!r}{where} is not one of the "
                f"recordings in {str(root)!r}"
            )
        if training[1] != config.track:
            raise BenchmarkError(
                f"the training file {config.training_file!r} is on the {training[1]} track; "
                f"the protocol trains on the main track ({config.track})"
            )
        illustrative = training[0]
        paths = [p.resolve() for p in scan.found[training]]
        training_index = paths.index(training_file)
    if illustrative not in names:
        raise BenchmarkError(
            f"illustrative driver {illustrative!r} has no usable recordings in {str(root)!r}; "
            f"drivers: {', '.join(names)}"
        )
    return illustrative, training_index


def _training_notes(
    trainings: Sequence[RunRef], illustrative: str, scenario: str, scan: _Scan
) -> list[str]:
    """What a recording plan's notes say of its training runs and its scenario."""
    notes = [f"the models are trained on {r.path} (driver {illustrative!r})" for r in trainings]
    if scenario != "paper":
        notes.append(
            f"the models and the lane-centring prior are fitted on a run of {scenario!r} "
            "itself, not on one of ordinary lane keeping ('paper') as in the synthetic "
            "protocol (docs/design.md section 14.4)"
        )
    others = sum(1 for s in scan.skipped if s["reason"].startswith("scenario "))
    if others:
        notes.append(
            f"{others} recording(s) of other scenarios than {scenario!r} not scored "
            "(listed as skipped)"
        )
    return notes


def recording_plan(config: ProtocolConfig) -> Plan:
    """The runs of a folder of recordings (one recording per run).

    Every file is loaded and checked first (:func:`hasa_env.recording.load_paths`);
    a file that does not load or fails a quality gate (:func:`quality_problem`)
    is skipped and listed, with its reason, in the plan's ``skipped``
    (``{"file", "reason"}``). Curved-track recordings of every driver are
    scored on steering (the curved table); recordings of a track the protocol
    does not score are listed in the notes. What loading repaired in a file (a
    crashed recording's partly written last line, dropped) is shown as a
    :class:`~hasa_env.recording.RecordingWarning` and kept in the notes, naming it.

    Folders with a study session file (``session.json`` of ``hasa-drive
    study``) contribute their completed measured runs only: practice runs and
    aborted attempts are left out and reported in the notes, and the drivers
    are the sessions' participants, with their metadata.

    One scenario is scored: the training run's (its recording's env config
    ``scenario``; a recording without one is ``paper``). Recordings of another
    scenario are listed in ``skipped``, not pooled: a lane shift or a lane change
    makes other errors than lane keeping, and one table and verdict over both
    would describe neither; and the training run stays one of the scored
    scenario's, as a folder of one study's recordings has it. To score another
    scenario, give it a folder of its own (or ``training_file`` one of its
    recordings). (Unlike the synthetic protocol, whose training run is driven in
    the ``paper`` scenario whatever it scores, :attr:`Plan.training_env_config`,
    the models here are fitted on a run of the scored scenario: the notes say so
    when it is not ``paper``.)
    """
    root = Path(config.recordings or "")
    if not root.is_dir():
        raise BenchmarkError(f"recordings directory {str(root)!r} does not exist")
    training_file = Path(config.training_file).resolve() if config.training_file else None
    scan = _scan_recordings(root, config, training_file)
    illustrative, training_index = _training_choice(config, root, scan, training_file)
    scenario, training_index = _keep_one_scenario(scan, illustrative, config.track, training_index)
    found = scan.found
    names = sorted({d for d, _ in found})
    order = [illustrative] + [n for n in names if n != illustrative]
    other_track = "curved" if config.track != "curved" else None
    main, curved, drivers = [], [], []
    for name in order:
        main_paths = found.get((name, config.track), [])
        main += [RunRef(name, config.track, i, path=str(p)) for i, p in enumerate(main_paths)]
        curved_paths = found.get((name, other_track), []) if other_track else []
        curved += [RunRef(name, "curved", i, path=str(p)) for i, p in enumerate(curved_paths)]
        drivers.append(
            {
                "seed": None,
                "driver": name,
                "runs": len(main_paths),
                "curved_runs": len(curved_paths),
                "recordings": [str(p) for p in main_paths + list(curved_paths)],
                **(
                    {"study_session": scan.session_details[name]}
                    if name in scan.session_details
                    else {}
                ),
            }
        )
    notes = [
        f"recordings: {len(main) + len(curved)} runs of {len(names)} drivers from {root}, "
        f"scenario {scenario!r} (the training run's)"
    ]
    unused = sum(
        len(paths)
        for (_, track), paths in found.items()
        if track not in (config.track, other_track)
    )
    if unused:
        notes.append(
            f"{unused} recording(s) on another track than {config.track!r} not scored "
            "(--track chooses the main track)"
        )
    notes += scan.session_notes
    notes += scan.load_notes
    notes += [f"skipped {s['file']}: {s['reason']}" for s in scan.skipped]
    wanted = range(training_index, training_index + config.training_runs)
    notes += _training_notes(
        [r for r in main if r.driver == illustrative and r.index in wanted],
        illustrative,
        scenario,
        scan,
    )
    return Plan(
        seed=None,
        track=config.track,
        illustrative=illustrative,
        training_run=training_index,
        training_runs=config.training_runs,
        main=main,
        curved=curved,
        params={},
        env_config={},
        drivers=drivers,
        driver_order=order,
        notes=notes,
        skipped=scan.skipped,
        scenario=scenario,
    )


def constant_speed_run(
    training: RunRef, track: str, env_config: Mapping[str, Any], params: Mapping[str, Any]
) -> pd.DataFrame:
    """The training run driven again at constant speed (the driver holds its start speed;
    same seeds): the closed-loop data that make plain least squares collinear (the
    stress set's ``stress_unregularized``, :mod:`benchmarks.stress`)."""
    driver = params[training.driver]
    held = driver.with_speed(SpeedProfile.hold(driver.speed.max_lateral_acceleration))
    return load_frames([training], track, env_config, {training.driver: held})[0]


def load_frames(
    runs: Sequence[RunRef],
    track: str,
    env_config: Mapping[str, Any],
    params: Mapping[str, Any],
) -> list[pd.DataFrame]:
    """The recordings of ``runs`` (all on ``track``): generated in one vector env, or loaded."""
    if not runs:
        return []
    if runs[0].path is not None:
        frames = []
        for ref in runs:
            assert ref.path is not None  # (a plan's runs are all recorded or all synthetic)
            rec = load_any(ref.path)
            frame = rec.data
            frame.attrs = {
                "config": rec.meta["config"],
                "track": rec.meta["config"]["track"],
                "driver": ref.driver,
                "path": ref.path,
            }
            frames.append(frame)
        return frames

    drivers: dict[str, Any] = {}
    cars = []
    for ref in runs:
        if ref.driver not in drivers:
            drivers[ref.driver] = SyntheticDriver(params[ref.driver])
        cars.append(drivers[ref.driver])
    seeds = [(int(r.env_seed), int(r.driver_seed)) for r in runs]  # type: ignore[arg-type]
    return run_drivers(cars, seeds, TRACK_ENV_IDS[track], dict(env_config))


def training_frames(plan: Plan) -> list[pd.DataFrame]:
    """Every run the models of ``plan`` are fitted on, in the order the benchmark fits them:
    the illustrative driver's training runs, its extra runs at other start speeds
    (``training_speeds``) and the training drivers' runs (none of them scored)."""
    train_env = plan.training_env_config or plan.env_config
    frames = load_frames(plan.trainings(), plan.track, train_env, plan.params)
    for ref, start_speed in plan.speed_trainings():  # extra runs at other speeds (train only)
        speed_env = deep_merge(train_env, {"initial_state": {"speed": start_speed}})
        frames += load_frames([ref], plan.track, speed_env, plan.params)
    extra = {p.name: p for p in plan.training_drivers}  # other drivers (train only)
    return frames + load_frames(plan.driver_trainings(), plan.track, train_env, extra)

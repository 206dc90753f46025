"""Which runs the protocol drives or loads: run references, plans, frames."""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.protocol.config import _ENV_IDS, ILLUSTRATIVE, BenchmarkError, ProtocolConfig
from hasa_env.drivers import SyntheticDriver, population, run_drivers, run_seeds
from hasa_env.recording import load_recording
from hasa_env.session.session_file import SessionError, SessionFile, find_session_files

__all__ = ["RunRef", "chunks", "load_frames", "recording_plan", "synthetic_plan"]


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
    return [list(items[i : i + size]) for i in range(0, len(items), size)]


def synthetic_plan(config: ProtocolConfig, seed: int) -> dict[str, Any]:
    """The runs of population seed ``seed``: drivers, main-track and curved runs, env config."""
    try:
        params = population(config.population, seed, config.drivers)
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
    return {
        "illustrative": ILLUSTRATIVE,
        "main": main,
        "curved": curved,
        "params": by_name,
        "env_config": config.env_config(),
        "drivers": drivers,
        "driver_order": [p.name for p in params],
    }


def _study_sessions(root: Path) -> tuple[dict[Path, str], set[Path], dict[str, Any], list[str]]:
    """What the study session files under ``root`` say (``hasa-drive study``).

    Returns (measured recording -> participant, recordings to leave out (practice
    runs, aborted attempts, files the session does not list), per-participant
    details, notes). A session file that cannot be read is named in the notes and its
    folder's recordings are read like any others.
    """
    measured: dict[Path, str] = {}
    excluded: set[Path] = set()
    details: dict[str, Any] = {}
    notes: list[str] = []
    for path in find_session_files(root):
        try:
            session = SessionFile.open(path)
        except SessionError as exc:
            notes.append(f"skipped the session file {exc}")
            continue
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
            excluded.add(csv)
            if attempt["block"] == "practice":
                practice += 1
            if attempt["status"] != "completed":
                aborted += 1
                notes.append(
                    f"aborted run not analysed: {who} {attempt['block']} run "
                    f"{attempt['number']} attempt {attempt['attempt']} ({attempt['end_reason']}, "
                    f"{attempt['steps']} steps): {folder / attempt['file']}"
                )
        unlisted = {c.resolve() for c in folder.glob("*.csv")} - listed
        excluded |= unlisted
        summary = session.summary()
        details[who] = {
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
        notes.append(text)
    return measured, excluded, details, notes


def recording_plan(config: ProtocolConfig) -> dict[str, Any]:
    """The runs of a folder of recordings (one recording per run).

    Folders with a study session file (``session.json`` of ``hasa-drive
    study``) contribute their completed measured runs only: practice runs and
    aborted attempts are left out and reported in the notes, and the drivers
    are the sessions' participants, with their metadata.
    """
    root = Path(config.recordings or "")
    if not root.is_dir():
        raise BenchmarkError(f"recordings directory {str(root)!r} does not exist")
    found: dict[tuple[str, str], list[Path]] = defaultdict(list)
    skipped: list[str] = []
    session_runs, session_excluded, session_details, session_notes = _study_sessions(root)
    for csv in sorted(root.rglob("*.csv")):
        if csv.resolve() in session_excluded:
            continue
        sidecar = csv.with_suffix(".json")
        try:
            meta = json.loads(sidecar.read_text(encoding="utf-8"))
            track = str(meta["config"]["track"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            skipped.append(f"{csv}: no readable sidecar with config.track ({type(exc).__name__})")
            continue
        metadata = meta.get("metadata") or {}
        driver = (
            session_runs.get(csv.resolve()) or metadata.get("driver") or metadata.get("participant")
        )
        if not driver:
            relative = csv.parent.relative_to(root)
            driver = relative.parts[0] if relative.parts else "driver"
        found[(str(driver), track)].append(csv)
    if not found:
        raise BenchmarkError(f"no recordings (*.csv with a .json sidecar) in {str(root)!r}")
    names = sorted({d for d, _ in found})
    illustrative = config.illustrative or (ILLUSTRATIVE if ILLUSTRATIVE in names else names[0])
    if illustrative not in names:
        raise BenchmarkError(
            f"illustrative driver {illustrative!r} has no recordings in {str(root)!r}; "
            f"drivers: {', '.join(names)}"
        )
    order = [illustrative] + [n for n in names if n != illustrative]
    main, curved, drivers = [], [], []
    for name in order:
        main_paths = found.get((name, config.track), [])
        main += [RunRef(name, config.track, i, path=str(p)) for i, p in enumerate(main_paths)]
        curved_paths = found.get((name, "curved"), []) if config.track != "curved" else []
        if name == illustrative:
            curved += [RunRef(name, "curved", i, path=str(p)) for i, p in enumerate(curved_paths)]
        drivers.append(
            {
                "seed": None,
                "driver": name,
                "runs": len(main_paths),
                "curved_runs": len(curved_paths) if name == illustrative else 0,
                "recordings": [str(p) for p in main_paths + list(curved_paths)],
                **({"study_session": session_details[name]} if name in session_details else {}),
            }
        )
    notes = [f"recordings: {len(main) + len(curved)} runs of {len(names)} drivers from {root}"]
    notes += session_notes
    notes += [f"skipped {s}" for s in skipped]
    return {
        "illustrative": illustrative,
        "main": main,
        "curved": curved,
        "params": {},
        "env_config": {},
        "drivers": drivers,
        "driver_order": order,
        "notes": notes,
    }


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
            rec = load_recording(ref.path)
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
    return run_drivers(cars, seeds, _ENV_IDS[track], dict(env_config))

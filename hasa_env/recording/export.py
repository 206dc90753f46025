"""Recordings as offline-RL datasets: Minari export, Parquet conversion, summaries.

- :func:`export_minari` turns recordings (a folder of them, human or
  synthetic) into a `Minari <https://minari.farama.org>`_ dataset that
  ``minari.load_dataset`` loads and ``recover_environment()`` rebuilds.
- :func:`to_parquet` / :func:`read_parquet` convert a recording to one
  self-contained Parquet file (the sidecar travels in the file's metadata).
- :func:`summarize` describes and validates one recording (``hasa-rec info``).

Both Minari and pyarrow are optional extras, imported when used; a clear
``ImportError`` says how to install them.

**Actions.** A recording stores the *physical* action (road-wheel angle rad,
acceleration m/s^2, after clipping). The dataset's env is the recording's
config with ``action.type`` set to the exported action type, so the stored
actions are always in the recovered env's action space: ``"physical"``
(default, the recorded values as float32) or ``"normalized"`` (mapped to
-1..1 with the config's limits, as the env maps them back).

**Observations** are recomputed from the recording columns exactly as the env
computes them: ``"sensors"`` from the ``sensor_*`` columns, ``"state"`` from
(lateral_offset, heading, speed, steering, road_curvature), each clipped to
the observation bounds and cast to float32; ``"both"`` is the dict of the two.
Episode k of the dataset has the recording's rows 0..n as observations (n + 1),
rows 1..n's actions, rewards and flags (n each), and every info key of rows
0..n as ``infos`` (arrays of n + 1).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import re
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

from hasa_env.recording.format import (
    Recording,
    RecordingError,
    RecordingWarning,
    _validate_meta,
)
from hasa_env.recording.reader import load_recording, load_recordings
from hasa_env.sim.config import deep_merge
from hasa_env.sim.dynamics import SENSOR_NAMES
from hasa_env.sim.setup import INFO_KEYS, RECORDING_COLUMNS, STATE_NAMES, EnvSetup, build_setup

__all__ = [
    "ExportResult",
    "RecordingSummary",
    "action_columns",
    "episode_arrays",
    "export_minari",
    "observations",
    "read_parquet",
    "require_minari",
    "require_pyarrow",
    "summarize",
    "to_parquet",
]

ACTION_TYPES = ("physical", "normalized")
OBSERVATION_TYPES = ("sensors", "state", "both")
PARQUET_METADATA_KEY = b"hasa_env.recording"
"""Key of the sidecar JSON in a converted Parquet file's schema metadata."""
_SENSOR_COLUMNS = tuple(f"sensor_{name}" for name in SENSOR_NAMES)
_ID_FOR_TRACK = {"straight": "hasa_env/LaneKeeping-v0", "curved": "hasa_env/LaneKeepingCurved-v0"}


def require_minari() -> Any:
    """Import and return ``minari``, or raise ImportError saying how to install it."""
    try:
        import minari
    except ImportError as exc:
        raise ImportError(
            "Minari is not installed; install the datasets extra: pip install 'hasa-env[minari]'"
        ) from exc
    try:
        import pyarrow  # noqa: F401 - Minari's default (arrow) storage needs it
    except ImportError as exc:
        raise ImportError(
            "Minari's arrow storage needs pyarrow; install the datasets extra: "
            "pip install 'hasa-env[minari]'"
        ) from exc
    return minari


def require_pyarrow() -> Any:
    """Import and return ``pyarrow.parquet``, or raise ImportError saying how to install it."""
    try:
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise ImportError(
            "pyarrow is not installed; install the Parquet extra: pip install 'hasa-env[parquet]'"
        ) from exc
    return pq


# ----------------------------------------------------------- conversions
def _setup(config: Mapping[str, Any]) -> EnvSetup:
    return build_setup(config)


def observations(data: pd.DataFrame, config: Mapping[str, Any], kind: str | None = None) -> Any:
    """The env's observations of every recording row, recomputed from the columns.

    Args:
        data: recording rows (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`).
        config: the env's full config (the recording's sidecar ``config``).
        kind: ``"sensors"``, ``"state"`` or ``"both"``; default the config's
            ``observation.type``.

    Returns:
        (rows, 6) float32 sensors, (rows, 5) float32 state, or a dict of both,
        bit-identical to what the env returned (readings clipped to the bounds).
    """
    setup = _setup(config)
    kind = setup.observation_type if kind is None else kind
    if kind not in OBSERVATION_TYPES:
        raise ValueError(f"observation type must be one of {OBSERVATION_TYPES}, got {kind!r}")

    def clipped(columns: Sequence[str], bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        values = data[list(columns)].to_numpy(dtype=np.float64)
        lo, hi = (b.astype(np.float64) for b in bounds)
        return np.clip(values, lo, hi).astype(np.float32)

    if kind == "sensors":
        return clipped(_SENSOR_COLUMNS, setup.sensor_bounds())
    if kind == "state":
        return clipped(STATE_NAMES, setup.state_bounds())
    return {
        "sensors": clipped(_SENSOR_COLUMNS, setup.sensor_bounds()),
        "state": clipped(STATE_NAMES, setup.state_bounds()),
    }


def action_columns(data: pd.DataFrame, config: Mapping[str, Any], kind: str) -> np.ndarray:
    """Rows 1..n's actions as (n, 2) float32 in the ``kind`` action space.

    ``"physical"``: (road-wheel angle rad, acceleration m/s^2) as recorded;
    ``"normalized"``: mapped onto -1..1 with the config's ``action`` limits
    (the inverse of the env's mapping), clipped to -1..1.
    """
    if kind not in ACTION_TYPES:
        raise ValueError(f"action type must be one of {ACTION_TYPES}, got {kind!r}")
    physical = data[["steering", "acceleration"]].to_numpy(dtype=np.float64)[1:]
    if kind == "physical":
        return physical.astype(np.float32)
    act = config["action"]
    limit = act["max_steering"]
    lo, hi = act["min_acceleration"], act["max_acceleration"]
    steer = physical[:, 0] / limit
    acc = 2.0 * (physical[:, 1] - lo) / (hi - lo) - 1.0
    return np.clip(np.column_stack([steer, acc]), -1.0, 1.0).astype(np.float32)


def dataset_config(
    config: Mapping[str, Any], action_type: str, observation_type: str | None
) -> dict[str, Any]:
    """The recording's config with the exported action and observation types."""
    update: dict[str, Any] = {"action": {"type": action_type}}
    if observation_type is not None:
        update["observation"] = {"type": observation_type}
    return deep_merge(config, update)


def episode_arrays(
    recording: Recording, action_type: str = "physical", observation_type: str | None = None
) -> dict[str, Any]:
    """One recording as Minari episode arrays (see the module docstring for the layout).

    Returns a dict with ``observations`` (n + 1 rows), ``actions``,
    ``rewards`` (float64), ``terminations``, ``truncations`` (n each),
    ``infos`` (every :data:`~hasa_env.sim.setup.INFO_KEYS` column, n + 1 rows),
    and ``cut``: True when the recording ended without termination or
    truncation (stopped, or incomplete); its last step is then marked
    truncated, as Minari's own collector does for an episode cut short.
    """
    data = recording.data
    n = len(data) - 1
    if n < 1:
        raise ValueError("the recording has no steps (only the reset row)")
    config = dataset_config(recording.config, action_type, observation_type)
    terminations = data["terminated"].to_numpy(dtype=bool)[1:].copy()
    truncations = data["truncated"].to_numpy(dtype=bool)[1:].copy()
    cut = not (terminations[-1] or truncations[-1])
    if cut:
        truncations[-1] = True
    infos = {
        key: data[key].to_numpy(dtype=np.int64 if key == "bias_index" else np.float64).copy()
        for key in INFO_KEYS
    }
    return {
        "observations": observations(data, config),
        "actions": action_columns(data, config, action_type),
        "rewards": data["reward"].to_numpy(dtype=np.float64)[1:].copy(),
        "terminations": terminations,
        "truncations": truncations,
        "infos": infos,
        "cut": cut,
    }


# ------------------------------------------------------------------ Minari
@dataclass
class ExportResult:
    """What :func:`export_minari` did.

    Attributes:
        dataset: the created ``minari.MinariDataset``.
        dataset_id: its id.
        exported: the recordings (CSV paths) in the dataset, episode i = exported[i].
        skipped: (path, reason) of every recording left out: corrupt files,
            recordings without steps, configs that differ from the first one.
        cut: exported recordings whose last step was marked truncated because
            they ended without termination or truncation.
        env_id: the env id stored in the dataset's spec.
        config: the config the recovered env is built with.
    """

    dataset: Any
    dataset_id: str
    exported: list[Path] = field(default_factory=list)
    skipped: list[tuple[Path | None, str]] = field(default_factory=list)
    cut: list[Path] = field(default_factory=list)
    env_id: str = ""
    config: dict[str, Any] = field(default_factory=dict)


@contextlib.contextmanager
def _minari_path(data_path: str | os.PathLike[str] | None) -> Iterator[None]:
    """Temporarily point Minari at ``data_path`` (its MINARI_DATASETS_PATH)."""
    if data_path is None:
        yield
        return
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = os.fspath(Path(data_path).resolve())
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def _config_differences(a: Any, b: Any, prefix: str = "") -> list[str]:
    """Key paths where two configs differ."""
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        out: list[str] = []
        for key in sorted(set(a) | set(b)):
            out.extend(_config_differences(a.get(key), b.get(key), f"{prefix}{key}."))
        return out
    return [] if a == b else [prefix.rstrip(".")]


_IGNORED_CONFIG = ("render",)
"""Config sections that may differ between recordings of one dataset (display only)."""


def _comparable(config: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in config.items() if k not in _IGNORED_CONFIG}


def _load_sources(
    source: str | os.PathLike[str] | Sequence[Recording | str | os.PathLike[str]],
) -> tuple[list[Recording], list[tuple[Path | None, str]]]:
    """Recordings from a folder or a list (of Recordings or paths), plus the corrupt ones."""
    skipped: list[tuple[Path | None, str]] = []
    if isinstance(source, str | os.PathLike):
        root = Path(source)
        if not root.is_dir():
            raise FileNotFoundError(f"recordings folder {str(root)!r} does not exist")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordingWarning)
            loaded = load_recordings(root)
        for err in loaded.errors:
            skipped.append((err.path, err.reason if err.line is None else str(err)))
        return list(loaded), skipped
    recordings: list[Recording] = []
    for item in source:
        if isinstance(item, Recording):
            recordings.append(item)
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RecordingWarning)
                recordings.append(load_recording(item))
        except RecordingError as err:
            skipped.append((err.path or Path(item), str(err)))
    return recordings, skipped


def _env_id(recordings: Sequence[Recording], track: str) -> str:
    for rec in recordings:
        env_id = rec.meta.get("env_id")
        if env_id in _ID_FOR_TRACK.values():
            return str(env_id)
    return _ID_FOR_TRACK[track]


def export_minari(
    source: str | os.PathLike[str] | Sequence[Recording | str | os.PathLike[str]],
    dataset_id: str,
    *,
    data_path: str | os.PathLike[str] | None = None,
    action_type: str = "physical",
    observation_type: str | None = None,
    overwrite: bool = False,
    author: str | None = None,
    description: str | None = None,
    algorithm_name: str | None = None,
) -> ExportResult:
    """Export recordings as the Minari dataset ``dataset_id`` (e.g. ``"hasa/drives-v0"``).

    Args:
        source: a folder of recordings (every ``*.csv`` with its sidecar, as
            :func:`hasa_env.recording.load_recordings` reads it), or a list of
            :class:`~hasa_env.recording.Recording` objects or CSV paths.
        dataset_id: Minari id ``(namespace/)name-v<version>``.
        data_path: the Minari datasets root (default ``$MINARI_DATASETS_PATH``,
            else ``~/.minari/datasets``); load with the same
            ``MINARI_DATASETS_PATH``.
        action_type: ``"physical"`` (rad, m/s^2) or ``"normalized"`` (-1..1);
            the recovered env uses the same.
        observation_type: ``"sensors"``, ``"state"`` or ``"both"``; default the
            recordings' config's.
        overwrite: replace an existing dataset of the same id.
        author, description, algorithm_name: Minari metadata.

    The first recording (in name order) fixes the config; recordings whose
    config differs from it (apart from ``render``) are skipped, like corrupt
    recordings and recordings without steps; each is listed with its reason in
    :attr:`ExportResult.skipped` and with a warning. The dataset's env spec is
    the registered id with ``kwargs={"config": <that config>}``, so
    ``dataset.recover_environment()`` is ``gym.make`` of exactly that env.

    Raises:
        ImportError: Minari (or pyarrow) is not installed.
        ValueError: a malformed dataset id, an unknown type, an existing dataset
            without ``overwrite``, or no exportable recording.
    """
    minari = require_minari()
    # minari is the optional 'minari' extra: imported only when exporting
    from minari.data_collector.episode_buffer import EpisodeBuffer
    from minari.dataset.minari_dataset import parse_dataset_id

    try:
        if not re.fullmatch(r"[^/]+(/[^/]+)?-v[0-9]+", dataset_id):
            raise ValueError(dataset_id)
        parse_dataset_id(dataset_id)
    except (ValueError, TypeError):  # minari 0.5.4 raises TypeError when the version is missing
        raise ValueError(
            f"dataset id {dataset_id!r} is malformed: use (namespace/)name-v<version>, "
            "e.g. 'hasa/drives-v0'"
        ) from None
    if action_type not in ACTION_TYPES:
        raise ValueError(f"action_type must be one of {ACTION_TYPES}, got {action_type!r}")
    if observation_type is not None and observation_type not in OBSERVATION_TYPES:
        raise ValueError(
            f"observation_type must be one of {OBSERVATION_TYPES} or None, got {observation_type!r}"
        )
    recordings, skipped = _load_sources(source)
    reference: dict[str, Any] | None = None
    chosen: list[tuple[Recording, dict[str, Any]]] = []
    for rec in recordings:
        if reference is None and len(rec.data) > 1:
            reference = _comparable(rec.config)
        if len(rec.data) < 2:
            skipped.append((rec.path, "no steps (only the reset row)"))
            continue
        differences = _config_differences(reference, _comparable(rec.config))
        if differences:
            skipped.append(
                (
                    rec.path,
                    "config differs from the dataset's (first recording's) in "
                    + ", ".join(differences),
                )
            )
            continue
        chosen.append((rec, episode_arrays(rec, action_type, observation_type)))
    for path, reason in skipped:
        warnings.warn(f"not exported: {path}: {reason}", RecordingWarning, stacklevel=2)
    if not chosen:
        raise ValueError(
            "no recording to export"
            + (": " + "; ".join(f"{p}: {r}" for p, r in skipped) if skipped else "")
        )
    first = chosen[0][0]
    config = dataset_config(first.config, action_type, observation_type)
    env_id = _env_id([rec for rec, _ in chosen], config["track"])
    spec = dataclasses.replace(gym.spec(env_id), kwargs={"config": config})
    buffers = []
    for i, (rec, arrays) in enumerate(chosen):
        options = rec.meta.get("reset_options")
        buffers.append(
            EpisodeBuffer(
                id=i,
                seed=rec.seed,
                options=dict(options) if options else None,
                observations=arrays["observations"],
                actions=arrays["actions"],
                rewards=arrays["rewards"].tolist(),
                terminations=arrays["terminations"].tolist(),
                truncations=arrays["truncations"].tolist(),
                # lists, not 1-D arrays: minari 0.5's arrow storage cannot decode the
                # empty shape it writes for per-step scalar arrays
                infos={k: v.tolist() for k, v in arrays["infos"].items()},
            )
        )
    sources = sorted({str(rec.meta.get("metadata", {}).get("driver", "")) for rec, _ in chosen})
    sources = [s for s in sources if s]
    default_description = (
        f"{len(chosen)} hasa_env recording(s) of {env_id} ({config['track']} road, "
        f"{config['sim_frequency'] / config['action_repeat']:g} Hz env steps); "
        f"{action_type} actions [road-wheel angle, acceleration]; "
        f"{config['observation']['type']} observations; infos: {', '.join(INFO_KEYS)}"
        + (f"; drivers: {', '.join(sources)}" if sources else "")
    )
    with _minari_path(data_path):
        if overwrite:
            with contextlib.suppress(FileNotFoundError):
                minari.delete_dataset(dataset_id)
        with warnings.catch_warnings():
            # Minari's recommendations (author, e-mail, code permalink, eval env) are optional
            warnings.filterwarnings("ignore", message=".* is set to None", category=UserWarning)
            dataset = minari.create_dataset_from_buffers(
                dataset_id=dataset_id,
                buffer=buffers,
                env=spec,
                algorithm_name=algorithm_name or "hasa_env recordings (human or synthetic drivers)",
                author=author,
                description=description or default_description,
                requirements=["hasa-env"],
                data_format="arrow",
            )
    return ExportResult(
        dataset=dataset,
        dataset_id=dataset_id,
        exported=[rec.path for rec, _ in chosen],
        skipped=skipped,
        cut=[rec.path for rec, arrays in chosen if arrays["cut"]],
        env_id=env_id,
        config=config,
    )


# ----------------------------------------------------------------- Parquet
def to_parquet(
    recording: Recording | str | os.PathLike[str], path: str | os.PathLike[str] | None = None
) -> Path:
    """Write one recording as a Parquet file; returns its path.

    Columns and dtypes are the recording's (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`:
    int64 ``step``/``bias_index``, bool flags, float64 values, bit-exact);
    the sidecar JSON is stored in the schema metadata under
    ``hasa_env.recording`` (read it back with :func:`read_parquet`). ``path``
    defaults to the CSV's path with ``.parquet``; an existing file is replaced.

    Raises:
        ImportError: pyarrow is not installed.
        RecordingError: the recording is corrupt (file, line, column).
    """
    pq = require_pyarrow()
    import pyarrow as pa

    if not isinstance(recording, Recording):
        recording = load_recording(recording)
    if path is None:
        if recording.path is None:
            raise ValueError("give a path for a recording that has no file")
        path = recording.path.with_suffix(".parquet")
    path = Path(path)
    table = pa.Table.from_pandas(recording.data[list(RECORDING_COLUMNS)], preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[PARQUET_METADATA_KEY] = json.dumps(recording.meta, allow_nan=False).encode("utf-8")
    table = table.replace_schema_metadata(meta)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path


def read_parquet(path: str | os.PathLike[str]) -> Recording:
    """Read a recording written by :func:`to_parquet` (validated like a CSV recording).

    Raises:
        ImportError: pyarrow is not installed.
        RecordingError: not a hasa_env recording, or invalid columns or values.
    """
    pq = require_pyarrow()
    path = Path(path)
    try:
        table = pq.read_table(path)
    except FileNotFoundError:
        raise RecordingError("no such Parquet file", path) from None
    except OSError as exc:  # pyarrow raises ArrowInvalid (an OSError subclass) on bad files
        raise RecordingError(f"unreadable Parquet file: {exc}", path) from None
    raw = (table.schema.metadata or {}).get(PARQUET_METADATA_KEY)
    if raw is None:
        raise RecordingError(
            "not a hasa_env recording: no 'hasa_env.recording' sidecar in the Parquet metadata",
            path,
        )
    try:
        meta = _validate_meta(json.loads(raw.decode("utf-8")), path)
    except json.JSONDecodeError as exc:
        raise RecordingError(f"sidecar metadata is not valid JSON: {exc.msg}", path) from None
    names = list(table.column_names)
    if names != list(RECORDING_COLUMNS):
        missing = [c for c in RECORDING_COLUMNS if c not in names]
        extra = [c for c in names if c not in RECORDING_COLUMNS]
        raise RecordingError(
            f"columns differ from the schema (missing {missing}, unknown {extra})",
            path,
            column=(missing or extra or [None])[0],
        )
    frame = table.to_pandas()
    for column in RECORDING_COLUMNS:
        expected = (
            np.int64
            if column in ("step", "bias_index")
            else (np.bool_ if column in ("terminated", "truncated") else np.float64)
        )
        if frame[column].dtype != expected:
            raise RecordingError(
                f"dtype {frame[column].dtype} instead of {np.dtype(expected)}", path, column=column
            )
        if expected is np.float64:
            bad = np.flatnonzero(~np.isfinite(frame[column].to_numpy()))
            if bad.size:
                raise RecordingError(f"row {int(bad[0])}: non-finite value", path, column=column)
    step = frame["step"].to_numpy()
    bad = np.flatnonzero(step != np.arange(len(step)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(f"row {i}: step = {int(step[i])}, expected {i}", path, column="step")
    config = meta["config"]
    expected = step * config["action_repeat"] * (1.0 / config["sim_frequency"])
    time = frame["time"].to_numpy()
    bad = np.flatnonzero(np.abs(time - expected) > 1e-9 * np.maximum(1.0, np.abs(expected)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(
            f"row {i}: time = {time[i]!r} s, expected {expected[i]!r} s", path, column="time"
        )
    return Recording(frame, meta, path)


# ----------------------------------------------------------------- summary
@dataclass(frozen=True)
class RecordingSummary:
    """What ``hasa-rec info`` prints about one valid recording (SI units, radians)."""

    path: Path | None
    steps: int
    duration: float
    env_step: float
    complete: bool
    end_reason: str | None
    seed: int | None
    env_id: str | None
    track: str
    sim_frequency: float
    action_repeat: int
    action_type: str
    observation_type: str
    hypotheses: tuple[float, ...]
    camera_noise: float
    bias: float
    bias_index: int
    lateral_rmse: float
    max_abs_lateral: float
    total_reward: float
    terminated: bool
    truncated: bool
    metadata: dict[str, Any]
    warnings: tuple[str, ...]

    def lines(self) -> list[str]:
        """Human-readable lines."""
        policy_rate = self.sim_frequency / self.action_repeat
        end = self.end_reason or ("terminated" if self.terminated else "running / unknown")
        out = [
            f"file           {self.path}",
            f"valid          yes ({'complete' if self.complete else 'INCOMPLETE: not finalized'})",
            f"steps          {self.steps} env steps, {self.duration:.2f} s "
            f"(env step {self.env_step:g} s)",
            f"end            {end}",
            f"env            {self.env_id or 'unknown id'}, track {self.track}, "
            f"{self.sim_frequency:g} Hz simulation, action_repeat {self.action_repeat} "
            f"({policy_rate:g} Hz policy)",
            f"spaces         {self.action_type} actions, {self.observation_type} observations",
            f"markings       hypotheses {list(self.hypotheses)} m, camera noise "
            f"{self.camera_noise:g} m",
            f"bias           b = {self.bias:+g} m (hypothesis {self.bias_index})",
            f"lateral        RMSE {self.lateral_rmse:.3f} m, max |y| {self.max_abs_lateral:.3f} m",
            f"return         {self.total_reward:.3f}",
            f"seed           {self.seed}",
        ]
        if self.metadata:
            out.append(f"metadata       {json.dumps(self.metadata, sort_keys=True)}")
        out.extend(f"warning        {w}" for w in self.warnings)
        return out


def _load_any(path: str | os.PathLike[str]) -> Recording:
    p = Path(path)
    if p.suffix == ".parquet":
        return read_parquet(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)
        return load_recording(p)


def summarize(path: str | os.PathLike[str] | Recording) -> RecordingSummary:
    """Load, validate and summarise a recording (CSV + sidecar, or a converted Parquet file).

    The lateral RMSE and max |y| are of the true lateral offset over rows
    1..n (the reset row excluded; row 0 alone if there are no steps).

    Raises:
        RecordingError: the recording is corrupt (file, line and column named).
    """
    rec = path if isinstance(path, Recording) else _load_any(path)
    data = rec.data
    config = rec.config
    env_step = config["action_repeat"] / config["sim_frequency"]
    y = data["lateral_offset"].to_numpy()
    y = y[1:] if len(y) > 1 else y
    last = data.iloc[-1]
    return RecordingSummary(
        path=rec.path,
        steps=rec.steps,
        duration=float(data["time"].iloc[-1]),
        env_step=env_step,
        complete=rec.complete,
        end_reason=rec.meta.get("end_reason"),
        seed=rec.seed,
        env_id=rec.meta.get("env_id"),
        track=config["track"],
        sim_frequency=float(config["sim_frequency"]),
        action_repeat=int(config["action_repeat"]),
        action_type=config["action"]["type"],
        observation_type=config["observation"]["type"],
        hypotheses=tuple(config["markings"]["hypotheses"]),
        camera_noise=float(config["noise"]["camera"]),
        bias=float(data["bias"].iloc[0]),
        bias_index=int(data["bias_index"].iloc[0]),
        lateral_rmse=float(math.sqrt(np.mean(y * y))),
        max_abs_lateral=float(np.max(np.abs(y))),
        total_reward=float(data["reward"].sum()),
        terminated=bool(last["terminated"]),
        truncated=bool(last["truncated"]),
        metadata=dict(rec.meta.get("metadata") or {}),
        warnings=tuple(rec.warnings),
    )

"""Recordings as offline-RL datasets: the Minari export.

:func:`export_minari` turns recordings (a folder of them, human or
synthetic) into a `Minari <https://minari.farama.org>`_ dataset that
``minari.load_dataset`` loads and ``recover_environment()`` rebuilds. Minari
is an optional extra, imported when used; a clear ``ImportError`` says how to
install it. Parquet conversion: :mod:`hasa_env.recording.parquet`.

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
import os
import re
import shutil
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

from hasa_env.extras import install_hint
from hasa_env.recording.format import (
    Recording,
    RecordingError,
    RecordingWarning,
)
from hasa_env.recording.reader import (
    load_recording,
    load_recordings,
    subfolder_hint,
    warn_load_notes,
)
from hasa_env.sim.config import deep_merge
from hasa_env.sim.sensors import SENSOR_NAMES
from hasa_env.sim.setup import INFO_KEYS, STATE_NAMES, EnvSetup, build_setup

__all__ = [
    "ExportResult",
    "action_columns",
    "episode_arrays",
    "export_minari",
    "observations",
    "require_minari",
]


ACTION_TYPES = ("physical", "normalized")
OBSERVATION_TYPES = ("sensors", "state", "both")
_SENSOR_COLUMNS = tuple(f"sensor_{name}" for name in SENSOR_NAMES)
_ID_FOR_TRACK = {"straight": "hasa_env/LaneKeeping-v0", "curved": "hasa_env/LaneKeepingCurved-v0"}


def require_minari() -> Any:
    """Import and return ``minari``, or raise ImportError saying how to install it."""
    try:
        import minari  # optional extra 'minari'
    except ImportError as exc:
        raise ImportError(
            f"Minari is not installed; install the minari extra: {install_hint('minari')}"
        ) from exc
    try:
        import pyarrow  # noqa: F401 - Minari's default (arrow) storage needs it
    except ImportError as exc:
        raise ImportError(
            f"Minari's arrow storage needs pyarrow; install the minari extra: {install_hint('minari')}"
        ) from exc
    return minari


# ----------------------------------------------------------- conversions
def _setup(config: Mapping[str, Any]) -> EnvSetup:
    return build_setup(config)


def observations(
    data: pd.DataFrame, config: Mapping[str, Any], kind: str | None = None
) -> np.ndarray | dict[str, np.ndarray]:
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
        exported: the recordings (CSV paths; None for one built in memory) in the
            dataset, episode i = exported[i].
        skipped: (path, reason) of every recording left out: corrupt files,
            recordings without steps, configs that differ from the first one.
        cut: exported recordings whose last step was marked truncated because
            they ended without termination or truncation.
        env_id: the env id stored in the dataset's spec.
        config: the config the recovered env is built with.
    """

    dataset: Any
    dataset_id: str
    exported: list[Path | None] = field(default_factory=list)
    skipped: list[tuple[Path | None, str]] = field(default_factory=list)
    cut: list[Path | None] = field(default_factory=list)
    env_id: str = ""
    config: dict[str, Any] = field(default_factory=dict)


def _check_written(dataset: Any, buffers: Sequence[Any], target: Path) -> None:
    """Raise OSError unless ``dataset`` holds every episode and step of ``buffers``."""
    episodes, steps = len(buffers), sum(len(b.rewards) for b in buffers)
    if dataset.total_episodes != episodes or dataset.total_steps != steps:
        raise OSError(
            f"{target}: the dataset written holds {dataset.total_episodes} of {episodes} "
            f"episodes and {dataset.total_steps} of {steps} steps (a full disk?); removed"
        )


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
    """Recordings from a folder or a list (of Recordings or paths), plus the corrupt ones.

    Loaded quietly (:func:`export_minari` warns once about each corrupt one, as not
    exported); what loading repaired in a recording loaded here is shown by
    :func:`warn_load_notes`."""
    skipped: list[tuple[Path | None, str]] = []
    if isinstance(source, str | os.PathLike):
        root = Path(source)
        if not root.is_dir():
            raise FileNotFoundError(f"recordings folder {str(root)!r} does not exist")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordingWarning)
            loaded = load_recordings(root)
        warn_load_notes(loaded)  # e.g. a crashed recording's cut last line, dropped
        for err in loaded.errors:
            skipped.append((err.path, err.located))
        return list(loaded), skipped
    recordings: list[Recording] = []
    for item in source:
        if isinstance(item, Recording):
            recordings.append(item)
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RecordingWarning)
                rec = load_recording(item)
        except RecordingError as err:
            skipped.append((err.path or Path(item), str(err)))
            continue
        warn_load_notes([rec])
        recordings.append(rec)
    return recordings, skipped


def _env_id(recordings: Sequence[Recording], track: str) -> str:
    for rec in recordings:
        env_id = rec.meta.get("env_id")
        if env_id in _ID_FOR_TRACK.values():
            return str(env_id)
    return _ID_FOR_TRACK[track]


def _check_export_arguments(
    dataset_id: str, action_type: str, observation_type: str | None
) -> None:
    """``ValueError`` for a malformed Minari dataset id or an unknown action or observation
    type (the arguments of :func:`export_minari`)."""
    # minari is the optional 'minari' extra: imported only when exporting
    from minari.dataset.minari_dataset import parse_dataset_id  # optional extra

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


def _exportable(
    recordings: Sequence[Recording],
    skipped: list[tuple[Path | None, str]],
    action_type: str,
    observation_type: str | None,
) -> list[tuple[Recording, dict[str, Any]]]:
    """The recordings with steps whose config matches the first such recording's (apart
    from ``render``), each with its :func:`episode_arrays`; the others are appended to
    ``skipped`` with the reason."""
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
    return chosen


def _episode_buffers(chosen: Sequence[tuple[Recording, dict[str, Any]]]) -> list[Any]:
    """One Minari ``EpisodeBuffer`` per exported recording (id = its place in ``chosen``)."""
    # minari is the optional 'minari' extra: imported only when exporting
    from minari.data_collector.episode_buffer import EpisodeBuffer  # optional extra

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
    return buffers


def _default_description(
    chosen: Sequence[tuple[Recording, dict[str, Any]]],
    env_id: str,
    config: dict[str, Any],
    action_type: str,
) -> str:
    """The dataset description when none is given: count, env, road, step rate, action and
    observation types, infos and the drivers named in the recordings' metadata."""
    sources = sorted({str(rec.meta.get("metadata", {}).get("driver", "")) for rec, _ in chosen})
    sources = [s for s in sources if s]
    return (
        f"{len(chosen)} hasa_env recording(s) of {env_id} ({config['track']} road, "
        f"{config['sim_frequency'] / config['action_repeat']:g} Hz env steps); "
        f"{action_type} actions [road-wheel angle, acceleration]; "
        f"{config['observation']['type']} observations; infos: {', '.join(INFO_KEYS)}"
        + (f"; drivers: {', '.join(sources)}" if sources else "")
    )


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
    :attr:`ExportResult.skipped` and with a warning. What loading repaired in a
    recording read from a path (a crashed recording's partly written last line,
    dropped) is shown as a :class:`~hasa_env.recording.RecordingWarning` naming the
    file (:func:`hasa_env.recording.warn_load_notes`). The dataset's env spec is
    the registered id with ``kwargs={"config": <that config>}``, so
    ``dataset.recover_environment()`` is ``gym.make`` of exactly that env.

    Raises:
        ImportError: Minari (or pyarrow) is not installed.
        ValueError: a malformed dataset id, an unknown type, an existing dataset
            without ``overwrite``, or no exportable recording.
    """
    minari = require_minari()
    _check_export_arguments(dataset_id, action_type, observation_type)
    recordings, skipped = _load_sources(source)
    chosen = _exportable(recordings, skipped, action_type, observation_type)
    for path, reason in skipped:
        warnings.warn(f"not exported: {path}: {reason}", RecordingWarning, stacklevel=2)
    if not chosen:
        nested = subfolder_hint(source) if isinstance(source, (str, os.PathLike)) else ""
        raise ValueError(
            "no recording to export"
            + (": " + "; ".join(f"{p}: {r}" for p, r in skipped) if skipped else nested)
        )
    first = chosen[0][0]
    config = dataset_config(first.config, action_type, observation_type)
    env_id = _env_id([rec for rec, _ in chosen], config["track"])
    spec = dataclasses.replace(gym.spec(env_id), kwargs={"config": config})
    buffers = _episode_buffers(chosen)
    default_description = _default_description(chosen, env_id, config, action_type)
    with _minari_path(data_path):
        if overwrite:
            with contextlib.suppress(FileNotFoundError):
                minari.delete_dataset(dataset_id)
        target = Path(minari.storage.get_dataset_path(dataset_id))
        new = not os.path.lexists(target)
        try:
            with warnings.catch_warnings():
                # Minari's recommendations (author, e-mail, code permalink, eval env) are optional
                warnings.filterwarnings("ignore", message=".* is set to None", category=UserWarning)
                dataset = minari.create_dataset_from_buffers(
                    dataset_id=dataset_id,
                    buffer=buffers,
                    env=spec,
                    algorithm_name=algorithm_name
                    or "hasa_env recordings (human or synthetic drivers)",
                    author=author,
                    description=description or default_description,
                    requirements=["hasa-env"],
                    data_format="arrow",
                )
            _check_written(dataset, buffers, target)
        except BaseException:
            if new:  # a dataset cut by a full disk would load, and block the next export
                shutil.rmtree(target, ignore_errors=True)
            raise
    return ExportResult(
        dataset=dataset,
        dataset_id=dataset_id,
        exported=[rec.path for rec, _ in chosen],
        skipped=skipped,
        cut=[rec.path for rec, arrays in chosen if arrays["cut"]],
        env_id=env_id,
        config=config,
    )

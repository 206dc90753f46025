"""One recording described and validated: :func:`summarize` (``hasa-rec info``)."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.recording.format import Recording
from hasa_env.recording.reader import load_any

__all__ = ["RecordingSummary", "summarize"]


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


def summarize(path: str | os.PathLike[str] | Recording) -> RecordingSummary:
    """Load, validate and summarise a recording (CSV + sidecar, or a converted Parquet file).

    The lateral RMSE and max |y| are of the true lateral offset over rows
    1..n (the reset row excluded; row 0 alone if there are no steps).

    Raises:
        RecordingError: the recording is corrupt (file, line and column named).
    """
    rec = path if isinstance(path, Recording) else load_any(path)
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

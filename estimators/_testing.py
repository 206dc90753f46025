"""Closed-loop data for the estimator tests: an ARX steering model driving the env.

Private helper (the project's synthetic humans live in ``hasa_env.drivers``).
The driver acts on the env's true state at row k; its steering is applied
over the step ending at row k+1, the alignment of recordings
(``decision_lag = 1``)::

    delta_model(k+1) = sum_j a_j delta_model(k+1-j) + sum_j beta_j . u(k-j) + e(k+1)
    road-wheel angle = delta_model / steering_ratio

with e white Gaussian (``model_noise_std``, model units).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hasa_env.envs.vector import LaneKeepingVectorEnv
from hasa_env.sim.setup import INFO_KEYS, RECORDING_COLUMNS
from hasa_env.steering.arx import ARXForm

__all__ = ["drive_arx"]


def drive_arx(
    arx: ARXForm,
    *,
    runs: int = 4,
    duration: float = 30.0,
    seed: int = 0,
    bias_index: int | None = None,
    steering_ratio: float = 15.0,
    model_noise_std: float = 1e-3,
    config: dict | None = None,
) -> list[pd.DataFrame]:
    """Drive ``runs`` episodes of the straight-road env with an ARX driver.

    Returns one DataFrame per run with :data:`hasa_env.sim.setup.RECORDING_COLUMNS`
    (row 0 = reset state). ``bias_index`` fixes the true lane hypothesis
    (None: drawn by the env).
    """
    cfg = {"action": {"type": "physical"}, "time_limit": duration}
    if config:
        cfg = {**cfg, **config}
    env = LaneKeepingVectorEnv(num_envs=runs, config=cfg)
    options = None if bias_index is None else {"bias_index": int(bias_index)}
    _, info = env.reset(seed=seed, options=options)
    rng = np.random.default_rng(seed + 10_000)
    a, beta = _arx_coefficients(arx)
    n_a, n_u = len(a), beta.shape[0]
    delta_hist = np.zeros((runs, max(n_a, 1)))  # delta_model(k), delta_model(k-1), ...
    delta_hist[:] = (np.asarray(info["steering"]) * steering_ratio)[:, None]
    u_hist = np.zeros((runs, n_u, 3))  # u(k), u(k-1), ...
    u_hist[:] = _features(info, arx.near_distance, arx.far_distance)[:, None, :]
    max_steering = env.setup.steering_limit
    zeros = np.zeros(runs)
    no = zeros.astype(bool)
    rows = [[_row(0, info, i, zeros, no, no)] for i in range(runs)]
    done = np.zeros(runs, dtype=bool)
    step = 0
    while not done.all():
        delta = delta_hist[:, :n_a] @ a + np.einsum("rjc,jc->r", u_hist, beta)
        delta += model_noise_std * rng.standard_normal(runs)
        action = np.stack(
            [np.clip(delta / steering_ratio, -max_steering, max_steering), zeros], axis=1
        )
        _, reward, terminated, truncated, info = env.step(action)
        step += 1
        delta_hist = np.roll(delta_hist, 1, axis=1)
        delta_hist[:, 0] = action[:, 0] * steering_ratio
        u_hist = np.roll(u_hist, 1, axis=1)
        u_hist[:, 0] = _features(info, arx.near_distance, arx.far_distance)
        for i in np.flatnonzero(~done):
            rows[i].append(_row(step, info, int(i), reward, terminated, truncated))
        done |= terminated | truncated
    env.close()
    frames = []
    for r in rows:
        frame = pd.DataFrame(r, columns=list(RECORDING_COLUMNS))
        frame["bias_index"] = frame["bias_index"].astype(int)
        frames.append(frame)
    return frames


def _arx_coefficients(arx: ARXForm) -> tuple[np.ndarray, np.ndarray]:
    """The autoregressive coefficients a_j (n_a,) and the input coefficients
    beta_j = [b_j, c_j, d_j] (n_u, 3) (zero beyond each list's length)."""
    n_u = max(len(arx.b), len(arx.c), len(arx.d))
    beta = np.zeros((n_u, 3))
    for column, coefficients in enumerate((arx.b, arx.c, arx.d)):
        beta[: len(coefficients), column] = coefficients
    return np.asarray(arx.a), beta


def _features(info: dict, near: float, far: float) -> np.ndarray:
    """The ARX inputs u = [-(theta + atan(y / near)), -(theta + atan(y / far)), v_y], (R, 3)."""
    y = np.asarray(info["lateral_offset"])
    th = np.asarray(info["heading"])
    return np.stack(
        [
            -(th + np.arctan(y / near)),
            -(th + np.arctan(y / far)),
            np.asarray(info["lateral_velocity"]),
        ],
        axis=1,
    )


def _row(
    step: int,
    info: dict,
    run: int,
    reward: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
) -> list:
    """Run ``run``'s recording row at ``step`` (:data:`RECORDING_COLUMNS` order)."""
    return [
        step,
        *(info[key][run] for key in INFO_KEYS),
        float(reward[run]),
        bool(terminated[run]),
        bool(truncated[run]),
    ]

"""How overconfident the raw lane evidence is, and what the evidence checks do about it.

``python -m benchmarks.evidence_dispersion [--population paper] [--seed 0] [--runs 3]``

The paper's generalized model (:meth:`GeneralizedModel.paper`) filters runs of
every driver of a population, with and without the evidence checks
(:mod:`estimators.evidence`). Per run it prints:

- ``sum_d``: the raw log-likelihood ratio of the true over the wrong lane,
  summed over the run (nats; the filter without the checks, no floor), from
  0.5 s on;
- ``tau_data``: the batch-means calibration factor of that sum,
  ``Var(sum d) / (2 sum d)`` with the variance from 1 s blocks: how many
  times larger the sum's spread is than a correct likelihood's (for which
  ``Var = 2 E``), i.e. what the evidence would have to be divided by;
- ``tau_rule``: the median evidence scale the rule used (``Estimate.evidence_scale``);
- ``lambda``: the median model-error ratio (``Estimate.model_error``);
- the final weight of the true lane, and the time (s) from which it stays
  above 0.99, without and with the checks; the lateral RMSE (m) both ways.

docs/design.md §8.11 quotes its numbers.
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Sequence

import numpy as np

from estimators.base import ACCELERATION_KEYS, MEASUREMENT_KEYS
from estimators.gm_ekf import GaussianMixtureEKF
from hasa_env.drivers import population, run_population
from hasa_env.steering import GeneralizedModel

__all__ = ["evidence_dispersion_table", "main"]

HYPOTHESES = (0.0, -1.8)
BLOCK = 100  # samples per batch-means block (1 s at 100 Hz)
SKIP = 50  # samples skipped at the start (the first 0.5 s)


def _settle_time(weight: np.ndarray, dt: float, threshold: float = 0.99) -> float:
    below = np.flatnonzero(weight <= threshold)
    if below.size == 0:
        return 0.0
    return float("nan") if below[-1] + 1 >= weight.size else (below[-1] + 1) * dt


def evidence_dispersion_table(
    population_name: str = "paper", seed: int = 0, runs: int = 3
) -> list[dict[str, float | str]]:
    """One row per run (see the module docstring); the true lane is hypothesis 0."""
    drivers = population(population_name, seed=seed)
    recorded = run_population(drivers, runs=runs, seed=seed, options={"bias_index": 0})
    owners = [name for name, frames in recorded.items() for _ in frames]
    frames = [f for frames in recorded.values() for f in frames]
    z = np.stack([f[list(MEASUREMENT_KEYS)].to_numpy() for f in frames])
    a = np.stack([f[list(ACCELERATION_KEYS)].to_numpy() for f in frames])
    truth = np.stack([f["lateral_offset"].to_numpy() for f in frames])
    arx = GeneralizedModel.paper().arx()
    traces = {}
    for checks in (False, True):
        ekf = GaussianMixtureEKF(arx, evidence_checks=checks, weight_floor=0.0)
        est = ekf.reset(z[:, 0], HYPOTHESES)
        log_w, lateral, scale, error = [est.log_weights], [est.lateral_offset], [], []
        for k in range(1, z.shape[1]):
            est = ekf.step(z[:, k], a[:, k])
            log_w.append(est.log_weights)
            lateral.append(est.lateral_offset)
            scale.append(est.evidence_scale)
            error.append(est.model_error)
        traces[checks] = {
            "log_w": np.array(log_w),
            "lateral": np.array(lateral),
            "scale": np.array(scale),
            "error": np.array(error),
        }
    raw = traces[False]["log_w"]
    increments = np.diff(raw[:, :, 0] - raw[:, :, 1], axis=0)[SKIP:]
    dt = arx.dt
    rows: list[dict[str, float | str]] = []
    for r, owner in enumerate(owners):
        d = increments[:, r]
        n = d.size // BLOCK
        blocks = d[: n * BLOCK].reshape(n, BLOCK).sum(axis=1)
        total = float(blocks.sum())
        row: dict[str, float | str] = {
            "driver": owner,
            "sum_d": total,
            "tau_data": float(blocks.var(ddof=1) * n / (2.0 * abs(total))),
            "tau_rule": float(np.median(traces[True]["scale"][:, r])),
            "lambda": float(np.nanmedian(traces[True]["error"][:, r])),
        }
        for checks, label in ((False, "raw"), (True, "checked")):
            run_log_w = traces[checks]["log_w"][:, r]
            weight = np.exp(run_log_w[:, 0] - np.logaddexp(run_log_w[:, 0], run_log_w[:, 1]))
            miss = traces[checks]["lateral"][:, r] - truth[r]
            row[f"final_weight_{label}"] = float(weight[-1])
            row[f"settle_s_{label}"] = _settle_time(weight, dt)
            row[f"rmse_{label}"] = float(np.sqrt(np.mean(miss * miss)))
        rows.append(row)
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.evidence_dispersion", allow_abbrev=False
    )
    parser.add_argument("--population", default="paper")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--runs", type=int, default=3, help="runs per driver")
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        rows = evidence_dispersion_table(args.population, args.seed, args.runs)
    keys = list(rows[0])
    print("  ".join(f"{k:>14}" for k in keys))
    for row in rows:
        print("  ".join(f"{v:>14}" if isinstance(v, str) else f"{v:14.4g}" for v in row.values()))
    ratio = np.array([float(r["tau_rule"]) / float(r["tau_data"]) for r in rows])
    rmse = {k: np.mean([float(r[f"rmse_{k}"]) for r in rows]) for k in ("raw", "checked")}
    settle = {k: np.nanmax([float(r[f"settle_s_{k}"]) for r in rows]) for k in ("raw", "checked")}
    print(
        f"\ntau_rule / tau_data: {ratio.min():.2f}-{ratio.max():.2f}; lateral RMSE raw "
        f"{rmse['raw']:.4f} m, checked {rmse['checked']:.4f} m; settled (> 0.99) after at "
        f"most {settle['raw']:.2f} s raw, {settle['checked']:.2f} s checked"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

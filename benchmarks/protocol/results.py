"""The result of a benchmark run and its JSON document."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from benchmarks import paper_values
from benchmarks.documents import json_clean, versions
from hasa_env.steering.loading import PAPER_STEERING_RATIO

__all__ = ["RESULTS_FORMAT", "BenchmarkResult", "versions"]


_TABLE_1_KEYS = (
    "two_point_rmse", "two_point_r2_acc", "generalized_rmse", "generalized_r2_acc", "rmse_decrease"
)  # fmt: skip
_TABLE_2_KEYS = ("two_point_mean", "two_point_std", "generalized_mean", "generalized_std")


RESULTS_FORMAT = "hasa_bench.results"
"""The ``format`` of a ``results.json`` (what marks a folder as a previous result)."""


@dataclass
class BenchmarkResult:
    """Everything :func:`run_protocol` measured (see :meth:`to_json_dict`).

    Attributes:
        config: the protocol configuration (dict).
        models: per model and seed: name, kind, spec, seed, parameters, fit
            statistics, ``checks`` (condition number, AR poles, stability,
            identifiability, ridge penalty), notes.
        steering: rows per (seed, driver, model), main track (paper table 1).
        curved: rows per (seed, driver, model) on the curved track.
        estimation: rows per (seed, driver, model) incl. the baselines (paper table 2).
        curved_estimation: the same on the curved track.
        seed_summary: per (seed, model), means over drivers and the ranks.
        summary: per model, the verdict over seeds (or the participants of recordings):
            means with 95 % hierarchical-bootstrap intervals, shares of runs with exact
            binomial intervals, decision metrics, ranks among every ranked model and their
            stability (:func:`benchmarks.protocol.aggregate.verdict`; format_version 3).
        runs_steering, runs_estimation: per-run rows (with their seed).
        errors: failed user models (:meth:`ModelError.to_dict`).
        drivers: the drivers (synthetic parameters or recording files).
        plots: data of the figures (not written to results.json).
        timing: wall-clock seconds per phase; executor: how tasks ran.
        notes: what the reader should know (files used, tracks not scored, ...).
        skipped: the recordings that were not used, ``{"file", "reason"}`` each
            (a file that does not load, or fails a quality gate).
        degenerate: the runs left out of every mean, ``{"seed", "driver",
            "track", "run", "file", "reason"}`` each
            (:func:`benchmarks.protocol.tasks.degenerate_reason`).
        baselines: the fitted baselines, per seed: ``{"name", "seed", "params"}``
            (the lane-centring prior fitted on that seed's training run,
            :meth:`estimators.lane_centring.LaneCentringParams.to_dict`).
    """

    config: dict[str, Any]
    models: list[dict[str, Any]]
    steering: list[dict[str, Any]]
    curved: list[dict[str, Any]]
    estimation: list[dict[str, Any]]
    curved_estimation: list[dict[str, Any]]
    seed_summary: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    runs_steering: list[dict[str, Any]]
    runs_estimation: list[dict[str, Any]]
    errors: list[dict[str, str]]
    drivers: list[dict[str, Any]]
    plots: dict[str, Any]
    timing: dict[str, float]
    executor: dict[str, Any]
    versions: dict[str, str]
    notes: list[str] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    degenerate: list[dict[str, Any]] = field(default_factory=list)
    baselines: list[dict[str, Any]] = field(default_factory=list)

    @property
    def model_names(self) -> list[str]:
        """Steering models that were scored, built-ins first."""
        return list(dict.fromkeys(m["name"] for m in self.models if m.get("error") is None))

    def to_json_dict(self) -> dict[str, Any]:
        """The JSON document of ``results.json`` (NaN and infinities become null)."""
        doc = {
            "format": RESULTS_FORMAT,
            "format_version": 3,
            "config": self.config,
            "versions": self.versions,
            "executor": self.executor,
            "timing_seconds": self.timing,
            "drivers": self.drivers,
            "models": self.models,
            "baselines": self.baselines,
            "steering": self.steering,
            "curved": self.curved,
            "estimation": self.estimation,
            "curved_estimation": self.curved_estimation,
            "seed_summary": self.seed_summary,
            "summary": self.summary,
            "runs_steering": self.runs_steering,
            "runs_estimation": self.runs_estimation,
            "errors": self.errors,
            "skipped": self.skipped,
            "degenerate": self.degenerate,
            "notes": self.notes,
            "paper": {
                "table_1": {
                    d: dict(zip(_TABLE_1_KEYS, v, strict=True))
                    for d, v in paper_values.TABLE_1.items()
                },
                "table_1_units": (
                    "RMSE in rad of the steering WHEEL, as printed; the steering rows' "
                    f"paper_rmse is it divided by the steering ratio {PAPER_STEERING_RATIO:g} "
                    "(road-wheel rad, the unit of rmse)"
                ),
                "table_2": {
                    d: dict(zip(_TABLE_2_KEYS, v, strict=True))
                    for d, v in paper_values.TABLE_2.items()
                },
                "curved": {k: {"r2": v[0], "rmse": v[1]} for k, v in paper_values.CURVED.items()},
                "no_steering_lateral_rmse": paper_values.NO_STEERING_LATERAL_RMSE,
            },
        }
        return json_clean(doc)

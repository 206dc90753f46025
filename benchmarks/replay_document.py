"""The document ``hasa-replay --json`` writes (:class:`ReplayDocument`): what the steps of
:mod:`benchmarks.recordings` found, collected step by step and written atomically, so that a
run that ends early keeps what was done."""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from benchmarks.documents import json_clean, versions
from benchmarks.recordings import (
    SPEED_SCALED_KEYS,
    PreparedModel,
    RecordingOutcome,
    ReplayCheck,
    WarningLog,
)
from benchmarks.replay_estimate import estimate_verdict
from estimators.offline import EstimatorRun
from hasa_env.atomic import write_atomic

__all__ = ["REPLAY_FORMAT", "ReplayDocument"]


REPLAY_FORMAT = "hasa_replay.results"
"""The ``format`` of the document :class:`ReplayDocument` writes (``hasa-replay --json``)."""


def _estimate_dict(run: EstimatorRun) -> dict[str, Any]:
    """An estimator run's result as JSON data (what :func:`describe_estimate` says, and the
    reasons of the filter that ran)."""
    return {
        "lateral_rmse": run.lateral_rmse,
        "hypotheses": run.hypotheses,
        "final_weights": run.weights[-1],
        "true_index": None if run.true_index < 0 else run.true_index,
        "true_lane_weight": run.final_true_weight,
        "trusted_from": run.trusted_from,
        "final_decision": run.final_decision,
        "refused_by": run.refused_by,
        "trust_reasons": None if run.trust is None else list(run.trust.reasons),
        **estimate_verdict(run),
    }


@dataclass
class ReplayDocument:
    """What ``hasa-replay`` found, collected step by step as one JSON document
    (:meth:`to_dict`, :meth:`write`), so that a run that ends early keeps what was done.

    Attributes:
        arguments: the arguments that matter (model spec, atol, estimator on or off, ...).
        load_errors: the files that could not be loaded, ``{"path", "message"}`` each.
        recordings: per loaded recording, in order: ``path``, ``label``, ``steps``,
            ``complete``, ``replay`` (:meth:`ReplayCheck.to_dict`) and, when those steps
            ran, ``model`` (``{"scores": {...}}`` of :data:`SCORE_KEYS`, or ``{"error"}``),
            ``estimator`` (the result, or ``{"error"}``), ``frames`` (``{"written",
            "directory"}`` or ``{"error"}``).
        model: the model used (:meth:`add_model`: ``spec``, ``steering_ratio``, ``fitted_on``,
            ``fitted_on_recordings``, the keys of :data:`SPEED_SCALED_KEYS`), None before (or
            without) one.
        estimator_trust: the trust line shared by every recording's filter (None: none).
        warnings: the warnings shown while it listened (:meth:`WarningLog.listen`; the steps
            given it say on which recording each arose), the document's ``warnings``.
        error: why the run ended early (None: it did not).
        exit_status: the program's exit status.
    """

    arguments: dict[str, Any]
    load_errors: list[dict[str, Any]] = field(default_factory=list)
    recordings: list[dict[str, Any]] = field(default_factory=list)
    model: dict[str, Any] | None = None
    estimator_trust: str | None = None
    warnings: WarningLog = field(default_factory=WarningLog)
    error: str | None = None
    exit_status: int | None = None

    def add_load_errors(self, errors: Sequence[Exception]) -> None:
        """The files that could not be loaded (:class:`~hasa_env.recording.RecordingError`)."""
        for exc in errors:
            path = getattr(exc, "path", None)
            self.load_errors.append(
                {"path": None if path is None else str(path), "message": str(exc)}
            )

    def add_checks(self, checks: Sequence[ReplayCheck]) -> None:
        """One entry per recording, with its replay check."""
        for check in checks:
            self.recordings.append(
                {"path": None if check.path is None else str(check.path), "label": check.label,
                 "steps": check.steps, "complete": check.complete, "replay": check.to_dict()}
            )  # fmt: skip

    def add_model(self, prepared: PreparedModel) -> None:
        """The model used: ``spec``, ``steering_ratio``, ``fitted_on`` (the first recording
        it was fitted on, as before ``--fit-on``; None: as loaded), ``fitted_on_recordings``
        (all of them, in order; empty: as loaded) and its fitted speed-scaled equation error's
        ``speed_scaled_error`` (numbers, or None), ``speed_scaled_held_out`` and
        ``speed_scaled_gain`` (each None when it was not fitted); ``equation_error_order``, the
        lags of its equation error's autoregression (0: white), and ``equation_error_ar``, the
        autoregression (empty: white; as hasa-bench's results.json)."""
        paths = [None if path is None else str(path) for path in prepared.fitted_on]
        found = prepared.speed_scaled or {}
        model = prepared.model
        self.model = json_clean({
            "spec": prepared.spec, "steering_ratio": prepared.steering_ratio,
            "fitted_on": paths[0] if paths else None, "fitted_on_recordings": paths,
            **{key: found.get(key) for key in SPEED_SCALED_KEYS},
            "equation_error_order": int(getattr(model, "equation_error_order", 0)),
            "equation_error_ar": list(getattr(model, "equation_error_ar", ()) or ()),
        })  # fmt: skip

    def add_outcomes(self, key: str, outcomes: Sequence[RecordingOutcome]) -> None:
        """Each outcome of a step under ``key`` of its recording: ``"model"`` (scores),
        ``"estimator"`` (:class:`~estimators.offline.EstimatorRun`) or ``"frames"``
        (frames written, folder); ``{"error": ...}`` for one that failed."""
        for o in outcomes:
            if o.error is not None:
                value: dict[str, Any] = {"error": o.error}
            elif key == "model":
                value = {"scores": dict(o.value)}
            elif key == "estimator":
                value = _estimate_dict(o.value)
            else:
                written, folder = o.value
                value = {"written": len(written), "directory": None if folder is None
                         else str(folder)}  # fmt: skip
            self.recordings[o.index][key] = json_clean(value)

    def to_dict(self) -> dict[str, Any]:
        """The document: ``format``, ``version`` (hasa-env's), ``versions`` (as hasa-bench's
        results.json), ``arguments``, ``model``, ``estimator_trust``, ``load_errors``,
        ``recordings``, ``warnings`` (:attr:`WarningLog.entries`), ``error``, ``exit_status``;
        NaN and infinities as None."""
        found = versions()
        return json_clean({
            "format": REPLAY_FORMAT, "version": found.get("hasa-env"), "versions": found,
            "arguments": self.arguments, "model": self.model,
            "estimator_trust": self.estimator_trust, "load_errors": self.load_errors,
            "recordings": self.recordings, "warnings": self.warnings.entries,
            "error": self.error, "exit_status": self.exit_status,
        })  # fmt: skip

    def write(self, path: str | os.PathLike[str]) -> None:
        """Write the document to ``path`` atomically (:func:`hasa_env.atomic.write_atomic`:
        the old file or the whole new one, never half of it).

        Raises:
            OSError: it cannot be written.
        """
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        write_atomic(path, text + "\n")

"""Recordings checked and analysed one by one: replay, a steering model's scores, the estimator.

The library side of ``hasa-replay`` (:mod:`hasa_cli.replay`), in four steps that
each take a list of loaded recordings (:func:`hasa_env.recording.load_paths`; what loading
repaired or tolerated in each is shown by :func:`warn_load_notes`):

1. :func:`check_recordings`: replay each recording's actions through the env
   (:func:`hasa_env.recording.check_replay`) and compare, bit for bit or within
   ``atol``;
2. :func:`prepare_model`: a steering model (:func:`hasa_env.steering.loading.load_model`),
   optionally fitted on the first recordings (a generalized model with its equation error's
   autoregression and speed-scaled equation error, as ``hasa-bench`` fits it), with its
   steering ratio (model units per recorded road-wheel rad) and where the estimator trusts it
   (:meth:`PreparedModel.trust`), and
   :func:`score_recordings`: its one-step-ahead scores on every recording
   (:func:`hasa_env.steering.score`: RMSE, R^2, R^2 of the increments, Ljung-Box p);
3. :func:`estimate_recordings`: the Gaussian-mixture EKF with that model over each
   recording's sensors (:func:`estimators.offline.estimate_recording`);
4. :func:`render_recordings`: PNG frames and/or a video of each recording
   (:func:`hasa_env.render.frames.write_frames`), with the estimator's weights.

A recording that fails a step is reported with its reason and the others go on.
:class:`benchmarks.replay_document.ReplayDocument` collects what the steps found as one JSON
document (``hasa-replay --json``), written atomically, with the warnings they raised
(:class:`WarningLog`: each step given one says which recording a warning arose on).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchmarks.defaults import DEFAULT_EQUATION_ERROR_ORDER
from benchmarks.documents import json_clean
from benchmarks.replay_estimate import describe_estimate
from benchmarks.speed_scaled import (
    add_speed_scaled_error,
    describe_equation_error,
    describe_speed_scaled,
    fits_speed_scaled_error,
)
from estimators.offline import EstimatorRun, estimate_recording
from estimators.trust import STEERING_EVERYWHERE, TrustedFilter, trusted_filter
from hasa_env.drivers import require_lane_keeping
from hasa_env.recording import check_replay
from hasa_env.recording import warn_load_notes as warn_recording_notes
from hasa_env.render.frames import write_frames
from hasa_env.sim.road import Road
from hasa_env.steering import GeneralizedModel, SteeringModel, score
from hasa_env.steering.equation_error import MAX_EQUATION_ERROR_ORDER
from hasa_env.steering.loading import (
    default_steering_ratio,
    in_model_units,
    load_model,
    model_spec_kind,
)

__all__ = [
    "MAX_STEERING_RATIO",
    "SCORE_KEYS",
    "SPEED_SCALED_KEYS",
    "LaneKeepingError",
    "ModelSetupError",
    "PreparedModel",
    "RecordingOutcome",
    "ReplayCheck",
    "TrustLines",
    "WarningLog",
    "check_recordings",
    "describe_equation_error",
    "describe_estimate",
    "describe_speed_scaled",
    "describe_trust",
    "estimate_recordings",
    "load_model_spec",
    "prepare_model",
    "render_recordings",
    "score_recordings",
    "warn_load_notes",
]

MAX_STEERING_RATIO = 1e4
"""Largest steering ratio (model units per road-wheel rad) accepted: a steering-wheel angle
in degrees is about 15 x 57 = 860 per road-wheel rad."""

SCORE_KEYS = ("rmse", "r2", "r2_increments", "ljung_box_p")
"""The scores :func:`score_recordings` keeps (of :func:`hasa_env.steering.score`)."""

SPEED_SCALED_KEYS = ("speed_scaled_error", "speed_scaled_held_out", "speed_scaled_gain")
"""What fitting a model's speed-scaled equation error records
(:func:`benchmarks.speed_scaled.add_speed_scaled_error`; hasa-bench's results.json has the
same keys), kept in the ``--json`` document's ``model``."""


@dataclass
class WarningLog:
    """The warnings shown while it listens (:meth:`listen`), each kept with where it arose
    (:meth:`about`) and still shown as before.

    Attributes:
        entries: in the order shown, ``{"recording", "step", "category", "message"}`` each:
            the recording's path (None: not one recording's, e.g. loading a model), the step
            (``"load"``, ``"replay"``, ``"model"``, ``"estimator"``, ``"frames"``; None: none
            said), the warning's class name (e.g. ``"IdentifiabilityWarning"``) and its text.
    """

    entries: list[dict[str, Any]] = field(default_factory=list)
    _where: tuple[str | None, str | None] = (None, None)

    @contextmanager
    def listen(self) -> Iterator[None]:
        """Keep every warning the block shows: those the warning filters let through (not an
        ignored one, nor a repeat they hide), shown at once by the :func:`warnings.showwarning`
        in place (hasa-replay's one-line ``warning:`` format), so stderr is unchanged."""
        with warnings.catch_warnings():
            shown = warnings.showwarning

            def show(
                message: Warning | str,
                category: type[Warning],
                filename: str,
                lineno: int,
                file: Any = None,
                line: str | None = None,
            ) -> None:
                recording, step = self._where
                self.entries.append(
                    {
                        "recording": recording,
                        "step": step,
                        "category": category.__name__,
                        "message": str(message),
                    }
                )
                shown(message, category, filename, lineno, file, line)

            warnings.showwarning = show
            yield

    @contextmanager
    def about(self, recording: str | os.PathLike[str] | None, step: str) -> Iterator[None]:
        """Warnings shown in the block arose on ``recording`` (None: on no one recording) in
        ``step``; an inner :meth:`about` says more."""
        before = self._where
        self._where = (None if recording is None else str(recording), step)
        try:
            yield
        finally:
            self._where = before


def _about(
    log: WarningLog | None, recording: str | os.PathLike[str] | None, step: str
) -> AbstractContextManager[None]:
    """``log.about(recording, step)``, or nothing without a log."""
    return nullcontext() if log is None else log.about(recording, step)


def warn_load_notes(recordings: Sequence[Any], log: WarningLog | None = None) -> None:
    """Show each recording's notes from loading (:attr:`hasa_env.recording.Recording.warnings`:
    what was repaired or tolerated, e.g. the partly written last line of a crashed recording
    dropped), in order, as :class:`~hasa_env.recording.RecordingWarning` naming the file
    (:func:`hasa_env.recording.warn_load_notes`, at the caller's line). ``log``: each the
    recording's (step ``"load"``)."""
    for rec in recordings:
        with _about(log, rec.path, "load"):
            warn_recording_notes([rec], stacklevel=2)


@dataclass(frozen=True)
class ReplayCheck:
    """One recording replayed: what it is and whether it reproduces.

    Attributes:
        path: the recording; label: "synthetic" or "recorded"; steps: its rows;
        complete: its writer finalized it; matches: the replay reproduces it (False
        when it cannot be replayed); text: the comparison (where it first diverges) or
        why it cannot be replayed; divergence: where it first diverges, ``(row, column,
        recorded value, replayed value)`` (a value is None past the end of the shorter
        one; None: it matches or cannot be replayed); time: the simulated time (s) of
        that row (NaN when there is none).
    """

    path: Path | None
    label: str
    steps: int
    complete: bool
    matches: bool
    text: str
    divergence: tuple[int, str, Any, Any] | None = None
    time: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """The check as JSON data (NaN as None): ``matches``, ``text`` and ``divergence``
        (``{"row", "time", "column", "recorded", "replayed"}`` or None)."""
        where = None
        if self.divergence is not None:
            row, column, recorded, replayed = self.divergence
            where = {"row": row, "time": self.time, "column": column, "recorded": recorded,
                     "replayed": replayed}  # fmt: skip
        return json_clean({"matches": self.matches, "text": self.text, "divergence": where})

    def describe(self) -> str:
        """One line: ``<path>: <label>, <steps> steps[ (incomplete...)]: <text>``."""
        complete = "" if self.complete else " (incomplete: its writer stopped early)"
        return f"{self.path}: {self.label}, {self.steps} steps{complete}: {self.text}"


def check_recordings(
    recordings: Sequence[Any], atol: float = 0.0, log: WarningLog | None = None
) -> list[ReplayCheck]:
    """Replay every recording and compare the replayed trajectory with the recorded one
    (``|replayed - recorded| <= atol``; 0: bit for bit). ``log``: the warnings shown are each
    the recording's (step ``"replay"``)."""
    checks = []
    for rec in recordings:
        label = "synthetic" if (rec.meta.get("metadata") or {}).get("synthetic") else "recorded"
        divergence, time = None, math.nan
        try:
            with _about(log, rec.path, "replay"):
                check = check_replay(rec, atol)
            matches, text = bool(check.matches), check.describe(atol)
            divergence, time = check.divergence, check.time
        except ValueError as exc:
            matches, text = False, f"cannot replay: {exc}"
        checks.append(ReplayCheck(rec.path, label, rec.steps, rec.complete, matches, text,
                                  divergence, time))  # fmt: skip
    return checks


class ModelSetupError(ValueError):
    """The steering model cannot be used: it does not load, or has no parameters to score."""


class LaneKeepingError(ValueError):
    """The steering model drives off the road when it steers itself (no lane evidence)."""


@dataclass(frozen=True)
class PreparedModel:
    """A steering model ready to score and estimate recordings.

    Attributes:
        spec: how it was named (a preset, a model file, ``package.module:Class``);
        model: the model (fitted); steering_ratio: model units per recorded road-wheel
        rad; fitted_on: the recordings it was fitted on, in order, each a run of its own
        (empty: as loaded); speed_scaled: what fitting its speed-scaled equation error
        found (:func:`benchmarks.speed_scaled.add_speed_scaled_error`: ``speed_scaled_error``,
        its numbers or None when none was found; ``speed_scaled_held_out``;
        ``speed_scaled_gain`` on the recordings fitted on), None when it was not fitted
        (no fit, turned off, or not a generalized model).
    """

    spec: str
    model: SteeringModel
    steering_ratio: float
    fitted_on: tuple[Path | None, ...] = ()
    speed_scaled: dict[str, Any] | None = None

    def trust(self) -> TrustedFilter:
        """Where the estimator would trust the model's steering without a recording, and why
        not elsewhere (:func:`estimators.trust.trusted_filter` on the default settings). Not
        the filter a recording gets: that one measures the model's residual levels on the
        recording, and takes a declared equation-error autoregression only where it lowers
        the model's one-step residual there (docs/design.md §8.32), which this one takes as
        declared. What each recording's filter said is in its run
        (:attr:`~estimators.offline.EstimatorRun.trust`; :func:`describe_trust`)."""
        return trusted_filter(self.model, steering_ratio=self.steering_ratio)


def load_model_spec(
    spec: str,
    recordings: Sequence[Any],
    *,
    fit: bool = False,
    fit_on: int = 1,
    equation_error_order: int | None = None,
    steering_ratio: float | None = None,
    trust_module: bool = False,
) -> SteeringModel:
    """The model ``spec`` loaded for ``recordings``' sample time, and the arguments
    :func:`prepare_model` takes with it checked, before anything is fitted or run: what a
    program asks first, so that a misspelt model refuses the run before any recording is
    replayed.

    Raises:
        ModelSetupError: as :func:`prepare_model`.
    """
    if steering_ratio is not None and not (0 < steering_ratio <= MAX_STEERING_RATIO):
        raise ModelSetupError(
            f"steering ratio must be a number in (0, {MAX_STEERING_RATIO:g}] (model units per "
            f"road-wheel rad), got {steering_ratio!r}"
        )
    if fit and not _is_int_in(fit_on, 1, len(recordings)):
        raise ModelSetupError(
            f"--fit-on must be an integer from 1 to {len(recordings)} (the recordings loaded), "
            f"got {fit_on!r}"
        )
    if equation_error_order is not None and not _is_int_in(
        equation_error_order, 0, MAX_EQUATION_ERROR_ORDER
    ):
        raise ModelSetupError(
            f"--equation-error-order must be an integer in [0, {MAX_EQUATION_ERROR_ORDER}] "
            f"(0: white), got {equation_error_order!r}"
        )
    try:
        model = load_model(spec, recordings[0].dt, trust_module=trust_module)
    except (ValueError, OSError) as exc:
        raise ModelSetupError(str(exc)) from None
    if not model.is_fitted and not fit:
        raise ModelSetupError(
            f"model {spec!r} has no parameters: add --fit to fit it on the first "
            "recording, or give a saved model file (model.save('model.json'))"
        )
    return model


def prepare_model(
    spec: str,
    recordings: Sequence[Any],
    *,
    fit: bool = False,
    fit_on: int = 1,
    speed_scaled_error: bool = True,
    equation_error_order: int | None = None,
    steering: str | None = None,
    steering_ratio: float | None = None,
    lane_check: bool = False,
    say: Callable[[str], None] = lambda message: None,
    trust_module: bool = False,
    log: WarningLog | None = None,
    loaded: SteeringModel | None = None,
) -> PreparedModel:
    """Load the model ``spec`` for ``recordings``' sample time (``loaded``: what
    :func:`load_model_spec` returned for the same arguments, not loaded again); with ``fit``
    fit it on the first ``fit_on`` recordings, each a run of its own (their ``steering`` signal: "measured"
    or "applied"; None: the model's). A generalized model (:class:`GeneralizedModel`, not a
    user subclass) fitted so is fitted as ``hasa-bench`` fits its built-in one: its fit
    estimates an ``equation_error_order``-lag autoregression of its equation error
    (docs/design.md §8.32; None: hasa-bench's order,
    :data:`~benchmarks.defaults.DEFAULT_EQUATION_ERROR_ORDER`, for the ``generalized``
    preset, and its own for a model file or class, whose structure a fit keeps), and it gets
    its speed-scaled equation error (``speed_scaled_error``; docs/design.md §8.34;
    :func:`benchmarks.speed_scaled.add_speed_scaled_error`: on held-out residuals when
    ``fit_on`` >= 2, else in-sample). The steering ratio is ``steering_ratio`` or the default
    of the spec (:func:`default_steering_ratio`: 15 for a paper preset as given, else 1). With
    ``lane_check`` the model must keep a lane when it steers itself
    (:func:`hasa_env.drivers.require_lane_keeping`: 4 cars, 30 s, the straight track).
    ``say`` hears what was fitted (the recordings, the equation error's autoregression and its
    order, the speed-scaled error's numbers and whether held out, or that none was found) and
    the ratio used. ``trust_module``: a model file of a type not registered yet imports the
    module its ``"class"`` names (:func:`hasa_env.steering.loading.load_model_file`).
    ``log``: the warnings shown by the fit
    are the recording's fitted on (step ``"model"``; e.g. an
    :class:`~hasa_env.steering.identifiability.IdentifiabilityWarning`), or no one
    recording's when fitted on several.

    Raises:
        ModelSetupError: the model does not load, has no parameters and ``fit`` is off,
            ``fit_on`` is not an integer from 1 to the number of recordings,
            ``equation_error_order`` is not None or an integer in [0,
            :data:`~hasa_env.steering.equation_error.MAX_EQUATION_ERROR_ORDER`], or
            ``steering_ratio`` is not a number in (0, :data:`MAX_STEERING_RATIO`].
        LaneKeepingError: ``lane_check`` and it drives off the road.
    """
    model = loaded
    if model is None:
        model = load_model_spec(
            spec,
            recordings,
            fit=fit,
            fit_on=fit_on,
            equation_error_order=equation_error_order,
            steering_ratio=steering_ratio,
            trust_module=trust_module,
        )
    if steering is not None:
        model.steering_signal = steering
    fitted_on: tuple[Path | None, ...] = ()
    found = None
    if fit:
        model, found = _fit(
            spec, model, recordings[:fit_on], speed_scaled_error, equation_error_order, say, log
        )
        fitted_on = tuple(rec.path for rec in recordings[:fit_on])
    ratio = default_steering_ratio(spec, fit) if steering_ratio is None else steering_ratio
    say(f"model {spec}: steering ratio {ratio:g} (model units per recorded road-wheel rad)")
    if lane_check:
        try:  # a model that cannot keep a lane would give the estimator wrong evidence
            require_lane_keeping(model, steering_ratio=ratio, what=f"model {spec!r}")
        except ValueError as exc:
            raise LaneKeepingError(str(exc)) from None
    return PreparedModel(spec, model, ratio, fitted_on, found)


def _is_int_in(value: object, low: int, high: int) -> bool:
    """Whether ``value`` is an integer (not a bool) in [``low``, ``high``]."""
    return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high


def _fit(
    spec: str,
    model: SteeringModel,
    recordings: Sequence[Any],
    speed_scaled_error: bool,
    equation_error_order: int | None,
    say: Callable[[str], None],
    log: WarningLog | None,
) -> tuple[SteeringModel, dict[str, Any] | None]:
    """``model`` fitted on ``recordings`` (each a run of its own; on their road when they
    share one, else each run's from its metadata) as :func:`prepare_model` says, and what
    fitting its speed-scaled equation error found (None: not fitted)."""
    model, order_how = _with_equation_error_order(spec, model, equation_error_order)
    if order_how is None and equation_error_order is not None:
        say(f"model {spec}: --equation-error-order not applied (it sets a generalized model's: "
            "the preset's or a GeneralizedModel file's); this model keeps its own")  # fmt: skip
    runs = [rec.data for rec in recordings]
    road = _shared_road(recordings)
    where = recordings[0].path if len(recordings) == 1 else None
    names = ", ".join(str(rec.path) for rec in recordings)
    with _about(log, where, "model"):
        try:
            fitted = model.fit(runs[0] if len(runs) == 1 else runs, road)
        except ValueError as exc:  # e.g. a preset whose coefficients belong to another Ts
            raise ModelSetupError(f"cannot fit {spec} on {names}: {exc}") from None
        each = "" if len(runs) == 1 else f" ({len(runs)} recordings, each a run of its own)"
        say(f"model {spec}: fitted on {names}{each}")
        if order_how is not None:
            say(f"model {spec}: {describe_equation_error(fitted)} ({order_how})")
        if not fits_speed_scaled_error(model) or fitted.arx() is None:
            return fitted, None  # the built-in generalized model's error only, as hasa-bench
        if not speed_scaled_error:
            say(f"model {spec}: speed-scaled equation error not fitted (--no-speed-scaled-error)")
            return fitted, None
        found: dict[str, Any] = {}
        add_speed_scaled_error(model, fitted, runs, 0.0, found, road=road)
    say(f"model {spec}: {describe_speed_scaled(found)}")
    return fitted, found


def _with_equation_error_order(
    spec: str, model: SteeringModel, order: int | None
) -> tuple[SteeringModel, str | None]:
    """``model`` to fit with ``order`` lags of its equation error's autoregression, as
    :func:`prepare_model` says (None: hasa-bench's for the ``generalized`` preset, its own
    for another), and how the order was chosen, for the log; a model other than a
    :class:`GeneralizedModel` as it is, and None."""
    if type(model) is not GeneralizedModel:
        return model, None
    if order is None and model_spec_kind(spec) != "preset":
        return model, "the model's own order; --equation-error-order sets another"
    how = f"--equation-error-order {order}"
    if order is None:
        order = DEFAULT_EQUATION_ERROR_ORDER
        how = f"--equation-error-order {order}: hasa-bench's default"
    structure = model.structure() | {"equation_error_order": order}  # as hasa-bench builds it
    return GeneralizedModel(**structure, **model.common_kwargs()), how


def _shared_road(recordings: Sequence[Any]) -> Road | None:
    """The road of ``recordings`` when they were all made on the same track and lane width
    (what a fit's features read of it), else None (each run's from its metadata)."""
    roads = {(rec.config["track"], rec.config["road"]["lane_width"]) for rec in recordings}
    return recordings[0].road if len(roads) == 1 else None


@dataclass(frozen=True)
class RecordingOutcome:
    """What a step produced for one recording (by its index), or why it failed."""

    index: int
    path: Path | None
    value: Any = None
    error: str | None = None


def score_recordings(
    prepared: PreparedModel, recordings: Sequence[Any], log: WarningLog | None = None
) -> list[RecordingOutcome]:
    """Per recording the model's one-step-ahead scores of :data:`SCORE_KEYS` (steering in
    model units: the recorded steering times the ratio): outcomes whose ``value`` is the
    scores' dict, or whose ``error`` says why it cannot be scored (e.g. a recording sampled
    at another rate than the model's coefficients belong to). ``log``: the warnings shown
    are each the recording's (step ``"model"``)."""
    out = []
    for i, rec in enumerate(recordings):
        try:
            with _about(log, rec.path, "model"):
                frame = in_model_units(rec.data, prepared.steering_ratio)
                scores = score(prepared.model, frame, rec.road)
        except ValueError as exc:
            out.append(RecordingOutcome(i, rec.path, error=str(exc)))
            continue
        out.append(RecordingOutcome(i, rec.path, value={k: v for k, v in scores.items()
                                                        if k in SCORE_KEYS}))  # fmt: skip
    return out


def estimate_recordings(
    prepared: PreparedModel, recordings: Sequence[Any], log: WarningLog | None = None
) -> list[RecordingOutcome]:
    """The Gaussian-mixture EKF with the model over each recording: outcomes whose ``value``
    is an :class:`~estimators.offline.EstimatorRun`, or whose ``error`` says why it could not
    run (e.g. a recording sampled at another rate than the model). ``log``: the warnings
    shown (the trust rule's included) are each the recording's (step ``"estimator"``)."""
    out = []
    for i, rec in enumerate(recordings):
        try:
            with _about(log, rec.path, "estimator"):
                run: EstimatorRun = estimate_recording(rec, prepared.model, prepared.steering_ratio)
        except ValueError as exc:
            out.append(RecordingOutcome(i, rec.path, error=str(exc)))
            continue
        out.append(RecordingOutcome(i, rec.path, value=run))
    return out


@dataclass(frozen=True)
class TrustLines:
    """Where the estimator trusted a model's steering on the recordings it ran on, in the
    lines ``hasa-replay`` prints (:func:`describe_trust`).

    Attributes:
        model: the reasons that the filters of all those recordings share, in one line
            (None: no filter to describe);
        recordings: by recording index, the reasons of that recording's filter that
            ``model`` does not hold, in one line (absent: none). A declared equation-error
            autoregression's line (taken or ignored, by that recording's data) is always
            here, never in ``model``.
    """

    model: str | None
    recordings: dict[int, str]


def describe_trust(prepared: PreparedModel, outcomes: Sequence[RecordingOutcome]) -> TrustLines:
    """The trust lines of the filters :func:`estimate_recordings` ran (``outcomes``; each
    run keeps its filter, :attr:`~estimators.offline.EstimatorRun.trust`, so none is made
    again). When none ran (every recording failed), ``model`` is the line of
    :meth:`PreparedModel.trust` without its equation-error line, or None when the trust rule
    refuses the model (each recording's error already says why)."""
    filters = {
        o.index: o.value.trust
        for o in outcomes
        if o.error is None and getattr(o.value, "trust", None) is not None
    }
    trusts = list(filters.values())
    if not trusts:
        try:
            trusts = [prepared.trust()]
        except ValueError:  # e.g. a non-stationary autoregression, named per recording
            return TrustLines(None, {})
    first, *rest = trusts
    shared = [
        r
        for r in first.reasons
        if r != first.equation_error_reason and all(r in t.reasons for t in rest)
    ]
    lines, limited = {}, False
    for index, trust in filters.items():
        extra = [r for r in trust.reasons if r not in shared]
        if extra:
            lines[index] = "; ".join(extra)
        limited |= trust.arx is None or any(r != trust.equation_error_reason for r in extra)
    if shared:
        model = "; ".join(shared)
    else:  # nothing shared: everywhere, unless some recording's filter has a limit
        model = "as each recording's line says" if limited else STEERING_EVERYWHERE
    return TrustLines(model, lines)


def render_recordings(
    recordings: Sequence[Any],
    frames: Path | None,
    video: Path | None,
    weights: dict[int, Any],
    log: WarningLog | None = None,
    **options: Any,
) -> list[RecordingOutcome]:
    """PNG frames into ``frames`` and/or a video ``video`` of every recording (several
    recordings: a subfolder per recording, ``<video stem>_<recording stem>`` videos), the
    estimator's ``weights`` (by recording index) in the HUD. ``options``: those of
    :func:`hasa_env.render.frames.write_frames` (``every``, ``view``, ``size``,
    ``show_points``). Outcomes: ``value`` (frames written, folder) or the write error.
    ``log``: the warnings shown are each the recording's (step ``"frames"``)."""
    out = []
    several = len(recordings) > 1
    for i, rec in enumerate(recordings):
        stem = Path(rec.path).stem
        frames_dir = None if frames is None else (frames / stem if several else frames)
        target = video
        if target is not None and several:
            target = target.with_name(f"{target.stem}_{stem}{target.suffix}")
        try:
            with _about(log, rec.path, "frames"):
                written = write_frames(
                    rec, frames_dir, weights=weights.get(i), video=target, **options
                )
        except OSError as exc:  # a read-only or full output folder
            out.append(RecordingOutcome(i, rec.path, error=str(exc)))
            continue
        out.append(RecordingOutcome(i, rec.path, value=(written, frames_dir)))
    return out

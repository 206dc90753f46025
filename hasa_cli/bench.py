"""The ``hasa-bench`` command: the paper's benchmark, scoring your model, performance.

Usage::

    hasa-bench paper [options]                       # the paper's protocol, built-in models
    hasa-bench score my_pkg.my_module:MyModel [...]  # the same, ranking your model(s)
    hasa-bench score path/to/model.json             # a saved model, with its own parameters
    hasa-bench paper --recordings STUDY_DIR          # a study's recordings (session files)
    hasa-bench perf [--quick] [--json FILE]          # the performance benchmarks

``paper`` and ``score`` print the tables and write into ``--out``
(default ``hasa-bench-results``): ``results.json``, CSV tables,
``report.md``, ``report.html`` (self-contained) and PNG figures (docs/results.md). A folder that holds a previous result is only
replaced with ``--overwrite`` (the new result is written beside it first and
swapped in when complete). Exit status (:mod:`hasa_cli`): 0 success; 1
partial: a user model failed, or recordings were skipped or runs left out
as degenerate (each named on stderr and in results.json; every other result
is written); 2 invalid arguments or data, a user model that does not
import, an output folder that exists (nothing run, nothing written); 3 the
environment: the Dask scheduler cannot be reached or is lost, Dask's package is not
installed (the ``dask`` extra), or the results cannot be written. What loading repaired in a recording of
``--recordings`` (a crashed recording's partly written last line, dropped) is a
``hasa-bench: warning:`` line naming it, with ``--quiet`` too, and a note in
results.json; it does not change the exit status.

Why this module is long: it is the argument parser and the output of three
subcommands (paper, score, perf) with their options, each documented at
the option, plus the mapping of every failure onto one exit status; the
work itself is in :mod:`benchmarks`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from benchmarks.defaults import (
    DEFAULT_EQUATION_ERROR_ORDER,
    DEFAULT_MODEL_TIME_LIMIT,
    DEFAULT_SEEDS,
    DEFAULT_TRAINING_DRIVERS,
    GENERALIZED_ORDERS,
    NO_WORKER_TIMEOUT,
)
from hasa_cli import (
    EXIT_ENVIRONMENT,
    EXIT_OK,
    EXIT_PARTIAL,
    EXIT_USAGE,
    ArgumentParser,
    add_equation_error_order_option,
    add_speed_scaled_error_option,
    add_trust_model_option,
    add_version,
    console_script,
    error,
    output_file_problem,
    printable,
    report_write_failure,
    seed_list,
    speed_list,
    stop_on_signals,
    warn,
)
from hasa_env.atomic import write_atomic
from hasa_env.scenarios import SCENARIOS
from hasa_env.sim.config import ConfigError, make_config

# The protocol, its report and the performance benchmarks are imported where a command
# runs: ``hasa-bench --help`` and a usage error stay fast (statsmodels and matplotlib alone
# take seconds to import).

__all__ = ["main", "build_parser"]

PROG = "hasa-bench"


def _add_protocol_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``paper`` and ``score``: runs, sensor noise, models, recordings,
    execution and output."""
    _add_run_options(parser)
    add_trust_model_option(parser, "a --model file")
    _add_recording_options(parser)
    _add_execution_options(parser)


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """The synthetic runs, the sensor noise and ``--model``."""
    data = parser.add_argument_group("runs (synthetic population)")
    data.add_argument("--population", default="paper", help="population name (default: paper)")
    seeds = data.add_mutually_exclusive_group()
    seeds.add_argument(
        "--seeds",
        type=seed_list,
        default=None,
        metavar="S,S,...",
        help="population seeds: the protocol runs once per seed (drivers and runs drawn from "
        "it), the verdict comes with 95 %% intervals over them (default: 0,1,2,3,4)",
    )
    seeds.add_argument(
        "--seed", type=int, default=None, metavar="S", help="one seed only (--seeds S)"
    )
    data.add_argument("--drivers", type=int, default=9, metavar="N", help="drivers: Ill, 1.. (9)")
    data.add_argument("--runs", type=int, default=10, metavar="N", help="runs per driver (10)")
    data.add_argument(
        "--ill-runs",
        type=int,
        default=None,
        metavar="N",
        help="runs of the illustrative driver 'Ill', incl. the training run (default: runs + 4)",
    )
    data.add_argument(
        "--duration",
        type=_config_value("time_limit"),
        default=30.0,
        metavar="S",
        help="run length in s (30)",
    )
    tracks = ("straight", "curved")
    data.add_argument("--track", choices=tracks, default="straight", help="main track (straight)")
    data.add_argument(
        "--scenario",
        choices=(*SCENARIOS, "all"),
        default="paper",
        metavar="NAME",
        help=f"scenario of the synthetic runs: {', '.join(SCENARIOS)}, or all (each into "
        "its own folder of --out, and a table of every scenario); default paper",
    )
    data.add_argument(
        "--curved-runs",
        type=int,
        default=4,
        metavar="N",
        help="extra curved-track runs of 'Ill' (steering scores and estimation; 0: none; "
        "default 4)",
    )
    data.add_argument(
        "--stress",
        action="store_true",
        help="also score the stress set of bad advisors (benchmarks.stress): no lane "
        "information, sign-flipped, random stable ARX, unregularized constant-speed fit",
    )
    data.add_argument(
        "--filter",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="a FilterSettings field for every estimator, e.g. forgetting_time=10 "
        "(repeatable; JSON values: numbers, true/false)",
    )
    data.add_argument(
        "--compare-checks",
        action="store_true",
        help="also run every model's estimator without the evidence checks and the lane-keeping "
        "check ('<model> (no checks)')",
    )
    _add_noise_options(parser)
    parser.add_argument(
        "--model",
        action="append",
        default=[],
        metavar="MODEL",
        help="also score this steering model: 'package.module:ClassName' (a SteeringModel "
        "subclass, fitted on the training run like the built-ins) or a saved model file "
        "(scored with its own parameters); repeatable",
    )


def _add_noise_options(parser: argparse.ArgumentParser) -> None:
    """The sensor-noise options, each range-checked by the env config's validator."""
    noise = parser.add_argument_group("sensor noise (std; default: the env's)")
    for name, metavar, default in (
        ("speed", "M/S", "speedometer (0.05)"),
        ("camera", "M", "camera offset (0.05)"),
        ("imu", "M/S2", "IMU (0.05)"),
        ("steering", "RAD", "steering (1e-4)"),
    ):
        noise.add_argument(
            f"--{name}-noise", type=_config_value(f"noise.{name}"), metavar=metavar, help=default
        )


def _add_recording_options(parser: argparse.ArgumentParser) -> None:
    """Recorded drives instead of the synthetic population."""
    rec = parser.add_argument_group("recorded drives instead")
    rec.add_argument(
        "--recordings",
        metavar="DIR",
        help="directory of recordings (hasa_env format); drivers from metadata.driver or "
        "metadata.participant, else the sub-directory. A study's directory (session.json "
        "files of 'hasa-drive study'): its participants' measured runs, practice runs "
        "excluded, aborted runs reported",
    )
    rec.add_argument(
        "--illustrative",
        metavar="NAME",
        help="driver whose run trains the models (default 'Ill', or the first driver)",
    )
    rec.add_argument(
        "--training-run",
        type=int,
        default=0,
        metavar="N",
        help="which of its main-track runs trains the models (0)",
    )
    rec.add_argument(
        "--training-runs",
        type=int,
        default=1,
        metavar="N",
        help="how many of its main-track runs, from --training-run on, train the models (1: the "
        "paper's one-run protocol; more: several runs and the speeds they reach)",
    )
    rec.add_argument(
        "--training-drivers",
        type=int,
        default=None,
        metavar="N",
        help="also train the models on one run each of N more drivers drawn from the same "
        f"population, scored nowhere (synthetic runs; default {DEFAULT_TRAINING_DRIVERS}, with "
        "--recordings 0; 0: the paper's protocol, the illustrative driver only)",
    )
    rec.add_argument(
        "--training-speeds",
        type=speed_list,
        default=(),
        metavar="V,V,...",
        help="also train the models on one extra run of the illustrative driver per start "
        "speed (m/s), scored nowhere (synthetic runs; the models are then trusted over those "
        "speeds too; default: none, the paper's protocol)",
    )
    _add_generalized_options(rec)
    rec.add_argument(
        "--training-file",
        metavar="FILE",
        help="the recording that trains the models (instead of --illustrative/--training-run)",
    )
    rec.add_argument(
        "--min-duration",
        type=_seconds,
        default=5.0,
        metavar="S",
        help="skip recordings shorter than this, each named (default 5 s)",
    )
    rec.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="also score recordings whose writer stopped early (crash, failed write)",
    )


def _add_generalized_options(group: argparse._ArgumentGroup) -> None:
    """How the built-in generalized model is fitted: its equation error and its orders."""
    add_equation_error_order_option(
        group,
        "the built-in generalized model's fit",
        DEFAULT_EQUATION_ERROR_ORDER,
        str(DEFAULT_EQUATION_ERROR_ORDER),
    )
    add_speed_scaled_error_option(
        group, "fit the built-in generalized model's", "the whitening above", "the whitening"
    )
    group.add_argument(
        "--generalized-orders",
        choices=GENERALIZED_ORDERS,
        default=GENERALIZED_ORDERS[0],
        help="the built-in generalized model's orders: 'paper' keeps the paper's (na=2, nb=4, "
        "nc=1, nd=2; default); 'bic' selects them by BIC on the training runs (docs/design.md "
        "§8.26)",
    )


def _add_execution_options(parser: argparse.ArgumentParser) -> None:
    """Workers, the Dask scheduler, batches, the time limit of user models, the output."""
    run = parser.add_argument_group("execution and output")
    run.add_argument(
        "--workers", type=int, default=None, metavar="N", help="local processes (default: CPUs)"
    )
    run.add_argument(
        "--scheduler",
        metavar="ADDR",
        help="Dask scheduler address (tcp://host:8786): run the tasks on that cluster (its "
        "workers need hasa-env and the modules of your models)",
    )
    run.add_argument(
        "--worker-timeout",
        type=_positive_seconds,
        default=NO_WORKER_TIMEOUT,
        metavar="S",
        help="with --scheduler: give up (exit 3) when the cluster has had no worker for this "
        f"long (default {NO_WORKER_TIMEOUT:g} s); what finished is reported",
    )
    run.add_argument(
        "--batch-size",
        type=int,
        default=100,
        metavar="N",
        help="most runs per task, vectorized together (100: one task per seed; a seed's "
        "runs are cut into the fewest near-equal tasks); results are the same on any executor "
        "and worker count, another batch size can change them in the last digits",
    )
    run.add_argument(
        "--model-time-limit",
        type=_time_limit,
        default=DEFAULT_MODEL_TIME_LIMIT,
        metavar="S",
        help="time limit of one call into a user model (import, a fit, a batch of runs), each "
        "run in its own process so a model that hangs, exits or crashes fails alone "
        f"(default {DEFAULT_MODEL_TIME_LIMIT:g} s; 0: no limit, user code runs in-process)",
    )
    run.add_argument(
        "--out",
        default="hasa-bench-results",
        metavar="DIR",
        help="output directory (default hasa-bench-results)",
    )
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output directory if it holds a previous result",
    )
    run.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    run.add_argument(
        "--quiet", action="store_true", help="no progress bars or tables (errors only)"
    )


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a duration in s >= 0, got {text!r}")
    return value


def _config_value(key: str) -> Callable[[str], float]:
    """An argparse type: a number the env config accepts at the dotted ``key`` (e.g.
    ``noise.camera``), its range checked by the config's own validator
    (:func:`hasa_env.make_config`), so a bad value is a usage error naming the option and the
    allowed range before anything runs."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        update: Any = value
        for part in reversed(key.split(".")):
            update = {part: update}
        try:
            make_config(update)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return value

    return parse


def _positive_seconds(text: str) -> float:
    value = _seconds(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a duration in s > 0, got {text!r}")
    return value


def _time_limit(text: str) -> float | None:
    value = _seconds(text)
    return None if value == 0 else value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-bench``."""
    parser = ArgumentParser(
        prog=PROG,
        description="The human-as-advisor benchmark (Mai et al.): steering-model prediction "
        "and lane estimation on a synthetic population or recorded drives.",
        epilog="Exit status: 0 ok, 1 partial (a user model failed, recordings skipped, runs "
        "left out; each named), 2 usage or input error (nothing written), 3 environment: the "
        "Dask scheduler cannot be reached or is lost, its package is not installed (the dask "
        "extra), or the results cannot be written.",
    )
    add_version(parser)
    sub = parser.add_subparsers(dest="command", required=True, metavar="{paper,score,perf}")
    paper = sub.add_parser(
        "paper",
        help="the paper's protocol with the two built-in models",
        description="Fit the two-point and generalized models on one run of 'Ill' and one "
        "run each of --training-drivers more drivers (default 8; 0: the paper's one-run "
        "protocol), score steering prediction (paper table 1) and lateral estimation (table 2) "
        "on every other run; the paper's values are printed beside ours.",
    )
    _add_protocol_options(paper)
    score = sub.add_parser(
        "score",
        help="score your steering model(s) with the same protocol",
        description="Import each MODEL ('package.module:ClassName', a SteeringModel subclass, "
        "from the working directory or the installed packages), fit it on the training runs "
        "like the built-ins and rank it against them; a saved model file (model.save(...), "
        "any registered type) is scored with its own parameters.",
    )
    score.add_argument(
        "models",
        nargs="+",
        metavar="MODEL",
        help="package.module:ClassName or path/to/model.json",
    )
    _add_protocol_options(score)
    perf = sub.add_parser(
        "perf",
        help="the performance benchmarks, one table of ratios",
        description="Run the performance benchmarks of benchmarks.perf (env, estimators, "
        "render, advisor; those present) and print their measured ratios against the targets.",
    )
    perf.add_argument("--quick", action="store_true", help="seconds-long runs, rough numbers")
    perf.add_argument("--json", metavar="FILE", help="also write every number as JSON")
    from benchmarks.perf import BENCHMARKS  # start-up: only where needed

    perf.add_argument(
        "--only",
        metavar="NAMES",
        help=f"comma-separated subset of {', '.join(m.removeprefix('perf_') for m in BENCHMARKS)}",
    )
    perf.add_argument("--strict", action="store_true", help="exit 1 if a target fails")
    return parser


# -------------------------------------------------------------------- paper/score
def _config(args: argparse.Namespace, scenario: str = "paper") -> Any:
    from benchmarks.protocol import ProtocolConfig  # start-up: only where needed

    noise = {
        key: value
        for key, value in (
            ("speed", args.speed_noise),
            ("camera", args.camera_noise),
            ("imu", args.imu_noise),
            ("steering", args.steering_noise),
        )
        if value is not None
    }
    return ProtocolConfig(
        population=args.population,
        seeds=(
            (args.seed,) if args.seed is not None else args.seeds if args.seeds else DEFAULT_SEEDS
        ),
        drivers=args.drivers,
        runs=args.runs,
        ill_runs=args.ill_runs,
        duration=args.duration,
        scenario=scenario,
        track=args.track,
        curved_runs=args.curved_runs,
        noise=noise,
        recordings=args.recordings,
        illustrative=args.illustrative,
        training_run=args.training_run,
        training_runs=args.training_runs,
        training_drivers=args.training_drivers,
        training_speeds=args.training_speeds,
        generalized_orders=args.generalized_orders,
        equation_error_order=args.equation_error_order,
        speed_scaled_error=args.speed_scaled_error,
        training_file=args.training_file,
        min_duration=args.min_duration,
        allow_incomplete=args.allow_incomplete,
        model_time_limit=args.model_time_limit,
        batch_size=args.batch_size,
        stress=bool(getattr(args, "stress", False)),
        filter_settings=_filter_settings(getattr(args, "filter", [])),
        compare_checks=bool(getattr(args, "compare_checks", False)),
    )


def _filter_settings(items: list[str]) -> dict[str, Any]:
    """``["field=value", ...]`` as a dict (values parsed as JSON, else kept as text)."""
    from benchmarks.protocol import BenchmarkError  # start-up: only where needed

    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise BenchmarkError(f"--filter expects FIELD=VALUE, got {item!r}")
        try:
            out[name.strip()] = json.loads(text)
        except json.JSONDecodeError:
            out[name.strip()] = text
    return out


class _Progress:
    """Progress on stderr (nothing when quiet): a bar with an estimate of the time left for
    each long stage (the fits, seed by seed; the runs), a line with the elapsed time for the
    others and for the messages within a stage."""

    BARS = {"fits": ("fitting the models", "seed"), "runs": ("scoring runs", "run")}

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bar: Any = None
        self.phase = ""
        self.start = time.perf_counter()

    def __call__(self, phase: str, done: int, total: int) -> None:
        if self.quiet:
            return
        if phase in self.BARS:
            if self.bar is None or self.phase != phase:
                from tqdm import tqdm  # start-up: only where needed

                self.close()
                desc, unit = self.BARS[phase]
                self.bar = tqdm(total=total, unit=unit, desc=desc, file=sys.stderr)
                self.phase = phase
            self.bar.update(done - self.bar.n)
            if phase == "fits" and done == total:
                self.close()
            return
        line = f"[{time.perf_counter() - self.start:5.1f} s] {printable(phase)}"
        if self.bar is not None and self.phase == "fits":
            self.bar.write(line, file=sys.stderr)  # a message within the stage, above its bar
            return
        self.close()
        print(line, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _run_protocol(args: argparse.Namespace, user_models: Sequence[str]) -> int:
    from benchmarks.executor import SchedulerError, check_scheduler  # start-up: only where needed
    from benchmarks.output import output_problem  # start-up: only where needed
    from benchmarks.scenario_suite import (  # start-up: only where needed
        format_suite,
        suite_rows,
        write_suite,
    )
    from benchmarks.schema import ResultsSchemaError  # start-up: only where needed

    if args.workers is not None and args.workers < 1:
        error(PROG, f"--workers must be >= 1, got {args.workers}")
        return EXIT_USAGE
    if args.recordings is not None and args.scenario != "paper":
        error(
            PROG,
            "--scenario applies to synthetic runs; recordings carry their own scenario "
            "(their env config's 'scenario'): the training run's is scored, the others are "
            "listed as skipped (--training-file chooses)",
        )
        return EXIT_USAGE
    out = Path(args.out)
    problem = output_problem(out, args.overwrite)
    if problem is not None:
        error(PROG, problem)
        return EXIT_USAGE
    scheduler = args.scheduler
    if scheduler is not None:
        try:
            scheduler = check_scheduler(scheduler)
        except SchedulerError as exc:
            error(PROG, str(exc))
            return EXIT_USAGE if exc.kind == "address" else EXIT_ENVIRONMENT
    started = time.perf_counter()
    progress = _Progress(args.quiet)  # its times count from here
    if args.scenario != "all":
        code, results = _run_scenarios(args, user_models, [args.scenario], scheduler, progress)
        if results is None:
            return code
        return _write_scenario(args, results[args.scenario], out, started, progress)
    code, results = _run_scenarios(args, user_models, list(SCENARIOS), scheduler, progress)
    if results is None:
        return code
    out.mkdir(parents=True, exist_ok=True)
    status = EXIT_OK
    for name, result in results.items():
        if not args.quiet:
            print(f"== scenario {name}")
        status = max(status, _write_scenario(args, result, out / name, started, progress))
    rows = suite_rows(results)
    try:
        write_suite(rows, out)
    except OSError as exc:
        error(PROG, f"cannot write the scenario table to {out}: {exc}")
        return EXIT_ENVIRONMENT
    except ResultsSchemaError as exc:
        error(PROG, f"{out / 'scenarios.csv'} {exc} (every file is written; please report this)")
        status = max(status, EXIT_PARTIAL)
    if not args.quiet:
        print(printable(format_suite(rows), newlines=True))
        print(
            f"wrote {len(results)} scenario folders and scenarios.md, scenarios.html, "
            f"scenarios.csv to {out}/; "
            f"{time.perf_counter() - started:.1f} s in all"
        )
    return status


def _run_scenarios(
    args: argparse.Namespace,
    user_models: Sequence[str],
    scenarios: Sequence[str],
    scheduler: Any,
    progress: _Progress,
) -> tuple[int, dict[str, Any] | None]:
    """Run the protocol in each scenario (several: one suite, :func:`benchmarks.protocol.
    suite.run_suite`): (exit status, the results by scenario, or None when nothing ran)."""
    from benchmarks.executor import ClusterLost  # start-up: only where needed
    from benchmarks.protocol import BenchmarkError, run_protocol  # start-up: only where needed
    from benchmarks.protocol.suite import run_suite  # start-up: only where needed

    options = {
        "workers": args.workers,
        "scheduler": scheduler,
        "progress": progress,
        "no_worker_timeout": args.worker_timeout,
        "trust_model_modules": args.trust_model_module,
    }
    try:
        if len(scenarios) == 1:
            name = scenarios[0]
            results = {name: run_protocol(_config(args, name), user_models, **options)}
        else:
            configs = {name: _config(args, name) for name in scenarios}
            results = run_suite(configs, user_models, **options)
    except BenchmarkError as exc:
        progress.close()
        error(PROG, str(exc))
        return EXIT_USAGE, None
    except ClusterLost as exc:  # the scheduler or every worker went away mid-run
        progress.close()
        error(PROG, f"{exc}; nothing was written")
        return EXIT_ENVIRONMENT, None
    except BaseException:  # Ctrl-C, SIGTERM: end the progress bar's line before the message
        progress.close()
        raise
    progress.close()
    return EXIT_OK, results


def _write_scenario(
    args: argparse.Namespace, result: Any, out: Path, started: float, progress: _Progress
) -> int:
    """Write one scenario's folder, print its tables and its problems: the exit status."""
    from benchmarks.output import write_result_folder  # start-up: only where needed
    from benchmarks.report import format_tables  # start-up: only where needed
    from benchmarks.schema import ResultsSchemaError  # start-up: only where needed

    progress("writing results, tables and figures", 0, 0)
    try:
        written = write_result_folder(result, out, figures=not args.no_plots)
    except OSError as exc:
        progress.close()
        error(PROG, f"cannot write the results to {out}: {exc}")
        return EXIT_ENVIRONMENT
    except ResultsSchemaError as exc:  # a bug of ours: the files are written all the same
        progress.close()
        error(PROG, f"{out / 'results.json'} {exc} (every file is written; please report this)")
        return EXIT_PARTIAL
    progress.close()
    if not args.quiet:
        print(printable(format_tables(result), newlines=True))
        print()
        print(
            f"wrote {len(written)} files to {out}/ (results.json, report.md, report.html, "
            f"CSV tables{', figures' if not args.no_plots else ''}); "
            f"{time.perf_counter() - started:.1f} s in all"
        )
    for skip in result.skipped:
        error(PROG, f"skipped {skip['file']}: {skip['reason']}")
    for run in result.degenerate:
        where = run["file"] or f"driver {run['driver']!r} run {run['run']} ({run['track']})"
        warn(PROG, f"left out of the means: {where}: {run['reason']}")
    for failure in result.errors:
        error(PROG, failure["message"])
    partial = result.errors or result.skipped or result.degenerate
    return EXIT_PARTIAL if partial else EXIT_OK


# -------------------------------------------------------------------------- perf
def _perf(args: argparse.Namespace) -> int:
    from benchmarks.perf import (  # start-up: only where needed
        benchmark_names,
        format_perf_table,
        run_benchmarks,
    )

    try:
        names = benchmark_names(args.only)
    except ValueError as exc:
        error(f"{PROG} perf", str(exc))
        return EXIT_USAGE
    unwritable = None if args.json is None else output_file_problem("--json", args.json)
    if unwritable is not None:  # before minutes of measuring
        error(f"{PROG} perf", unwritable)
        return EXIT_USAGE
    measured = run_benchmarks(names, args.quick, lambda message: print(message, file=sys.stderr))
    print(format_perf_table(measured.rows))
    if args.quick:
        print("(quick mode: few steps, rough numbers)")
    if args.json:
        doc = {"rows": measured.rows, "benchmarks": measured.benchmarks}
        try:  # atomically: an interrupted write leaves no half file
            write_atomic(args.json, json.dumps(doc, indent=2, default=str) + "\n")
        except OSError as exc:
            failed = report_write_failure(
                f"{PROG} perf", exc, args.json, "the table is printed above"
            )
            return EXIT_PARTIAL if failed is None else failed
    if measured.failed or (args.strict and measured.any_target_failed()):
        return EXIT_PARTIAL
    return EXIT_OK


# -------------------------------------------------------------------------- main
@console_script(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-bench`` (returns the exit status)."""
    args = build_parser().parse_args(argv)
    if args.command == "perf":
        return _perf(args)
    user_models = (args.models if args.command == "score" else []) + list(args.model)
    if user_models:  # like other tools that import user code by path: the working directory
        from hasa_env.steering.loading import add_module_folders  # start-up: only where needed

        add_module_folders(os.getcwd())
    with stop_on_signals():  # SIGTERM / SIGHUP: the worker pool is terminated, exit 143 / 129
        return _run_protocol(args, user_models)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

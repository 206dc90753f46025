"""Performance benchmarks: how fast the env, the estimators, the views and the advisor task run.

- :mod:`benchmarks.perf.env`: env steps per second (single, vector, action repeat);
- :mod:`benchmarks.perf.estimators`: the Gaussian-mixture EKF against filterpy;
- :mod:`benchmarks.perf.render`: frames per second of the views;
- :mod:`benchmarks.perf.advisor`: the advisor task against the plain env.

Each module has ``run(quick=...)`` (a JSON-able dict of measurements and, per
target, ``value``/``minimum``/``passed`` or a ``ratios_to_target`` map) and a
``main`` (``python -m benchmarks.perf.env``). :func:`run_benchmarks` runs a
subset and :func:`perf_rows` turns each result into rows of one table
(``hasa-bench perf``): per measure, ratio = measured / target.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from benchmarks.tables import Column, render_text

__all__ = [
    "BENCHMARKS",
    "PerfRun",
    "benchmark_names",
    "format_perf_table",
    "module_name",
    "perf_rows",
    "run_benchmarks",
]

BENCHMARKS = ("perf_env", "perf_estimators", "perf_render", "perf_advisor")
"""Names of the performance benchmarks (``perf_<module>``: module ``benchmarks.perf.<module>``)."""


def module_name(benchmark: str) -> str:
    """The module of a benchmark name: ``"perf_env"`` -> ``"benchmarks.perf.env"``."""
    return f"benchmarks.perf.{benchmark.removeprefix('perf_')}"


def benchmark_names(only: str | None) -> list[str]:
    """The benchmarks of ``only`` (comma-separated, with or without ``perf_``; None: all).

    Raises:
        ValueError: a name that is not one of :data:`BENCHMARKS` (the message lists them).
    """
    if not only:
        return list(BENCHMARKS)
    wanted = [f"perf_{n.strip().removeprefix('perf_')}" for n in only.split(",") if n]
    unknown = [w for w in wanted if w not in BENCHMARKS]
    if unknown:
        raise ValueError(
            f"unknown benchmark(s) {unknown}; "
            f"allowed: {', '.join(m.removeprefix('perf_') for m in BENCHMARKS)}"
        )
    return wanted


def _row(
    name: str, measure: str, value: Any, target: Any, ratio: Any, passed: Any
) -> dict[str, Any]:
    return {
        "benchmark": name,
        "measure": measure,
        "value": value,
        "target": target,
        "ratio_to_target": ratio,
        "passed": passed,
    }


def perf_rows(name: str, results: dict[str, Any], module: Any = None) -> list[dict[str, Any]]:
    """One row per measured ratio of a performance benchmark's ``run()`` result.

    Rows: ``benchmark``, ``measure``, ``value``, ``target`` (minimum, or None),
    ``ratio_to_target`` (value / target) and ``passed`` (None without target).
    """
    rows: list[dict[str, Any]] = []
    if "targets" in results:
        for key, t in results["targets"].items():
            value, minimum = t.get("value"), t.get("minimum")
            ratio = value / minimum if value is not None and minimum else None
            measure = t.get("description", key)
            rows.append(_row(name, measure, value, minimum, ratio, t.get("passed")))
        for key, value in (results.get("ratios") or {}).items():
            if key not in results["targets"]:
                rows.append(_row(name, key.replace("_", " "), value, None, None, None))
    elif "ratios_to_target" in results:
        targets = getattr(module, "TARGETS", {}) if module is not None else {}
        for key, ratio in results["ratios_to_target"].items():
            text, minimum = targets.get(key, (key, None))
            measured = (results.get("results") or {}).get(key, {}).get("frames_per_second")
            passed = None if ratio is None else bool(ratio >= 1.0)
            rows.append(_row(name, f"{key} ({text})", measured, minimum, ratio, passed))
        for key, value in (results.get("ratios") or {}).items():
            measure = f"{key.replace('_', ' ')} (ratio, same run)"
            rows.append(_row(name, measure, value, None, None, None))
    return rows


def _number(x: Any) -> str:
    if x is None:
        return "-"
    return f"{x:,.0f}" if abs(x) >= 1000 else f"{x:.2f}"


_PERF_COLUMNS = [
    Column("benchmark", "benchmark", left=True),
    Column("measure", "measure", left=True),
    Column("value", "measured", _number),
    Column(lambda r: ">= " + _number(r["target"]) if r["target"] is not None else "-", "target"),
    Column(
        lambda r: "-" if r["ratio_to_target"] is None else f"{r['ratio_to_target']:.2f}x",
        "measured/target",
    ),
    Column(
        lambda r: (
            "ERROR"
            if r.get("error")
            else {True: "PASS", False: "FAIL", None: ""}.get(r["passed"], str(r["passed"]))
        ),
        "result",
    ),
]


def format_perf_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows of :func:`perf_rows` as one plain-text table."""
    return render_text(rows, _PERF_COLUMNS)


@dataclass
class PerfRun:
    """What :func:`run_benchmarks` measured.

    Attributes:
        rows: the table's rows (:func:`perf_rows`; a benchmark that raised gets one
            row with ``error`` True and the message as its measure).
        benchmarks: per benchmark ``{"seconds", "results"}``, ``{"status": "error",
            "error"}`` or ``{"status": "not present"}`` (its module is not installed).
        failed: a benchmark raised.
    """

    rows: list[dict[str, Any]] = field(default_factory=list)
    benchmarks: dict[str, Any] = field(default_factory=dict)
    failed: bool = False

    def any_target_failed(self) -> bool:
        """A measured ratio is below its target."""
        return any(r["passed"] is False for r in self.rows)


def run_benchmarks(
    names: Sequence[str], quick: bool, say: Callable[[str], None] = lambda message: None
) -> PerfRun:
    """Run the benchmarks ``names`` (of :data:`BENCHMARKS`) one after another.

    A benchmark that raises is recorded as an error and the others still run; one
    whose module is absent is recorded as not present. ``say`` hears which one starts.
    """
    out = PerfRun()
    for name in names:
        try:
            module = importlib.import_module(module_name(name))
        except ModuleNotFoundError as exc:
            if exc.name == module_name(name):
                out.benchmarks[name] = {"status": "not present"}
                continue
            raise
        say(f"running {module_name(name)}{' (quick)' if quick else ''} ...")
        start = time.perf_counter()
        try:
            results = module.run(quick=quick)
        except Exception as exc:  # noqa: BLE001 - report and continue with the others
            out.failed = True
            message = f"{type(exc).__name__}: {exc}"
            out.benchmarks[name] = {"status": "error", "error": message}
            out.rows.append(_row(name, message[:80], None, None, None, None) | {"error": True})
            continue
        out.benchmarks[name] = {"seconds": time.perf_counter() - start, "results": results}
        out.rows += perf_rows(name, results, module)
    return out

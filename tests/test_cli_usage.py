"""Usage errors as a user meets them: each program run as a console script in a fresh
working directory, its error on one ``prog: error: ...`` line with the README's exit code,
no abbreviated options, "did you mean" for a misspelt option, choice or config key, and a
``--help`` that does not import the benchmark's machinery."""

from __future__ import annotations

import subprocess
import sys

import pytest
from _programs import ROOT, program_env, run_program


def _error_lines(stderr: str, prog: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith(f"{prog}: error: ")]


def test_an_abbreviated_option_is_refused_with_the_option_it_may_mean(tmp_path):
    # --workers 0 stops an old parser that took --stres for --stress before any work
    done = run_program("hasa-bench", "paper", "--stres", "--workers", "0", cwd=tmp_path)
    assert done.returncode == 2
    (line,) = _error_lines(done.stderr, "hasa-bench")
    assert "unrecognized arguments: --stres" in line and "did you mean '--stress'?" in line
    assert not list(tmp_path.iterdir())


def test_an_option_of_another_subcommand_is_named_as_such(tmp_path):
    # (it said "unrecognized arguments: --out x (did you mean '--out'?)")
    done = run_program("hasa-bench", "perf", "--out", "x", cwd=tmp_path)
    assert done.returncode == 2
    (line,) = _error_lines(done.stderr, "hasa-bench")
    assert "unrecognized arguments: --out x" in line
    assert "(--out is an option of 'hasa-bench paper' and 'hasa-bench score' only)" in line
    assert "did you mean" not in line


def test_a_misspelt_choice_and_subcommand_get_a_suggestion(tmp_path):
    done = run_program("hasa-bench", "paper", "--scenario", "lane_shfit", cwd=tmp_path)
    assert done.returncode == 2 and "did you mean 'lane_shift'?" in done.stderr
    done = run_program("hasa-rec", "infos", "x.csv", cwd=tmp_path)
    assert done.returncode == 2 and "did you mean 'info'?" in done.stderr
    # a misspelt required option: argparse says it is missing before that the word is unknown
    done = run_program("hasa-drive", "study", "s.toml", "--participnt", "P01", cwd=tmp_path)
    assert done.returncode == 2
    (line,) = _error_lines(done.stderr, "hasa-drive study")
    assert "did you mean '--participant'? '--participnt' is no option" in line, line


def test_a_misspelt_filter_field_and_study_key_get_a_suggestion(tmp_path):
    done = run_program(
        "hasa-bench", "paper", "--filter", "forgeting_time=3", "--seed", "0", cwd=tmp_path
    )
    assert done.returncode == 2
    (line,) = _error_lines(done.stderr, "hasa-bench")
    assert "'forgeting_time'" in line and "did you mean 'forgetting_time'?" in line
    study = tmp_path / "pilot.toml"
    study.write_text('[study]\nname = "pilot"\n[runs]\nsecnds = 5.0\n')
    done = run_program(
        "hasa-drive", "study", "pilot.toml", "--participant", "P01", "--check", cwd=tmp_path
    )
    assert done.returncode == 2
    (line,) = _error_lines(done.stderr, "hasa-drive study")
    assert "secnds" in line and "did you mean 'seconds'?" in line


def test_study_errors_have_the_error_prefix(tmp_path):
    done = run_program("hasa-drive", "study", "missing.toml", "--participant", "P01", cwd=tmp_path)
    assert done.returncode == 2
    assert _error_lines(done.stderr, "hasa-drive study") == [
        "hasa-drive study: error: missing.toml: no such study file"
    ]
    study = tmp_path / "pilot.toml"
    study.write_text('[study]\nname = "pilot"\n')
    done = run_program(
        "hasa-drive", "study", "pilot.toml", "--participant", "P01", "--synthetic", "Il",
        "--output", "out", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    (line,) = _error_lines(done.stderr, "hasa-drive study")
    assert "unknown driver 'Il'" in line and "did you mean 'Ill'?" in line
    assert not (tmp_path / "out").exists()


def test_calibrate_without_a_joystick_exits_3(tmp_path):
    done = run_program("hasa-drive", "calibrate", "--timeout", "0.2", cwd=tmp_path)
    assert done.returncode == 3, done.stderr
    (line,) = _error_lines(done.stderr, "hasa-drive calibrate")
    assert "no joystick found" in line
    assert not list(tmp_path.iterdir())


def test_bench_help_imports_no_protocol_plotting_or_statistics(tmp_path):
    code = (
        "import sys\n"
        "from hasa_cli.bench import build_parser\n"
        "build_parser().format_help()\n"
        "heavy = ('benchmarks.protocol', 'benchmarks.report', 'matplotlib', 'statsmodels',"
        " 'scipy', 'pandas', 'tqdm')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    done = subprocess.run(
        [sys.executable, "-P", "-c", code],
        cwd=tmp_path,
        env=program_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


@pytest.mark.slow
def test_a_fit_warning_is_one_warning_line_that_does_not_contradict_the_estimate(tmp_path):
    """The two-point fit on the sample is not identifiable by the fit's own standard error,
    yet the estimator then picks the true lane: the warning says how both hold, on one
    ``prog: warning:`` line (no Python file, line or category)."""
    sample = ROOT / "recordings" / "sample"
    done = run_program(
        "hasa-replay", str(sample), "--model", "two-point", "--fit", "--estimator", cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    assert "true lane trusted" in done.stdout
    lines = done.stderr.strip().splitlines()
    assert lines and all(line.startswith("hasa-replay: warning: ") for line in lines), lines
    (line,) = [ln for ln in lines if "static lane-offset gain" in ln]
    assert "carries no information" not in line and "may still decide a lane" in line
    assert "Warning:" not in done.stderr and ".py:" not in done.stderr


def _options_with_defaults(name, parser):
    """(program, option, default, help) of every option of ``parser`` and its subcommands
    whose default is a value (not None, False, an empty list or argparse.SUPPRESS)."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, subparser in action.choices.items():
                yield from _options_with_defaults(f"{name} {sub}", subparser)
        elif action.option_strings and action.default not in (None, False, argparse.SUPPRESS):
            if action.default != [] and not isinstance(action, argparse._VersionAction):
                yield name, action.option_strings[-1], action.default, action.help or ""


def test_every_option_with_a_default_says_it_in_its_help():
    """A user reads the default in --help (hasa-drive calibrate's --wheel-range and --output
    said none); "(9)" or "(default 9)" both count."""
    from hasa_cli import bench, drive, rec, replay, study

    parsers = {"hasa-bench": bench.build_parser(), "hasa-rec": rec.build_parser(),
               "hasa-replay": replay.build_parser(), "hasa-drive study": study.build_parser(),
               "hasa-drive calibrate": drive._calibrate_parser(),
               "hasa-drive synthetic": drive._synthetic_parser(),
               "hasa-drive": drive._drive_parser()}  # fmt: skip
    silent = []
    for name, parser in parsers.items():
        for prog, option, default, text in _options_with_defaults(name, parser):
            shown = [str(default), f"{default:g}" if isinstance(default, float) else str(default)]
            if "default" not in text and not any(f"({s}" in text for s in shown):
                silent.append(f"{prog} {option} (default {default!r}): {text!r}")
    assert not silent, "\n".join(silent)

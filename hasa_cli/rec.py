"""``hasa-rec``: inspect, convert and export recordings.

Commands::

    hasa-rec info PATH [PATH ...]        summarise and validate recordings (.csv or .parquet files,
                                         or every recording in a folder and below)
    hasa-rec convert SRC [-o OUT]        CSV recording(s) -> Parquet (needs pyarrow)
    hasa-rec export-minari DIR NAME      a folder of recordings -> Minari dataset NAME

Exit status (:mod:`hasa_cli`): 0 success; 1 partial: some input was invalid
(each named on stderr by file, line and column) or a target existed, the
valid ones were processed; 2 usage errors or nothing to do (no input is
valid); 3 a missing optional dependency (pyarrow, minari) or an export that
failed while reading or writing (a full disk; nothing is kept). What loading
repaired in a recording ``convert`` converts or ``export-minari`` exports (a
crashed recording's partly written last line, dropped) is named in a
``hasa-rec: warning:`` line; ``info`` lists it in the file's summary.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

from hasa_cli import (
    EXIT_ENVIRONMENT,
    EXIT_OK,
    EXIT_PARTIAL,
    EXIT_USAGE,
    ArgumentParser,
    add_version,
    console_script,
    error,
    printable,
    warn,
)
from hasa_env.recording import (
    Recording,
    RecordingError,
    RecordingWarning,
    load_recordings,
    warn_load_notes,
)
from hasa_env.recording.export import export_minari
from hasa_env.recording.parquet import require_pyarrow, to_parquet
from hasa_env.recording.reader import load_any, load_paths, subfolder_hint
from hasa_env.recording.summary import summarize

__all__ = ["main"]

PROG = "hasa-rec"


def _err(message: str) -> None:
    error(PROG, message)


def _info_items(names: Sequence[str]) -> list[tuple[str, Recording | RecordingError | None]]:
    """What ``info`` summarises, in order: a file as given (None: load it when shown), a
    folder as the recordings in it and below (each loaded, or its error; as
    :func:`~hasa_env.recording.reader.load_paths` finds them)."""
    items: list[tuple[str, Recording | RecordingError | None]] = []
    for name in names:
        if not Path(name).is_dir():
            items.append((name, None))
            continue
        loaded = load_paths([name])
        items += [(str(rec.path), rec) for rec in loaded]
        items += [(str(e.path or name), e) for e in loaded.errors]
    return items


def _info(args: argparse.Namespace) -> int:
    failed = 0
    items = _info_items(args.files)
    for i, (name, item) in enumerate(items):
        if i:
            print()
        try:
            if isinstance(item, RecordingError):
                raise item
            summary = summarize(name if item is None else item)
        except RecordingError as exc:
            print(f"file           {printable(name)}")
            print("valid          NO")
            _err(str(exc))
            failed += 1
            continue
        except ImportError as exc:
            _err(f"{name}: {exc}")
            return EXIT_ENVIRONMENT
        print("\n".join(printable(line) for line in summary.lines()))
    if len(items) > 1:  # the tally of a batch (a study's folder is long)
        print(f"\n{len(items)} recordings: {len(items) - failed} valid, {failed} not")
    if not failed:
        return EXIT_OK
    return EXIT_USAGE if failed == len(items) else EXIT_PARTIAL


def _targets(
    src: Path, out: Path | None
) -> tuple[list[tuple[Recording, Path]], list[RecordingError]]:
    """(recording, Parquet file) pairs to write, and the recordings that did not load."""
    if src.is_dir():
        if out is not None and out.exists() and not out.is_dir():
            raise ValueError(f"-o {out}: exists and is not a folder (converting a folder)")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordingWarning)
            recordings = load_recordings(src)
        pairs = [
            (rec, (out or rec.path.parent) / rec.path.with_suffix(".parquet").name)
            for rec in recordings
            if rec.path is not None
        ]
        return pairs, list(recordings.errors)
    if not src.exists() and not src.with_suffix(".json").exists():
        raise ValueError(f"{src}: no such file or directory")
    try:
        rec = load_any(src)
    except RecordingError as exc:
        return [], [exc]
    assert rec.path is not None
    name = rec.path.with_suffix(".parquet").name
    if out is None:
        target = rec.path.with_suffix(".parquet")
    elif out.is_dir():
        target = out / name
    elif out.suffix == ".parquet":
        target = out
    elif out.exists():
        raise ValueError(f"-o {out}: exists and is neither a folder nor a .parquet file")
    else:
        target = out / name
    if target.resolve() == rec.path.resolve():
        raise ValueError(f"-o {out}: is the recording itself")
    return [(rec, target)], []


def _convert(args: argparse.Namespace) -> int:
    try:
        require_pyarrow()
    except ImportError as exc:
        _err(str(exc))
        return EXIT_ENVIRONMENT
    src = Path(args.source)
    out = Path(args.output) if args.output else None
    try:
        targets, errors = _targets(src, out)
    except ValueError as exc:
        _err(str(exc))
        return EXIT_USAGE
    if not targets and not errors:
        _err(f"no recordings (*.csv with a .json sidecar) in {src}{subfolder_hint(src)}")
        return EXIT_USAGE
    warn_load_notes(rec for rec, _ in targets)  # e.g. a crashed recording's cut line, dropped
    problems = [str(e) for e in errors]
    written = 0
    for rec, target in targets:
        if target.exists() and not args.overwrite:
            problems.append(f"{target} exists; --overwrite replaces it")
            continue
        try:
            path = to_parquet(rec, target, overwrite=True)
        except OSError as exc:
            problems.append(f"{target}: cannot write: {exc}")
            continue
        written += 1
        print(printable(f"{rec.path} -> {path} ({rec.steps} steps)"))
    for problem in problems:
        _err(f"skipped: {problem}")
    if not problems:
        return EXIT_OK
    return EXIT_PARTIAL if written else EXIT_USAGE


def _os_reason(exc: OSError) -> str:
    """What an operating-system error says, with the file it concerns."""
    where = f" ({exc.filename})" if exc.filename else ""
    return f"{exc.strerror or exc}{where}"


def _export(args: argparse.Namespace) -> int:
    root = Path(args.directory)
    if not root.is_dir():
        _err(f"recordings folder {str(root)!r} does not exist")
        return EXIT_USAGE
    try:
        with warnings.catch_warnings():
            # each skipped recording is named below (result.skipped); what loading repaired in
            # a recording (hasa_env.recording.warn_load_notes) is shown as a warning: line
            warnings.filterwarnings("ignore", "not exported: ", RecordingWarning)
            result = export_minari(
                root,
                args.name,
                data_path=args.data_path,
                action_type=args.actions,
                observation_type=args.observations,
                overwrite=args.overwrite,
                author=args.author,
                description=args.description,
            )
    except ImportError as exc:
        _err(str(exc))
        return EXIT_ENVIRONMENT
    except (ValueError, FileNotFoundError) as exc:  # no such input, nothing valid in it
        _err(str(exc))
        return EXIT_USAGE
    except OSError as exc:  # an I/O failure (a full disk): the partly written dataset is gone
        _err(f"cannot export {args.name!r}: {_os_reason(exc)}; nothing was kept")
        return EXIT_ENVIRONMENT
    steps = result.dataset.total_steps
    print(
        f"exported {len(result.exported)} recording(s), {steps} steps, as Minari dataset "
        f"{result.dataset_id!r} (env {result.env_id}, {result.config['action']['type']} actions, "
        f"{result.config['observation']['type']} observations)"
    )
    stored = Path(result.dataset.spec.data_path).parent
    print(printable(f"stored in {stored}"))
    if args.data_path:
        root = Path(args.data_path).resolve()
        print(
            f"load it with MINARI_DATASETS_PATH={root} and "
            f"minari.load_dataset({result.dataset_id!r})"
        )
    for path in result.cut:
        warn(
            PROG,
            f"{path} ended without termination or truncation: its last step is marked "
            "truncated in the dataset",
        )
    for path, reason in result.skipped:
        _err(f"skipped {path}: {reason}")
    return EXIT_PARTIAL if result.skipped else EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-rec``."""
    parser = ArgumentParser(
        prog=PROG,
        description="Inspect, convert and export hasa_env recordings.",
        epilog="Exit status: 0 ok, 1 some inputs failed (each named), 2 usage or input error, "
        "3 a missing optional package.",
    )
    add_version(parser)
    sub = parser.add_subparsers(dest="command", required=True)

    p_info = sub.add_parser("info", help="summarise and validate recordings")
    p_info.add_argument(
        "files",
        nargs="+",
        metavar="PATH",
        help="a recording .csv (or .parquet), or a folder: every recording in it and below",
    )
    p_info.set_defaults(func=_info)

    p_conv = sub.add_parser("convert", help="convert CSV recordings to Parquet (needs pyarrow)")
    p_conv.add_argument("source", metavar="SRC", help="a recording .csv or a folder of them")
    p_conv.add_argument(
        "-o",
        "--output",
        metavar="OUT",
        help="output file (single recording) or folder (default: next to each CSV)",
    )
    p_conv.add_argument("--overwrite", action="store_true", help="replace existing .parquet files")
    p_conv.set_defaults(func=_convert)

    p_exp = sub.add_parser(
        "export-minari", help="export a folder of recordings as a Minari dataset"
    )
    p_exp.add_argument("directory", metavar="DIR", help="folder of recordings")
    p_exp.add_argument("name", metavar="NAME", help="dataset id, e.g. hasa/drives-v0")
    p_exp.add_argument(
        "--data-path",
        metavar="PATH",
        help="Minari datasets root (default: $MINARI_DATASETS_PATH or ~/.minari/datasets)",
    )
    p_exp.add_argument(
        "--actions",
        choices=("physical", "normalized"),
        default="physical",
        help="action space of the dataset and its recovered env (default: physical, rad and m/s^2)",
    )
    p_exp.add_argument(
        "--observations",
        choices=("sensors", "state", "both"),
        default=None,
        help="observation type (default: the recordings' config)",
    )
    p_exp.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    p_exp.add_argument("--author", default=None)
    p_exp.add_argument("--description", default=None)
    p_exp.set_defaults(func=_export)
    return parser


@console_script(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-rec``; returns the exit status."""
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""``hasa-rec``: inspect, convert and export recordings.

Commands::

    hasa-rec info FILE [FILE ...]        summarise and validate recordings (.csv or .parquet)
    hasa-rec convert SRC [-o OUT]        CSV recording(s) -> Parquet (needs pyarrow)
    hasa-rec export-minari DIR NAME      a folder of recordings -> Minari dataset NAME

Exit status: 0 success; 1 some input was invalid (reported on stderr by file
name, line and column; ``convert`` and ``export-minari`` still process the
valid ones); 2 usage errors, a missing optional dependency, or nothing to do.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

from hasa_env.recording import RecordingError, RecordingWarning, load_recording, load_recordings
from hasa_env.recording.export import export_minari
from hasa_env.recording.parquet import require_pyarrow, to_parquet
from hasa_env.recording.summary import summarize

__all__ = ["main"]

EXIT_OK, EXIT_INVALID, EXIT_USAGE = 0, 1, 2


def _err(message: str) -> None:
    print(message, file=sys.stderr)


def _info(args: argparse.Namespace) -> int:
    status = EXIT_OK
    for i, name in enumerate(args.files):
        if i:
            print()
        try:
            summary = summarize(name)
        except RecordingError as exc:
            print(f"file           {name}")
            print("valid          NO")
            _err(f"error: {exc}")
            status = EXIT_INVALID
            continue
        except ImportError as exc:
            _err(f"error: {exc}")
            return EXIT_USAGE
        print("\n".join(summary.lines()))
    return status


def _convert(args: argparse.Namespace) -> int:
    try:
        require_pyarrow()
    except ImportError as exc:
        _err(f"error: {exc}")
        return EXIT_USAGE
    src = Path(args.source)
    out = Path(args.output) if args.output else None
    errors: list[RecordingError] = []
    if src.is_dir():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordingWarning)
            recordings = load_recordings(src)
        errors.extend(recordings.errors)
        if not recordings and not errors:
            _err(f"error: no recordings (*.csv with a .json sidecar) in {src}")
            return EXIT_USAGE
        targets = [
            (rec, (out / rec.path.with_suffix(".parquet").name) if out else None)
            for rec in recordings
        ]
    else:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RecordingWarning)
                rec = load_recording(src)
        except RecordingError as exc:
            _err(f"error: {exc}")
            return EXIT_INVALID
        if out is not None and (out.is_dir() or out.suffix != ".parquet"):
            out = out / rec.path.with_suffix(".parquet").name
        targets = [(rec, out)]
    for rec, target in targets:
        written = to_parquet(rec, target)
        print(f"{rec.path} -> {written} ({rec.steps} steps)")
    for exc in errors:
        _err(f"skipped corrupt recording: {exc}")
    return EXIT_INVALID if errors else EXIT_OK


def _export(args: argparse.Namespace) -> int:
    root = Path(args.directory)
    if not root.is_dir():
        _err(f"error: recordings folder {str(root)!r} does not exist")
        return EXIT_USAGE
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordingWarning)
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
        _err(f"error: {exc}")
        return EXIT_USAGE
    except ValueError as exc:
        _err(f"error: {exc}")
        return EXIT_USAGE
    steps = result.dataset.total_steps
    print(
        f"exported {len(result.exported)} recording(s), {steps} steps, as Minari dataset "
        f"{result.dataset_id!r} (env {result.env_id}, {result.config['action']['type']} actions, "
        f"{result.config['observation']['type']} observations)"
    )
    stored = Path(result.dataset.spec.data_path).parent
    print(f"stored in {stored}")
    if args.data_path:
        root = Path(args.data_path).resolve()
        print(
            f"load it with MINARI_DATASETS_PATH={root} and "
            f"minari.load_dataset({result.dataset_id!r})"
        )
    for path in result.cut:
        print(f"note: {path} ended without termination or truncation; last step marked truncated")
    for path, reason in result.skipped:
        _err(f"skipped {path}: {reason}")
    return EXIT_INVALID if result.skipped else EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-rec``; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="hasa-rec", description="Inspect, convert and export hasa_env recordings."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p_info = sub.add_parser("info", help="summarise and validate recordings")
    p_info.add_argument("files", nargs="+", metavar="FILE", help="a recording .csv (or .parquet)")
    p_info.set_defaults(func=_info)

    p_conv = sub.add_parser("convert", help="convert CSV recordings to Parquet (needs pyarrow)")
    p_conv.add_argument("source", metavar="SRC", help="a recording .csv or a folder of them")
    p_conv.add_argument(
        "-o",
        "--output",
        metavar="OUT",
        help="output file (single recording) or folder (default: next to each CSV)",
    )
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

    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

"""``python -m benchmarks.schema FOLDER...``: check hasa-bench result folders against the
shipped schemas; prints every problem (one line each), exits 1 if any.
``python -m benchmarks.schema --markdown``: the field tables of docs/results.md."""

from __future__ import annotations

import sys

from benchmarks.schema import folder_problems, markdown_fields


def main(argv: list[str] | None = None) -> int:
    folders = sys.argv[1:] if argv is None else argv
    if folders == ["--markdown"]:
        print(markdown_fields(), end="")
        return 0
    if not folders or any(f.startswith("-") for f in folders):
        print(
            "usage: python -m benchmarks.schema FOLDER... | --markdown\n"
            "benchmarks.schema: error: give result folders to check, or --markdown",
            file=sys.stderr,
        )
        return 2
    problems = [p for folder in folders for p in folder_problems(folder)]
    for problem in problems:
        print(f"benchmarks.schema: error: {problem}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())

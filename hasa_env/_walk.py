"""Walking a folder tree of recordings without leaving anything out silently.

``Path.rglob`` skips a folder it cannot read and does not enter a symlink to a folder
(Python < 3.13), so a participant's folder with mode 000, or one linked into the study
folder, vanished from an analysis without a word. :func:`walk_files` enters symlinked
folders (each real folder once: a link cycle ends there) and returns every folder it
could not read, with the reason, for the caller to name.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

__all__ = ["walk_files"]


def walk_files(
    root: str | os.PathLike[str], suffixes: Iterable[str] = (), names: Iterable[str] = ()
) -> tuple[list[Path], list[tuple[Path, str]]]:
    """Every file under ``root`` (and in folders linked into it) whose suffix is one of
    ``suffixes`` or whose name is one of ``names``, sorted; and every folder that could not
    be read or searched, as (folder, reason), sorted.

    A folder reached twice (a symlink to a folder already walked, or a link cycle) is walked
    once; its files are listed under the first path it was reached by.
    """
    suffixes, names = tuple(suffixes), frozenset(names)
    files: list[Path] = []
    problems: list[tuple[Path, str]] = []
    seen: set[str] = set()
    stack = [Path(root)]
    while stack:
        folder = stack.pop()
        real = os.path.realpath(folder)
        if real in seen:
            continue
        seen.add(real)
        try:
            entries = sorted(os.scandir(folder), key=lambda e: e.name)
        except OSError as exc:
            problems.append((folder, f"cannot read this folder: {exc.strerror or exc}"))
            continue
        if entries and not os.access(folder, os.X_OK):
            problems.append((folder, "cannot search this folder (no execute permission)"))
            continue
        for entry in entries:
            path = folder / entry.name
            try:
                is_dir = entry.is_dir()  # follows a symlink to a folder
            except OSError:
                is_dir = False
            if is_dir:
                stack.append(path)
            elif entry.name in names or entry.name.endswith(suffixes):
                files.append(path)
    return sorted(files), sorted(problems)

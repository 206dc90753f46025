"""Writing files safely: the one atomic-write helper of hasa_env.

Every file hasa_env rewrites in place (recording sidecars, session files,
calibration files, PNG frames) is written to a *new, randomly named*
temporary file next to its target (``O_CREAT | O_EXCL``: an existing file or
a pre-placed symlink at that name is never opened, so never followed), then
moved over the target with ``os.replace`` (which replaces a symlink at the
target itself rather than writing through it). On any failure (a full disk,
an interrupt) the temporary file is removed and the target is left as it
was: a reader sees the old or the new content, never a torn or empty file.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path

__all__ = ["fsync_directory", "new_temporary_file", "write_atomic"]


def new_temporary_file(path: Path) -> tuple[int, Path]:
    """A new, randomly named file next to ``path`` (``O_CREAT | O_EXCL``, mode 0o666 & ~umask).

    ``O_EXCL`` never opens an existing file, so a pre-placed file or symlink
    at a predictable ``<name>.tmp`` is neither followed nor overwritten.

    Returns:
        The open file descriptor (write only) and the temporary file's path.
    """
    path = Path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary file name next to {path}")


def fsync_directory(directory: Path) -> None:
    """Flush a directory's entries to disk (where the platform can open directories)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_atomic(path: str | os.PathLike[str], data: str | bytes, fsync: bool = True) -> None:
    """Write ``data`` (text, as UTF-8; or bytes) to ``path`` atomically.

    Via a new temporary file (:func:`new_temporary_file`) and ``os.replace``;
    ``fsync`` also flushes the file and its folder to disk. On any failure
    (``OSError`` such as ``ENOSPC``, an interrupt) the temporary file is
    removed, ``path`` is left as it was and the exception propagates.
    """
    path = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    fd, tmp = new_temporary_file(path)
    try:
        try:
            view = memoryview(raw)
            while view:
                view = view[os.write(fd, view) :]
            if fsync:
                os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    if fsync:
        fsync_directory(path.parent)

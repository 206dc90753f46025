"""Reading a user's input files safely: regular files only, bounded in size, never blocking.

:func:`read_bounded_bytes` is what every reader of a file named by a user goes
through (recordings and their sidecars, model files, study files): it opens
the path without blocking (``O_NONBLOCK``: a FIFO with no writer would
otherwise wait for ever), refuses anything but a regular file (``/dev/zero``,
a FIFO, a socket, a directory) before reading a byte, and refuses a file
larger than the cap given, so that a wrong path cannot make a program read
until the machine runs out of memory.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["FileReadError", "file_kind", "read_bounded_bytes", "read_bounded_text"]


class FileReadError(OSError):
    """A file that is not a regular file or is larger than the reader's cap (one-line message,
    naming what the file is and the cap)."""


def file_kind(mode: int) -> str:
    """What a non-regular file of ``st_mode`` ``mode`` is, for an error message ("a FIFO ...")."""
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"


def _size_text(n: int) -> str:
    """``n`` bytes for a message: ``"16 MiB"``, ``"2 GiB"`` or ``"1234 bytes"``."""
    for unit, size in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size and n % size == 0:
            return f"{n // size} {unit}"
    return f"{n} bytes"


def read_bounded_bytes(path: str | os.PathLike[str], what: str, max_bytes: int) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most ``max_bytes`` bytes.

    The file is opened with ``O_NONBLOCK`` and checked with ``fstat`` before
    anything is read, and at most ``max_bytes + 1`` bytes are read (a file that
    grows while it is read is refused too).

    Args:
        path: the file; what: how a message names it ("the model file").
        max_bytes: the largest size read (bytes, >= 0).

    Raises:
        FileNotFoundError, PermissionError, IsADirectoryError: from ``open``.
        FileReadError: not a regular file, or larger than ``max_bytes``.
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise FileReadError(f"{what} is {file_kind(info.st_mode)}, not a regular file")
        if info.st_size > max_bytes:
            raise FileReadError(
                f"{what} is {info.st_size} bytes, more than the {_size_text(max_bytes)} read"
            )
    except BaseException:
        os.close(fd)
        raise
    with open(fd, "rb") as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise FileReadError(f"{what} grew past the {_size_text(max_bytes)} read while being read")
    return data


def read_bounded_text(path: str | os.PathLike[str], what: str, max_bytes: int) -> str:
    """:func:`read_bounded_bytes` decoded as UTF-8 (``UnicodeDecodeError`` if it is not)."""
    return read_bounded_bytes(Path(path), what, max_bytes).decode("utf-8")

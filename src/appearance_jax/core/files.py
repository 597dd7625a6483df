"""Reading data files safely: regular files only, with a size limit checked before reading.

Every loader of the package (measurement tables, MERL ``.binary`` files, refractiveindex.info
YAML) reads its file through :func:`read_regular_file` or :func:`open_regular_file`, and the
table writers check their output with :func:`check_output_path`, so that

- a FIFO, a socket or a device (``/dev/zero``) is rejected at once instead of blocking or
  reading forever: the path is checked with ``os.stat`` before it is opened, opened without
  blocking and checked again on the open descriptor (the file cannot be swapped in between);
- a file larger than the caller's limit is rejected from its size, before any byte of it is
  read (and at most ``max_bytes`` bytes are ever read, should it grow meanwhile).

Problems are raised as :class:`FileProblem` (a ``ValueError``) whose ``problem`` text has no
file name, so each loader can prefix it in its own error style.
"""

from __future__ import annotations

import os
import stat

__all__ = ["FileProblem", "file_kind", "open_regular_file", "read_regular_file",
           "check_output_path"]


class FileProblem(ValueError):
    """A file that is not a readable regular file of an acceptable size; ``problem`` says why."""

    def __init__(self, problem: str):
        super().__init__(problem)
        self.problem = problem


def file_kind(mode: int) -> str:
    """Human-readable kind of a file from its ``st_mode`` ("a FIFO (named pipe)", ...)."""
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return name
    return "an unknown kind of file"


def _check(st: os.stat_result, max_bytes: int | None) -> int:
    if not stat.S_ISREG(st.st_mode):
        raise FileProblem(f"is {file_kind(st.st_mode)}, not a regular file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise FileProblem(f"file has {st.st_size} bytes, more than the limit of {max_bytes} bytes")
    return int(st.st_size)


def open_regular_file(path, max_bytes: int | None = None):
    """``(file, size)``: the regular file ``path`` opened for binary reading, and its size.

    The path is checked with ``os.stat`` before it is opened (opening a FIFO would block),
    opened without blocking, and the open descriptor checked again. Close the file when done
    (``with f: ...``); read at most ``size`` bytes from it.

    Raises:
        FileProblem: not a regular file (FIFO, device, directory, ...), or larger than ``max_bytes``.
        OSError: the file does not exist or cannot be opened.
    """
    p = os.fspath(path)
    _check(os.stat(p), max_bytes)
    fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    f = os.fdopen(fd, "rb")
    try:
        n = _check(os.fstat(f.fileno()), max_bytes)  # the file that was actually opened
    except BaseException:
        f.close()
        raise
    return f, n


def read_regular_file(path, max_bytes: int | None = None) -> bytes:
    """All bytes of the regular file ``path``, checked (kind, size) before reading.

    Args:
        path: file name (str or path-like).
        max_bytes: refuse files larger than this (None: no limit); at most this many bytes
            are read, even if the file grows meanwhile.

    Raises:
        FileProblem: not a regular file (FIFO, device, directory, ...), or too large.
        OSError: the file does not exist or cannot be opened or read.
    """
    f, _ = open_regular_file(path, max_bytes)
    with f:
        data = f.read() if max_bytes is None else f.read(max_bytes + 1)
    if max_bytes is not None and len(data) > max_bytes:  # grew while being read
        raise FileProblem(f"file has more than the limit of {max_bytes} bytes")
    return data


def check_output_path(path) -> None:
    """Refuse to write to ``path`` when it exists and is not a regular file.

    Opening a FIFO for writing blocks until something reads it, and writing a table to a
    device or over a directory is never meant; a missing path or a regular file is fine.

    Raises:
        FileProblem: ``path`` is a FIFO, a device, a directory, ...
    """
    try:
        st = os.stat(os.fspath(path))
    except FileNotFoundError:
        return
    if not stat.S_ISREG(st.st_mode):
        raise FileProblem(f"is {file_kind(st.st_mode)}, not a regular file to write to")

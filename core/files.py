"""Reading the user's input files: regular files only, bounded sizes, one-line errors.

A job names files: the job itself, its includes and motion profile, glTF scenes and
their external buffers, mesh files. Each is opened without blocking (``O_NONBLOCK``: a
FIFO would otherwise wait for a writer forever, a device could stream without end),
checked to be a regular file on the open descriptor (``fstat``, so nothing can be
swapped in between a check and the open), and read up to a size limit. A path with a
NUL byte, a symlink loop, a missing file, a folder, a FIFO, a device or socket, a file
that is too large or unreadable: each is a :class:`~.errors.UserError` naming the key
and the job file, never a traceback or a hang.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from pathlib import Path

from .errors import UserError

MAX_TEXT_BYTES = 64 * 2**20
"""Largest text input (a job, an include, glTF JSON): 64 MiB."""
MAX_BINARY_BYTES = 4 * 2**30
"""Largest binary input (a .glb, a glTF buffer, a mesh file): 4 GiB."""


def check_path_text(text: str | os.PathLike, key: str | None, file: str | Path | None
                    ) -> None:
    """A path's text is usable: no NUL byte (the OS cannot name such a file)."""
    if "\0" in os.fspath(text):
        raise UserError(f"the path {os.fspath(text)!r} contains a NUL byte", key=key,
                        file=file)


def resolve_path(text: str | os.PathLike, base: Path | None, key: str | None,
                 file: str | Path | None) -> Path:
    """``text`` made absolute (relative to ``base``), ``~`` expanded, symlinks resolved.

    A NUL byte or a symlink loop is a UserError naming ``key`` and ``file``; a missing
    file is not (the caller decides whether it must exist).
    """
    check_path_text(text, key, file)
    path = Path(text).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    name = "" if file is not None and Path(file) == Path(text) else f"{path}: "
    try:
        return path.resolve()
    except RuntimeError:  # Python < 3.13: "Symlink loop from ..."
        raise UserError(f"{name}a symlink loop", key=key, file=file) from None
    except OSError as e:
        raise UserError(f"{name}{_reason(e)}", key=key, file=file) from None


def open_regular(path: Path, key: str | None, file: str | Path | None,
                 limit: int = MAX_BINARY_BYTES) -> int:
    """An open, read-only descriptor of the regular file ``path`` (the caller closes it).

    Opened with ``O_NONBLOCK`` and checked with ``fstat``: directories, FIFOs, devices and
    sockets are refused without waiting, and so is a file larger than ``limit`` bytes.
    """
    check_path_text(path, key, file)
    name = "" if file is not None and Path(file) == Path(path) else f"{path}: "
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise UserError(f"{name}file not found", key=key, file=file) from None
    except OSError as e:
        raise UserError(f"{name}cannot read: {_reason(e)}", key=key, file=file) from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise UserError(f"{name}a directory, not a file", key=key, file=file)
        if not stat.S_ISREG(info.st_mode):
            raise UserError(f"{name}not a regular file (a FIFO, device or socket)",
                            key=key, file=file)
        if info.st_size > limit:
            raise UserError(f"{name}too large ({info.st_size} bytes; at most {limit})",
                            key=key, file=file)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


def read_input(path: Path, key: str | None, file: str | Path | None,
               limit: int = MAX_BINARY_BYTES) -> bytes:
    """The bytes of the regular file ``path`` (see :func:`open_regular`)."""
    fd = open_regular(path, key, file, limit)
    try:
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1)
    except OSError as e:
        raise UserError(f"{path}: cannot read: {_reason(e)}", key=key, file=file) from None
    finally:
        os.close(fd)
    if len(data) > limit:  # grew while we read it
        raise UserError(f"{path}: too large (more than {limit} bytes)", key=key, file=file)
    return data


def check_readable(path: Path, key: str | None, file: str | Path | None,
                   limit: int = MAX_BINARY_BYTES) -> None:
    """``path`` is a regular file this process can open (for files a library reads)."""
    os.close(open_regular(path, key, file, limit))


def is_regular_file(path: Path) -> bool:
    """Whether ``path`` is (a symlink to) a regular file; never raises, never blocks."""
    with contextlib.suppress(OSError, ValueError):
        return stat.S_ISREG(os.stat(path).st_mode)
    return False


def _reason(e: OSError) -> str:
    if e.errno == errno.ELOOP:
        return "a symlink loop"
    return e.strerror or " ".join(str(e).split()) or type(e).__name__

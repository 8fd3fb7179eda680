"""Reading the files a user names: task files, robot.toml, URDF.

Every way reading such a path can fail - missing, a directory, a FIFO, a symlink loop, a name too
long, a path through a regular file, a NUL byte, permission denied, not UTF-8, too large - becomes
one line naming the path and the cause, raised as the caller's :class:`~dualarm.errors.DualarmError`
subclass. Only regular files are opened, and they are opened non-blocking, so reading never waits
on a FIFO or a device.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from dualarm.errors import DualarmError, excerpt

#: The largest file :func:`read_text` reads [bytes] (16 MiB; the shipped task files are below 6 kB,
#: the humanoid's URDF below 20 kB).
MAX_FILE_BYTES = 16 * 1024 * 1024

#: What :func:`kind` says of a regular file and of a directory.
REGULAR_FILE, DIRECTORY = "a regular file", "a directory"
_KINDS = (
    (stat.S_ISDIR, DIRECTORY),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def listing(names: Iterable[object], most: int = 12) -> str:
    """``names`` joined by commas for a message: the first ``most`` and then how many there are in all.

    Each is quoted with :func:`~dualarm.errors.excerpt`.
    """
    quoted = [excerpt(n, 40) for n in names]
    if len(quoted) <= most:
        return ", ".join(quoted) or "none"
    return f"{', '.join(quoted[:most])}, ... ({len(quoted)} in all)"


def cause(exc: OSError | ValueError) -> str:
    """The reason an OS call on a path failed, in the OS's words (``strerror``).

    For example "No such file or directory", "Too many levels of symbolic links", ...
    """
    if isinstance(exc, OSError):
        return exc.strerror or type(exc).__name__
    return "the path holds a NUL byte" if "null" in str(exc) else excerpt(str(exc))


def kind(path: str | Path) -> str | None:
    """What ``path`` is (``a regular file``, ``a directory``, ``a FIFO``, ...), following symbolic links.

    None when it cannot be looked at (missing, a loop, too long, a NUL byte, ...). Never raises.
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return _kind(mode)


def _kind(mode: int) -> str:
    if stat.S_ISREG(mode):
        return REGULAR_FILE
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def read_text(path: str | Path, what: str, error: type[DualarmError], *, max_bytes: int = MAX_FILE_BYTES) -> str:
    """The UTF-8 text of the regular file ``path``.

    Args:
        path: the file.
        what: what the file is, for the message (``task file``, ``robot.toml``, ``URDF``).
        error: the error class to raise.
        max_bytes: the largest size accepted [bytes].

    Raises:
        error: one line, ``<path>: cannot read the <what>: <cause>`` (the path quoted with
            :func:`~dualarm.errors.excerpt`), when the path cannot be looked at or opened, is not a regular file, is
            larger than ``max_bytes`` or is not UTF-8. Nothing but a regular file is opened.
    """
    where = excerpt(path)

    def fail(reason: str) -> DualarmError:
        return error(f"{where}: cannot read the {what}: {reason}")

    try:
        mode = os.stat(path).st_mode  # before opening: a FIFO or a device is never opened
    except (OSError, ValueError) as exc:
        raise fail(cause(exc)) from None
    if not stat.S_ISREG(mode):
        raise fail(f"it is {_kind(mode)}, not a regular file")
    try:
        # non-blocking, and checked again once open, in case the path was swapped in between
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except (OSError, ValueError) as exc:
        raise fail(cause(exc)) from None
    try:
        with os.fdopen(fd, "rb") as file:
            opened = os.fstat(file.fileno())
            if not stat.S_ISREG(opened.st_mode):
                raise fail(f"it is {_kind(opened.st_mode)}, not a regular file")
            if opened.st_size > max_bytes:
                raise fail(f"{opened.st_size:,} bytes, more than the {max_bytes:,} accepted")
            data = file.read(max_bytes + 1)
    except OSError as exc:
        raise fail(cause(exc)) from None
    if len(data) > max_bytes:
        raise fail(f"more than the {max_bytes:,} bytes accepted")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise fail(f"not UTF-8 text (byte {exc.start})") from None

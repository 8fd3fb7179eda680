"""Silencing of what C libraries print straight to the process's file descriptors.

Such as PyBullet's banners and qpOASES's licence text: silenced so the CLI's stdout stays
machine-readable.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator


@contextlib.contextmanager
def c_output_silenced() -> Iterator[None]:
    """Send file descriptors 1 and 2 to /dev/null for the duration (C-level prints)."""
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)

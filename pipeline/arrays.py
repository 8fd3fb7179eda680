"""Read-only arrays for the immutable stage contracts."""

from __future__ import annotations

import numpy as np


def frozen(a, shape: tuple, name: str, dtype=float) -> np.ndarray:
    """A read-only copy of ``a`` as ``dtype``; ValueError naming ``name`` if its shape is not ``shape``."""
    a = np.array(a, dtype=dtype)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    a.setflags(write=False)
    return a

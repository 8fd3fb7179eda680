"""Read-only arrays for the immutable stage contracts, and the checks of array arguments.

The checks run at the public entry points; each failure is an
:class:`~dualarm.errors.InvalidArgumentError` naming the argument: a wrong shape, a NaN, a matrix
that is not a rigid transform.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from dualarm.errors import InvalidArgumentError

#: Largest deviation of R^T R from the identity, and of the last row from [0, 0, 0, 1], for a 4x4
#: argument to count as a rigid transform.
RIGID_TOLERANCE = 1e-6


def frozen(a: Any, shape: tuple[int, ...], name: str, dtype: type = float) -> np.ndarray:
    """A read-only copy of ``a`` as ``dtype``.

    Raises InvalidArgumentError naming ``name`` if its shape is not ``shape``.
    """
    a = np.array(a, dtype=dtype)
    if a.shape != shape:
        raise InvalidArgumentError(name, f"expected shape {shape}, got {a.shape}")
    a.setflags(write=False)
    return a


def finite_array(a: Any, name: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """``a`` as a float array, checked: the ``shape`` (``None`` entries match any length) and finite.

    Raises:
        InvalidArgumentError: not numbers, a wrong shape, or a NaN or infinity (with its index).
    """
    try:
        array = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        raise InvalidArgumentError(name, f"expected an array of numbers, got {type(a).__name__}") from None
    if shape is not None and (
        array.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, array.shape, strict=True))
    ):
        wanted = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise InvalidArgumentError(name, f"expected shape {wanted}, got {array.shape}")
    bad = np.argwhere(~np.isfinite(array))
    if len(bad):
        where = tuple(int(i) for i in bad[0])
        at = "" if array.ndim == 0 else f" at index {where if array.ndim > 1 else where[0]}"
        raise InvalidArgumentError(name, f"is not finite{at} ({array[where]})")
    return array


def rigid_transforms(a: Any, name: str, *, many: bool = False) -> np.ndarray:
    """``a`` as a 4x4 rigid transform (or (N, 4, 4) with ``many``), checked.

    The checks: shape, finite, a rotation block with R^T R = I and det R = 1, and the last row [0,
    0, 0, 1].

    Raises:
        InvalidArgumentError: naming the argument and what is wrong (a 3x3 where a 4x4 belongs, a NaN, ...).
    """
    T = finite_array(a, name, (None, 4, 4) if many else (4, 4))
    stack = T.reshape(-1, 4, 4)
    R = stack[:, :3, :3]
    orthogonal = np.abs(R.transpose(0, 2, 1) @ R - np.eye(3)).max(axis=(1, 2))
    row = np.abs(stack[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1)
    bad = np.flatnonzero((orthogonal > RIGID_TOLERANCE) | (row > RIGID_TOLERANCE) | (np.linalg.det(R) < 0))
    if len(bad):
        which = f" (pose {bad[0]})" if many else ""
        raise InvalidArgumentError(
            name,
            f"is not a rigid transform{which}: the rotation block must be "
            "orthonormal with determinant 1 and the last row [0, 0, 0, 1]",
        )
    return T


def joint_vector(q: Any, joint_names: tuple[str, ...], name: str) -> np.ndarray:
    """A configuration of ``joint_names`` [rad] from an array (n,) or a mapping joint name -> value.

    The mapping names every joint; the values are checked finite.

    Raises:
        InvalidArgumentError: a wrong length, a joint missing from the mapping, a NaN.
    """
    if isinstance(q, Mapping):
        missing = [n for n in joint_names if n not in q]
        if missing:
            raise InvalidArgumentError(name, f"has no value for joint {missing[0]} (needs {', '.join(joint_names)})")
        q = [q[n] for n in joint_names]
    return finite_array(q, name, (len(joint_names),))

"""Rotations about a constant unit axis as CasADi expressions (Rodrigues' formula).

Given the angle's cosine and sine.
"""

from __future__ import annotations

import casadi as cs
import numpy as np


def hat(k: np.ndarray) -> np.ndarray:
    """The cross-product matrix [k] of a 3-vector, [k] x = k x x."""
    return np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])


def rotation(k: np.ndarray, c, s) -> cs.SX:
    """exp([k] angle) for a constant unit axis ``k``, given c = cos and s = sin of the angle (Rodrigues)."""
    K = hat(k)
    return cs.SX.eye(3) + s * K + (1 - c) * (K @ K)


def rotate(k: np.ndarray, c, s, x):
    """exp([k] angle) x for a constant unit axis ``k``, given c = cos and s = sin of the angle (Rodrigues)."""
    return c * x + s * cs.cross(k, x) + (1 - c) * cs.dot(k, x) * k

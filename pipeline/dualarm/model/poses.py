"""Small helpers for homogeneous transforms (numpy) built on scipy's Rotation."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation


def pose_matrix(position: ArrayLike, rpy: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 transform from a position [m] and extrinsic x-y-z roll-pitch-yaw [rad] (R = Rz Ry Rx)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    T[:3, 3] = position
    return T


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (..., 4, 4)."""
    R = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = R
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3), w >= 0."""
    q = Rotation.from_matrix(R).as_quat()
    return np.where(q[..., 3:4] < 0, -q, q)


def pose_errors(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position [m] and rotation-angle [rad] differences between pose stacks (N, 4, 4)."""
    position = np.linalg.norm(A[:, :3, 3] - B[:, :3, 3], axis=1)
    relative = np.einsum("nji,njk->nik", A[:, :3, :3], B[:, :3, :3])
    rotation = np.linalg.norm(Rotation.from_matrix(relative).as_rotvec(), axis=1)
    return position, rotation

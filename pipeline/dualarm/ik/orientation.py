"""Hand orientation: the error the velocity-level methods feed back and the error every IK run reports.

- :func:`rotation_vector`: the rotation vector of a rotation matrix as a CasADi expression, the
  orientation error e_o = log(R_d R^T) that TV-GDD and pinv feed back in pose mode.
- :func:`angular_jacobian`: the Jacobian J_omega (3 x n) of a symbolic rotation matrix, the angular
  velocity omega = J_omega thetadot in the frame the rotation is expressed in.
- :func:`orientation_errors`: per sample and hand, the angle of R_asked^T R_reached [rad] (scipy).

liecasadi's ``SO3.from_matrix`` would give the rotation vector too, but it takes square roots of
``1 + R_00 - R_11 - R_22``-like terms that rounding makes negative near the identity (NaN on half
of the near-zero errors of a tracking controller), so the quaternion is taken here by Shepperd's
method: from the largest of its four squared components, every square root of a non-negative number.
"""

from __future__ import annotations

import casadi as cs
import numpy as np
from scipy.spatial.transform import Rotation

#: Below this norm of the quaternion's vector part the log map uses its limit 2 / w (no 0 / 0).
_SMALL = 1e-12


def _quaternion(E) -> cs.SX:
    """Unit quaternion [w, x, y, z] of a rotation matrix (3x3 SX/MX/DM) by Shepperd's method, with w >= 0."""
    trace = E[0, 0] + E[1, 1] + E[2, 2]
    squares = [
        1 + trace,
        1 + 2 * E[0, 0] - trace,
        1 + 2 * E[1, 1] - trace,
        1 + 2 * E[2, 2] - trace,
    ]  # 4 w^2, 4 x^2, 4 y^2, 4 z^2
    a = (E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1])  # 4 w x, 4 w y, 4 w z
    s = (E[0, 1] + E[1, 0], E[0, 2] + E[2, 0], E[1, 2] + E[2, 1])  # 4 x y, 4 x z, 4 y z
    products = [
        cs.vertcat(squares[0], a[0], a[1], a[2]),  # 4 w * (w, x, y, z)
        cs.vertcat(a[0], squares[1], s[0], s[1]),  # 4 x * (w, x, y, z)
        cs.vertcat(a[1], s[0], squares[2], s[2]),  # 4 y * (w, x, y, z)
        cs.vertcat(a[2], s[1], s[2], squares[3]),  # 4 z * (w, x, y, z)
    ]
    candidates = [p / (2 * cs.sqrt(cs.fmax(sq, _SMALL))) for p, sq in zip(products, squares, strict=True)]
    largest = [
        cs.logic_and(cs.logic_and(sq >= squares[(i + 1) % 4], sq >= squares[(i + 2) % 4]), sq >= squares[(i + 3) % 4])
        for i, sq in enumerate(squares)
    ]
    q = cs.if_else(
        largest[0],
        candidates[0],
        cs.if_else(largest[1], candidates[1], cs.if_else(largest[2], candidates[2], candidates[3])),
    )
    return cs.if_else(q[0] < 0, -q, q)


def rotation_vector(E):
    """The rotation vector (3,) [rad] of a rotation matrix ``E`` (3x3 CasADi SX, MX or DM).

    Axis times angle, angle in [0, pi].

    At an angle of exactly pi the axis's sign is arbitrary, as for every rotation vector.
    """
    q = _quaternion(E)
    w, v = q[0], q[1:]
    norm = cs.norm_2(v)
    scale = cs.if_else(
        norm < _SMALL, 2 / cs.fmax(w, _SMALL), 2 * cs.atan2(norm, w) / cs.fmax(norm, _SMALL)
    )  # angle / sin(angle / 2)
    return scale * v


def orientation_error(R_desired, R):
    """e_o = log(R_d R^T) (3,) [rad]: the rotation that takes ``R`` to ``R_desired``.

    In their common frame (3x3 each).
    """
    return rotation_vector(R_desired @ R.T)


def angular_jacobian(R: cs.SX, theta: cs.SX) -> cs.SX:
    """J_omega (3 x n) of a rotation matrix ``R`` (3x3 SX) depending on ``theta`` (n).

    omega = J_omega thetadot in R's frame.

    With r_k the columns of R, rdot_k = omega x r_k, so sum_k r_k x rdot_k = 2 omega and
    J_omega = 1/2 sum_k skew(r_k) d r_k / d theta.
    """
    return 0.5 * sum(cs.skew(R[:, k]) @ cs.jacobian(R[:, k], theta) for k in range(3))


def orientation_errors(asked: np.ndarray, reached: np.ndarray) -> np.ndarray:
    """Angle of R_asked^T R_reached [rad] in [0, pi] for rotations (..., 3, 3) each; shape (...)."""
    asked, reached = np.asarray(asked, dtype=float), np.asarray(reached, dtype=float)
    shape = np.broadcast_shapes(asked.shape, reached.shape)[:-2]
    relative = np.swapaxes(asked, -1, -2) @ reached
    return Rotation.from_matrix(relative.reshape(-1, 3, 3)).magnitude().reshape(shape)

"""Closed-form pieces of S-R-S inverse kinematics, as CasADi expressions of constant unit axes.

Rotations are products of exponentials exp([k] angle) about axes k given at the zero
configuration (see :mod:`dualarm.ik.analytic.mc_inverse`). Paden-Kahan sub-problem 1 turns one
vector onto another about one axis, :func:`elbow` is MC-Inverse's sub-problem 1, :func:`subproblem2`
one vector onto another by two rotations about intersecting axes; :func:`euler` solves three
consecutive perpendicular axes (MC-Inverse sub-problems 2 and 3, eqs 9-10 for ZYZ axes);
:func:`into_limits` moves an angle by 2 pi into limits that reach past +-pi.
"""

from __future__ import annotations

import math

import casadi as cs
import numpy as np

from dualarm.model.kinematics import chain_frames
from dualarm.model.robot import Chain
from dualarm.model.rodrigues import rotate, rotation

#: Relative slack on the law-of-cosines argument before a wrist centre counts as out of reach.
REACH_SLACK = 1e-12


def turn(k: np.ndarray, p, q):
    """Angle about unit axis ``k`` that turns vector p onto vector q (Paden-Kahan sub-problem 1)."""
    return cs.atan2(cs.dot(k, cs.cross(p, q)), cs.dot(p, q) - cs.dot(k, p) * cs.dot(k, q))


def euler(Q, ka: np.ndarray, kb: np.ndarray, kc: np.ndarray):
    """Both solutions of Q = exp(ka ta) exp(kb tb) exp(kc tc) for perpendicular ka, kb and kb, kc.

    Eqs 9 and 10 for ZYZ axes: a list of two (ta, tb, tc), and |sin| of the middle angle measured from its singular
    positions (0 where ta and tc are not separable).
    """
    phi = float(np.arctan2(ka @ np.cross(kb, kc), ka @ kc))  # ka . exp(kb t) kc = cos(t - phi)
    v = Q @ kc
    s = cs.norm_2(cs.cross(ka, v))  # |sin(tb - phi)|, accurate near 0 and pi
    c = cs.dot(ka, v)
    solutions = []
    for sign in (1.0, -1.0):
        delta = cs.atan2(sign * s, c)  # tb - phi
        cb, sb = cs.cos(delta + phi), cs.sin(delta + phi)
        ta = turn(ka, rotate(kb, cb, sb, cs.SX(kc)), v)
        # tc from what is left of Q once ta and tb are undone, so the three reproduce Q to rounding
        # even near the singularity, where ta alone is ill-conditioned
        rest = rotation(kb, cb, -sb) @ rotation(ka, cs.cos(ta), -cs.sin(ta)) @ Q
        tc = turn(kc, cs.SX(kb), rest @ kb)
        solutions.append((ta, cs.atan2(sb, cb), tc))
    return solutions, s


def into_limits(angle, lower: float, upper: float):
    """An angle in (-pi, pi] moved by 2 pi into [lower, upper] where that helps.

    Only for limits that reach beyond +-pi.
    """
    if lower < -np.pi:
        angle = cs.if_else(angle > upper, angle - 2 * np.pi, angle)
    if upper > np.pi:
        angle = cs.if_else(angle < lower, angle + 2 * np.pi, angle)
    return angle


def triad(x, y):
    """Orthonormal frame [x^, y'^, x^ x y'^] from two non-parallel vectors (Gram-Schmidt)."""
    e1 = x / cs.norm_2(x)
    y = y - cs.dot(y, e1) * e1
    e2 = y / cs.norm_2(y)
    return cs.horzcat(e1, e2, cs.cross(e1, e2))


def subproblem2(k1: np.ndarray, k2: np.ndarray, v, u):
    """Paden-Kahan sub-problem 2: exp(k1 t1) exp(k2 t2) v = u for unit axes k1, k2 through one point.

    The point is the shoulder; |u| = |v|, general axes (k1 . k2 may be any value but +-1).

    The intermediate vector c = exp(k2 t2) v = exp(-k1 t1) u keeps v's component along k2 and u's
    along k1: c = a k1 + b k2 + gamma (k1 x k2), with gamma^2 = (|v|^2 - |a k1 + b k2|^2) / |k1 x k2|^2.

    Returns:
        ([(t1, t2) for gamma >= 0, (t1, t2) for gamma <= 0], gamma^2 / |v|^2 (negative: no
        solution), |gamma| |k1 x k2| / |v| (the sine of c from the k1-k2 plane: 0 where the two
        roots merge)).
    """
    c12 = float(k1 @ k2)
    n = np.cross(k1, k2)
    n2 = float(n @ n)  # 1 - c12^2
    ku, kv = cs.dot(k1, u), cs.dot(k2, v)
    a = (ku - c12 * kv) / n2
    b = (kv - c12 * ku) / n2
    vv = cs.dot(v, v)
    gamma2 = (vv - a**2 - b**2 - 2 * a * b * c12) / n2
    gamma = cs.sqrt(cs.fmax(gamma2, 0))
    roots = []
    for sign in (1.0, -1.0):
        c = a * k1 + b * k2 + sign * gamma * n
        roots.append((turn(k1, c, u), turn(k2, v, c)))  # two sub-problem 1: c -> u about k1, v -> c about k2
    return roots, gamma2 * n2 / vv, gamma * math.sqrt(n2) / cs.sqrt(vv)


def zero_axes(chain: Chain) -> tuple[list[np.ndarray], np.ndarray]:
    """Joint axes k_i at q = 0 in the chain base frame and the tip rotation at q = 0 (3x3).

    The axes are unit, (3,) each.
    """
    movable = [j for j in chain.joints if j.movable]
    frames = chain_frames(chain)
    zero = cs.Function("zero", [frames.q], [*frames.before, frames.tip])(np.zeros(len(movable)))
    zero = [np.asarray(T) for T in zero]
    k = [zero[i][:3, :3] @ np.asarray(j.axis, dtype=float) for i, j in enumerate(movable)]
    return k, zero[-1][:3, :3]


def elbow(geometry, S: np.ndarray, E0: np.ndarray, W0: np.ndarray, a4: np.ndarray, T):
    """MC-Inverse sub-problem 1 (eqs 2-4) for a hand pose T (4x4).

    The wrist centre W, SW = W - S, d = |SW| [m], whether d is out of the elbow's reach, the elbow's interior angle
    beta [rad], and the two elbow joint angles theta4 = +-beta - phi0 [rad] (phi0: the elbow joint's angle at
    q = 0, from S, E0, W0 at q = 0 and its axis a4).
    """
    p, R = T[:3, 3], T[:3, :3]
    L2, L3 = geometry.upper_arm, geometry.forearm
    W = p - R @ geometry.tool_from_wrist  # eq (2): SW = OT - OS - WT
    sw = W - S
    d = cs.norm_2(sw)
    cos_beta = (L2**2 + L3**2 - d**2) / (2 * L2 * L3)  # eq (3)
    out_of_reach = cs.fabs(cos_beta) > 1 + REACH_SLACK
    beta = cs.acos(cs.fmin(1, cs.fmax(-1, cos_beta)))
    phi0 = np.arctan2(a4 @ np.cross(S - E0, W0 - E0), (S - E0) @ (W0 - E0))
    roots = [cs.atan2(cs.sin(sign * beta - phi0), cs.cos(sign * beta - phi0)) for sign in (1.0, -1.0)]  # eq (4)
    return W, sw, d, out_of_reach, beta, roots

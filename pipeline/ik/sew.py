"""Shoulder-elbow-wrist (SEW) angle and every inverse-kinematics solution at one SEW angle, for 7R arms that need not be S-R-S.

Elias and Wen ("Redundancy parameterization and inverse kinematics of 7-DOF revolute
manipulators", 2023; arXiv 2307.13122) generalise MC-Inverse's arm angle (its eq 1) to any 7R arm:
three points S, E, W fixed on the links, and psi the angle about the shoulder-wrist line from a
reference half-plane to the half-plane holding E. With psi fixed, the remaining 6-DOF problem is
solved with the canonical subproblems of IK-Geo (Elias and Wen, arXiv 2211.05737), in closed form
or with a 1-D search.

This module solves two families, in Elias and Wen's names (:func:`sew_chain` takes the first that
fits):

- ``R-2R-R-3R``: joints 2 and 3 meet at C, joints 5-7 at the wrist W: a humanoid arm whose
  shoulder is offset from its first axis, and every S-R-S arm (where axis 1 passes through C too;
  there the solutions are MC-Inverse's). S is the point of axis 1 nearest C, E the foot of C on
  the elbow axis. The search runs over q1: C turns about axis 1, |C - W| gives q4 (subproblem 3,
  2 roots), (q2, q3) carry C -> W onto the goal (subproblem 2, 2 roots), and the error e(q1) is
  E's distance from the SEW plane. Then (q5, q6) by subproblem 2 and q7 by subproblem 1.
- ``3R-R-2R-R`` (``IK_3R_R_2R_R``): joints 1-3 meet at the shoulder S, joints 5 and 6 at C, joint
  7 offset from C: the Franka Panda. E is the foot of S on the elbow axis, W the foot of C on
  axis 7. The search runs over the angle theta of the upper arm S-E from SW in the SEW
  half-plane: subproblem 3 gives q7 (2 roots), subproblem 2 gives (q5, q6) (2 roots), and q4
  exists where the elbow axis's component of a vector is right (subproblem 1's condition): the
  error e(theta). Then q4 by subproblem 1, (q1, q2) by subproblem 2 and q3 by subproblem 1.

Either error's zeros are bracketed by a sign change between neighbouring samples of a fine grid
over the whole range (as IK-Geo's ``search_1D``), and beyond it: the ends of each branch's domain
(where two branches meet and e behaves as a square root; a planar pose such as the Panda's
``ready`` has its solutions exactly there) and the turning points of e between samples (two roots
closer than the samples, or a double root) are located and sampled too. Every root is refined by
bisection, so every root in the range is found, not the one nearest a seed; each solution is then
polished by Newton on the 7 equations.

All arrays are numpy, every goal of a path searched at once (:func:`solve_many`); axes and points
are those of the chain at q = 0 in its base frame (product of exponentials).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from dualarm.errors import NotSRSError
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import Chain, Robot
from dualarm.model.srs import INTERSECTION_TOLERANCE_M, _axis_lines, _meeting_point

#: Samples of the 1-D search over its range ([0, pi] or [-pi, pi]).
SEARCH_SAMPLES = 2000
#: Bisection steps refining each bracketed root (2000 samples: pi / 2000 / 2^60 is below rounding).
BISECTION_STEPS = 60
#: Newton steps polishing each solution on the 7 equations (pose and SEW angle).
POLISH_STEPS = 3
#: Central-difference step of the polishing Jacobian [rad].
DIFF_RAD = 1e-7
#: The golden section's ratio, (sqrt 5 - 1) / 2.
GOLDEN = (5**0.5 - 1) / 2
#: Goals searched at once (memory: samples x this x a few 3x3 matrices).
CHUNK_GOALS = 64
#: A turning point of the search's error, or the end of a branch's domain, this close to zero is a root [m].
TOUCHING_M = 1e-6
#: A candidate reproducing the pose (position [m], rotation) or the SEW angle [rad] worse than this is dropped.
RESIDUAL_TOLERANCE = 1e-9


class NotSewError(NotSRSError):
    """A chain is of no family the SEW solver handles (one line naming the chain and the joints)."""


# ----------------------------------------------------------------------------- subproblems (numpy)


def _rot(k: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """exp([k] theta) for unit axes k (..., 3) and angles theta (...,) -> (..., 3, 3) (Rodrigues)."""
    k = np.broadcast_to(k, np.shape(theta) + (3,))
    x, y, z = k[..., 0], k[..., 1], k[..., 2]
    zero = np.zeros_like(x)
    K = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(k.shape + (3,))
    s, c = np.sin(theta)[..., None, None], np.cos(theta)[..., None, None]
    return c * np.eye(3) + s * K + (1 - c) * (k[..., :, None] * k[..., None, :])  # K^2 = k k^T - I


def _turn(k: np.ndarray, theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """exp([k] theta) v for unit axes k (..., 3), angles theta (...,) and vectors v (..., 3), without forming the matrices (Rodrigues)."""
    s, c = np.sin(theta)[..., None], np.cos(theta)[..., None]
    return c * v + s * _cross(k, v) + (1 - c) * _dot(k, v)[..., None] * k


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product a x b of vectors (..., 3), broadcast (np.cross's axis handling costs more than the product on the search's small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack(np.broadcast_arrays(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), -1)


def sp1(p: np.ndarray, q: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Subproblem 1: the angle about unit axis k turning p towards q (exact when their k-components and norms agree)."""
    return np.arctan2(_dot(k, _cross(p, q)), _dot(p, q) - _dot(k, p) * _dot(k, q))


def sp2(p1: np.ndarray, p2: np.ndarray, k1: np.ndarray, k2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Subproblem 2: rot(k1, t1) p1 = rot(k2, t2) p2 for non-parallel unit axes; (t1, t2), each (..., 2), NaN where there is no exact solution.

    The common vector c = a k1 + b k2 + g (k1 x k2) keeps p1's component along k1 and p2's along k2,
    with g^2 from |c| = |p1|.
    """
    c12 = _dot(k1, k2)
    n = _cross(k1, k2)
    n2 = _dot(n, n)
    u, v = _dot(k1, p1), _dot(k2, p2)
    a = (u - c12 * v) / n2
    b = (v - c12 * u) / n2
    g2 = (_dot(p1, p1) - a**2 - b**2 - 2 * a * b * c12) / n2
    g = np.sqrt(np.where(g2 >= 0, g2, np.nan))
    t1, t2 = [], []
    for sign in (1.0, -1.0):
        c = a[..., None] * k1 + b[..., None] * k2 + (sign * g)[..., None] * n
        t1.append(sp1(p1, c, k1))
        t2.append(sp1(p2, c, k2))
    return np.stack(t1, -1), np.stack(t2, -1)


def sp3(p1: np.ndarray, p2: np.ndarray, k: np.ndarray, d: float | np.ndarray) -> np.ndarray:
    """Subproblem 3: |rot(k, t) p1 - p2| = d; t (..., 2), NaN where there is no exact solution.

    p2 . rot(k, t) p1 = A cos t + B sin t + (k.p1)(k.p2) = (|p1|^2 + |p2|^2 - d^2) / 2.
    """
    A = _dot(p2, p1 - _dot(k, p1)[..., None] * k)
    B = _dot(p2, _cross(k, p1))
    rhs = (_dot(p1, p1) + _dot(p2, p2) - d**2) / 2 - _dot(k, p1) * _dot(k, p2)
    r = np.hypot(A, B)
    ratio = np.where(np.abs(rhs) <= r, rhs / np.where(r > 0, r, 1.0), np.nan)
    phi, delta = np.arctan2(B, A), np.arccos(ratio)
    return np.stack([phi + delta, phi - delta], -1)


# ----------------------------------------------------------------------------- the SEW angle


@dataclass(frozen=True)
class SewAngle:
    """The SEW angle: psi about the shoulder-wrist line e_SW, from the reference direction e_x(e_SW) to the elbow's direction from that line.

    Conventional (``singular`` None): e_x is the reference direction ``reference`` made normal to
    e_SW; undefined where e_SW is parallel to it (a whole line through S). Stereographic
    (``singular`` e_t): e_x is normal to (e_SW - e_t) x e_r and to e_SW, undefined only on the
    half-line from S along e_t, which can be put out of reach (Elias and Wen, section 3).

    Attributes:
        reference: e_r, unit (3,) in the chain base frame.
        singular: e_t, unit (3,), or None for the conventional angle.
    """

    reference: tuple[float, float, float] = (0.0, 0.0, 1.0)
    singular: tuple[float, float, float] | None = None

    @classmethod
    def stereographic(cls, vertical: "np.ndarray | tuple[float, float, float]") -> "SewAngle":
        """The stereographic SEW angle with e_r the unit ``vertical`` and the singular half-line from the shoulder along -e_r (into the base, out of reach)."""
        v = np.asarray(vertical, dtype=float) / np.linalg.norm(vertical)
        return cls(reference=(float(v[0]), float(v[1]), float(v[2])), singular=(float(-v[0]), float(-v[1]), float(-v[2])))

    def reference_direction(self, e_sw: np.ndarray) -> np.ndarray:
        """e_x: the unit direction of psi = 0, normal to the unit shoulder-wrist directions ``e_sw`` (..., 3)."""
        r = np.asarray(self.reference, dtype=float)
        if self.singular is None:
            x = r - _dot(e_sw, r)[..., None] * e_sw
        else:
            x = np.cross(np.cross(e_sw - np.asarray(self.singular, dtype=float), r), e_sw)
        return x / np.linalg.norm(x, axis=-1, keepdims=True)

    def angle(self, S: np.ndarray, E: np.ndarray, W: np.ndarray) -> np.ndarray:
        """The angle psi [rad] in (-pi, pi] of points S, E, W (..., 3): right-handed about S -> W."""
        e_sw = (W - S) / np.linalg.norm(W - S, axis=-1, keepdims=True)
        x = self.reference_direction(e_sw)
        return np.arctan2(_dot(e_sw, np.cross(x, E - S)), _dot(x, E - S))


# ----------------------------------------------------------------------------- the arm

#: The families solved here, in Elias and Wen's names: which consecutive axes meet.
UPPER_ARM_FAMILY = "3R-R-2R-R"
FIRST_JOINT_FAMILY = "R-2R-R-3R"


@dataclass(frozen=True)
class SewChain:
    """A 7R arm of one of the two families, as products of exponentials at q = 0 in its chain base frame.

    Attributes:
        chain: the chain.
        family: ``"3R-R-2R-R"`` (axes 1-3 meet at S, axes 5 and 6 at C: the Franka Panda) or
            ``"R-2R-R-3R"`` (axes 2 and 3 meet at C, axes 5-7 at W: a humanoid arm whose shoulder is
            offset from its first axis, and every S-R-S arm).
        axes: h1..h7, unit (7, 3).
        axis_points: a point of each axis (7, 3) [m].
        shoulder: S, fixed: where axes 1-3 meet (3R-R-2R-R), or the foot of C on axis 1 [m].
        elbow: E at q = 0, fixed in link 3: the foot of S (3R-R-2R-R) or of C on axis 4 [m].
        crossing: C at q = 0: where axes 5 and 6 meet, fixed in link 4 (3R-R-2R-R), or where axes
            2 and 3 meet, fixed in link 1 [m].
        wrist: W at q = 0, fixed in link 6 and on axis 7: the foot of C on axis 7 (3R-R-2R-R), or
            where axes 5-7 meet [m].
        tool: the tip's position from W at q = 0 [m] (3,).
        tool_rotation: the tip's rotation at q = 0 (3, 3).
    """

    chain: Chain
    family: str
    axes: np.ndarray
    axis_points: np.ndarray
    shoulder: np.ndarray
    elbow: np.ndarray
    crossing: np.ndarray
    wrist: np.ndarray
    tool: np.ndarray
    tool_rotation: np.ndarray

    def transforms(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """R_0i (N, 7, 3, 3) and t_0i (N, 7, 3) [m] of T_0i = exp([xi_1] q_1) ... exp([xi_i] q_i) at configurations Q (N, 7): a point fixed in link i at x (q = 0) is at R_0i x + t_0i."""
        R, t = np.empty(Q.shape + (3, 3)), np.empty(Q.shape + (3,))
        R_acc, t_acc = np.broadcast_to(np.eye(3), Q.shape[:1] + (3, 3)), np.zeros(Q.shape[:1] + (3,))
        for i, (h, p) in enumerate(zip(self.axes, self.axis_points)):
            R_i = _rot(h, Q[:, i])
            t_acc = t_acc + _mv(R_acc, p - _mv(R_i, p))  # exp([xi] q) x = R x + (I - R) p for the line through p
            R_acc = R_acc @ R_i
            R[:, i], t[:, i] = R_acc, t_acc
        return R, t

    def points_and_poses(self, Q: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """(S, E, W), each (N, 3) [m], and the tip poses (N, 4, 4) at configurations Q (N, 7), from one product of exponentials."""
        R, t = self.transforms(Q)
        S = np.broadcast_to(self.shoulder, (len(Q), 3))
        E = _mv(R[:, 2], self.elbow) + t[:, 2]
        W = _mv(R[:, 5], self.wrist) + t[:, 5]
        T = np.tile(np.eye(4), (len(Q), 1, 1))
        T[:, :3, :3] = R[:, 6] @ self.tool_rotation
        T[:, :3, 3] = _mv(R[:, 6], self.wrist + self.tool) + t[:, 6]
        return (S, E, W), T

    def points(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """S, E, W at configurations Q (N, 7), each (N, 3) [m]."""
        return self.points_and_poses(Q)[0]

    def poses(self, Q: np.ndarray) -> np.ndarray:
        """Tip poses (N, 4, 4) at configurations Q (N, 7), by products of exponentials."""
        return self.points_and_poses(Q)[1]


def _foot(point: np.ndarray, line: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    p, d = line
    return p + d * np.dot(point - p, d)


@functools.lru_cache(maxsize=None)
def sew_chain(chain: Chain) -> SewChain:
    """The geometry of ``chain`` in the first family it belongs to, R-2R-R-3R then 3R-R-2R-R (once per chain).

    Raises:
        NotSewError: one line naming the chain and what it lacks: 7 revolute joints, or the
            meeting axes of either family (with how far they miss).
    """
    movable = [j for j in chain.joints if j.movable]
    names = [j.name for j in movable]
    if len(movable) != 7 or any(j.type == "prismatic" for j in movable):
        raise NotSewError(f"chain '{chain.name}' has {len(movable)} movable joints; the SEW solver needs 7 revolute joints", chain.name)
    check = _axis_lines(chain, np.random.default_rng(7).uniform(-0.8, 0.8, 7))  # no coincidence of the zero pose
    miss: dict[tuple[int, ...], float] = {idx: _meeting_point([check[i] for i in idx])[1] for idx in ((1, 2), (4, 5, 6), (0, 1, 2), (4, 5))}
    lines = _axis_lines(chain, np.zeros(7))
    if max(miss[(1, 2)], miss[(4, 5, 6)]) <= INTERSECTION_TOLERANCE_M:
        family, C = FIRST_JOINT_FAMILY, _meeting_point(lines[1:3])[0]
        S, W = _foot(C, lines[0]), _meeting_point(lines[4:7])[0]
        E = _foot(C, lines[3])
    elif max(miss[(0, 1, 2)], miss[(4, 5)]) <= INTERSECTION_TOLERANCE_M:
        family, S, C = UPPER_ARM_FAMILY, _meeting_point(lines[0:3])[0], _meeting_point(lines[4:6])[0]
        E, W = _foot(S, lines[3]), _foot(C, lines[6])
    else:

        def axes(idx: tuple[int, ...]) -> str:
            return f"{', '.join(names[i] for i in idx)} (miss {miss[idx]:.3g} m)"

        raise NotSewError(
            f"chain '{chain.name}' is of no family the SEW solver handles: R-2R-R-3R needs the axes of {axes((1, 2))} and of {axes((4, 5, 6))} "
            f"to meet, 3R-R-2R-R (the Franka Panda) those of {axes((0, 1, 2))} and of {axes((4, 5))}",
            chain.name,
        )
    tip = ChainKinematics.of(chain).pose(np.zeros(7))
    return SewChain(
        chain=chain,
        family=family,
        axes=np.array([d for _, d in lines]),
        axis_points=np.array([p for p, _ in lines]),
        shoulder=S,
        elbow=E,
        crossing=C,
        wrist=W,
        tool=tip[:3, 3] - W,
        tool_rotation=tip[:3, :3],
    )


# ----------------------------------------------------------------------------- inverse kinematics


@dataclass(frozen=True)
class SewSolutions:
    """Every solution of one pose at one SEW angle.

    Attributes:
        q: (M, 7) joint angles [rad], wrapped into (-pi, pi].
        search_rad: (M,) the search variable at which each was found [rad]: the upper arm's angle
            from S -> W (3R-R-2R-R) or q1 (R-2R-R-3R).
        branch: (M,) which of the 8 branches (the three two-root subproblems) it is, 0-7.
        residual: (M,) the largest error of the pose (position [m], rotation: the vector part of
            R_goal^T R) and the SEW angle [rad] each reproduces, by products of exponentials.
    """

    q: np.ndarray
    search_rad: np.ndarray
    branch: np.ndarray
    residual: np.ndarray


def _equations(arm: SewChain, sew: SewAngle, T: np.ndarray, psi: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """What a solution must zero, (M, 7), for goals T (M, 4, 4) and psi (M,): the position error [m], the rotation error (the vector part of R_goal^T R) and the SEW angle's error [rad]."""
    points, got = arm.points_and_poses(Q)
    D = np.einsum("nji,njk->nik", T[:, :3, :3], got[:, :3, :3])
    rotation = 0.5 * np.stack([D[:, 2, 1] - D[:, 1, 2], D[:, 0, 2] - D[:, 2, 0], D[:, 1, 0] - D[:, 0, 1]], -1)
    angle = np.angle(np.exp(1j * (sew.angle(*points) - psi)))
    return np.concatenate([got[:, :3, 3] - T[:, :3, 3], rotation, angle[:, None]], axis=1)


def _mv(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Matrices (..., 3, 3) times vectors (..., 3)."""
    return np.einsum("...ij,...j->...i", M, v)


def _t(M: np.ndarray) -> np.ndarray:
    """Transposes of matrices (..., 3, 3)."""
    return np.swapaxes(M, -1, -2)


class _Search:
    """A family's 1-D search for N goals at once: along the search variable x over ``span``, an error per branch whose zeros are the solutions (module docstring)."""

    span: tuple[float, float]

    def __init__(self, arm: SewChain, sew: SewAngle, T: np.ndarray, psi: np.ndarray):
        self.arm = arm
        self.R07 = np.einsum("nij,kj->nik", T[:, :3, :3], arm.tool_rotation)  # R_0T R_T0^T
        self.W = T[:, :3, 3] - _mv(self.R07, arm.tool)
        self.e_sw = (self.W - arm.shoulder) / np.linalg.norm(self.W - arm.shoulder, axis=1, keepdims=True)
        e_ce = _mv(_rot(self.e_sw, psi), sew.reference_direction(self.e_sw))
        self.n = _cross(self.e_sw, e_ce)  # normal of the half-plane holding the elbow

    def __call__(self, pose: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For goals ``pose`` (M,) (indices) at ``x`` (M,): the error e (M, 4) and the joints found on the way (M, 4, k)."""
        raise NotImplementedError

    def on_branch(self, pose: np.ndarray, x: np.ndarray, branch: np.ndarray) -> np.ndarray:
        return self(pose, x)[0][np.arange(len(x)), branch]

    def configurations(self, goal: np.ndarray, x: np.ndarray, branch: np.ndarray) -> np.ndarray:
        """The joints (2M, 7) at roots x (M,) of e on ``branch`` (M,): the last subproblem's first root for every root, then its second."""
        raise NotImplementedError


class _UpperArmSearch(_Search):
    """3R-R-2R-R: x is the upper arm's angle from S -> W in the SEW half-plane, over [0, pi]. Subproblem 3 gives q7 (2 roots), subproblem 2 (q5, q6) (2 roots); e is the error of subproblem 1's condition for q4 (the elbow axis's component)."""

    span = (0.0, np.pi)

    def __call__(self, pose: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        arm, h = self.arm, self.arm.axes
        P4, P5, P7 = arm.elbow - arm.shoulder, arm.crossing - arm.elbow, arm.wrist - arm.crossing
        p14 = self._upper_arm(pose, x)
        R07 = self.R07[pose]
        d = _mv(_t(R07), self.W[pose] - arm.shoulder - p14)  # R07^T (S -> W - S -> E)
        local = _mv(_t(R07), p14)
        t7 = sp3(P7, d, -h[6], float(np.linalg.norm(P5)))  # |R67^T P7 - d| = |P5|
        errors, q567 = [], []
        for i7 in range(2):
            local7 = _turn(h[6], t7[:, i7], local)
            t5, t6 = sp2(P5, _turn(h[6], t7[:, i7], d) - P7, -h[4], h[5])
            for i56 in range(2):
                errors.append(h[3] @ P4 - _turn(h[4], t5[:, i56], _turn(h[5], t6[:, i56], local7)) @ h[3])
                q567.append(np.stack([t5[:, i56], t6[:, i56], t7[:, i7]], -1))
        return np.stack(errors, -1), np.stack(q567, 1)

    def _upper_arm(self, pose: np.ndarray, x: np.ndarray) -> np.ndarray:
        """S -> E (M, 3) [m] at angle x from S -> W in the SEW half-plane."""
        return _turn(self.n[pose], x, self.e_sw[pose]) * np.linalg.norm(self.arm.elbow - self.arm.shoulder)

    def configurations(self, goal: np.ndarray, x: np.ndarray, branch: np.ndarray) -> np.ndarray:
        arm, h = self.arm, self.arm.axes
        q5, q6, q7 = self(goal, x)[1][np.arange(len(x)), branch].T
        R47 = _rot(h[4], q5) @ _rot(h[5], q6) @ _rot(h[6], q7)
        q4 = sp1(arm.elbow - arm.shoulder, _mv(R47, _mv(_t(self.R07[goal]), self._upper_arm(goal, x))), -h[3])
        R03 = self.R07[goal] @ _t(R47) @ _t(_rot(h[3], q4))
        t2, t1 = sp2(h[2], _mv(R03, h[2]), h[1], -h[0])
        rows = []
        for i12 in range(2):
            q1, q2 = t1[:, i12], t2[:, i12]
            q3 = sp1(h[1], _mv(_t(_rot(h[0], q1) @ _rot(h[1], q2)) @ R03, h[1]), h[2])
            rows.append(np.stack([q1, q2, q3, q4, q5, q6, q7], -1))
        return np.concatenate(rows)


class _FirstJointSearch(_Search):
    """R-2R-R-3R: x is q1, over [-pi, pi]. C turns with q1 about axis 1; |C - W| fixes q4 (subproblem 3, 2 roots); (q2, q3) turn C -> W onto the goal's (subproblem 2, 2 roots); e is E's distance from the SEW plane (zero on both of its half-planes: the one beyond S -> W fails the SEW-angle residual). Then (q5, q6) by subproblem 2 (2 roots) and q7 by subproblem 1."""

    span = (-np.pi, np.pi)

    def __call__(self, pose: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        arm, h, p4 = self.arm, self.arm.axes, self.arm.axis_points[3]
        C = arm.shoulder + _turn(h[0], x, arm.crossing - arm.shoulder)
        u = _turn(h[0], -x, self.W[pose] - C)  # R2 R3 (C -> W after q4) must be this
        t4 = sp3(arm.wrist - p4, arm.crossing - p4, h[3], np.linalg.norm(self.W[pose] - C, axis=1))
        errors, q1234 = [], []
        for i4 in range(2):
            v = p4 + _turn(h[3], t4[:, i4], arm.wrist - p4) - arm.crossing  # C -> W at q4 alone
            t2, t3 = sp2(u, v, -h[1], h[2])
            for i23 in range(2):
                E = C + _turn(h[0], x, _turn(h[1], t2[:, i23], _turn(h[2], t3[:, i23], arm.elbow - arm.crossing)))
                errors.append(_dot(self.n[pose], E - arm.shoulder))
                q1234.append(np.stack([x, t2[:, i23], t3[:, i23], t4[:, i4]], -1))
        return np.stack(errors, -1), np.stack(q1234, 1)

    def configurations(self, goal: np.ndarray, x: np.ndarray, branch: np.ndarray) -> np.ndarray:
        h = self.arm.axes
        q1234 = self(goal, x)[1][np.arange(len(x)), branch]
        R04 = _rot(h[0], q1234[:, 0]) @ _rot(h[1], q1234[:, 1]) @ _rot(h[2], q1234[:, 2]) @ _rot(h[3], q1234[:, 3])
        R47 = _t(R04) @ self.R07[goal]
        t5, t6 = sp2(_mv(R47, h[6]), h[6], -h[4], h[5])
        rows = []
        for i56 in range(2):
            R7 = _t(_rot(h[4], t5[:, i56]) @ _rot(h[5], t6[:, i56])) @ R47
            q7 = sp1(h[5], _mv(R7, h[5]), h[6])
            rows.append(np.concatenate([q1234, np.stack([t5[:, i56], t6[:, i56], q7], -1)], 1))
        return np.concatenate(rows)


SEARCHES: dict[str, type[_Search]] = {UPPER_ARM_FAMILY: _UpperArmSearch, FIRST_JOINT_FAMILY: _FirstJointSearch}


def _brackets(search: _Search, N: int, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(goal, branch, lo, hi) of every bracketed root of e on the grid of ``samples`` values of x over the search's span, with the ends of each branch's domain and its turning points towards zero sampled too (module docstring).

    The grid is evaluated :data:`CHUNK_GOALS` goals at a time; the ends and turning points of all
    goals are then refined together, one vectorised step at a time.
    """
    grid = np.linspace(*search.span, samples)
    found: tuple[list[np.ndarray], ...] = ([], [], [], [])  # goals, branches, lows, highs
    edges: tuple[list[np.ndarray], ...] = ([], [], [], [], [])  # goals, branches, grid index before the end, whether that sample is inside, e at the sample inside
    turns: tuple[list[np.ndarray], ...] = ([], [], [], [])  # goals, branches, grid index before the turn, sign of e there

    def add(to, *values):
        for column, value in zip(to, values):
            column.append(value)

    for first in range(0, N, CHUNK_GOALS):
        block = np.arange(first, min(N, first + CHUNK_GOALS))
        pose = np.repeat(block, samples)
        e = search(pose, np.tile(grid, len(block)))[0].reshape(len(block), samples, 4)
        finite = np.isfinite(e)
        # sign changes between neighbours
        a, c = e[:, :-1], e[:, 1:]
        g, k, b = np.nonzero(finite[:, :-1] & finite[:, 1:] & ((a == 0) | (np.sign(a) != np.sign(c))))
        add(found, block[g], b, grid[k], grid[k + 1])
        # the end of a branch's domain between two samples
        g, k, b = np.nonzero(finite[:, :-1] != finite[:, 1:])
        add(edges, block[g], b, k, finite[g, k, b], np.where(finite[g, k, b], e[g, k, b], e[g, k + 1, b]))
        # two roots closer than the samples: a branch turning back towards zero between samples of one sign
        before, here, after = e[:, :-2], e[:, 1:-1], e[:, 2:]
        same = (np.sign(before) == np.sign(here)) & (np.sign(here) == np.sign(after))
        g, k, b = np.nonzero(finite[:, :-2] & finite[:, 1:-1] & finite[:, 2:] & same & (np.abs(here) <= np.minimum(np.abs(before), np.abs(after))))
        add(turns, block[g], b, k, np.sign(e[g, k + 1, b]))
    # the ends, by bisection on where e is defined: a root between an end and the first sample
    # inside has no sign change on the grid
    g, b, k, lo_inside, e_inside = (np.concatenate(column) for column in edges)
    lo, hi = grid[k], grid[k + 1]
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        with_lo = np.isfinite(search.on_branch(g, mid, b)) == lo_inside
        lo, hi = np.where(with_lo, mid, lo), np.where(with_lo, hi, mid)
    edge, inside = np.where(lo_inside, lo, hi), np.where(lo_inside, grid[k], grid[k + 1])
    e_edge = search.on_branch(g, edge, b)
    crossed = np.isfinite(e_edge) & (np.sign(e_edge) != np.sign(e_inside))
    add(found, g[crossed], b[crossed], np.minimum(edge, inside)[crossed], np.maximum(edge, inside)[crossed])
    # a root at the end itself (two branches meeting there with e = 0, as at a planar home pose):
    # e behaves as sqrt near an end, so in doubles it gets only to ~1e-7 of it; kept for the polish
    at_end = ~crossed & (np.abs(e_edge) <= TOUCHING_M)
    add(found, g[at_end], b[at_end], edge[at_end], edge[at_end])
    # the turning points (golden section) split the pairs
    g, b, k, sign = (np.concatenate(column) for column in turns)
    lo, hi, toward = grid[k], grid[k + 2], -sign
    for _ in range(BISECTION_STEPS):
        m1, m2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
        f1 = np.nan_to_num(toward * search.on_branch(g, m1, b), nan=-np.inf)
        f2 = np.nan_to_num(toward * search.on_branch(g, m2, b), nan=-np.inf)
        higher = f2 >= f1
        lo, hi = np.where(higher, m1, lo), np.where(higher, hi, m2)
    turning = 0.5 * (lo + hi)
    e_turning = toward * search.on_branch(g, turning, b)
    crossed = e_turning > 0
    add(found, g[crossed], b[crossed], grid[k][crossed], turning[crossed])
    add(found, g[crossed], b[crossed], turning[crossed], grid[k + 2][crossed])
    # a double root (e touching zero, as at a planar configuration, where two solutions coincide)
    # may miss zero by rounding either way: kept, for the polish to settle
    touching = ~crossed & (np.abs(e_turning) <= TOUCHING_M)
    add(found, g[touching], b[touching], turning[touching], turning[touching])
    goal, branch, lo, hi = (np.concatenate(column) for column in found)
    return goal, branch, lo, hi


def solve_many(arm: SewChain, T: np.ndarray, psi: np.ndarray, sew: SewAngle = SewAngle(), samples: int = SEARCH_SAMPLES) -> list[SewSolutions]:
    """Every solution of each hand pose ``T`` (N, 4, 4, chain base frame) at its SEW angle ``psi`` (N,) [rad] (module docstring), limits not applied; one :class:`SewSolutions` per pose."""
    T = np.asarray(T, dtype=float).reshape(-1, 4, 4)
    psi = np.broadcast_to(np.asarray(psi, dtype=float), len(T))
    search = SEARCHES[arm.family](arm, sew, T, psi)
    goal, branch, lo, hi = _brackets(search, len(T), samples)
    goal, branch = goal.astype(int), branch.astype(int)
    e_lo = search.on_branch(goal, lo, branch)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        e_mid = search.on_branch(goal, mid, branch)
        with_lo = np.isfinite(e_mid) & (np.sign(e_mid) == np.sign(e_lo))
        with_hi = np.isfinite(e_mid) & ~with_lo
        lo, e_lo, hi = np.where(with_lo, mid, lo), np.where(with_lo, e_mid, e_lo), np.where(with_hi, mid, hi)
    x = 0.5 * (lo + hi)
    Q = search.configurations(goal, x, branch)
    goal, x, branch = np.tile(goal, 2), np.tile(x, 2), np.concatenate([2 * branch, 2 * branch + 1])
    ok = np.all(np.isfinite(Q), axis=1)
    Q, goal, x, branch = Q[ok], goal[ok], x[ok], branch[ok]
    T_goal, psi_goal = T[goal], psi[goal]
    offsets = DIFF_RAD * np.concatenate([np.eye(7), -np.eye(7)])  # central differences, all 14 in one call
    for _ in range(POLISH_STEPS):  # roots near a branch's end or a double root are found to ~1e-8 rad only
        F = _equations(arm, sew, T_goal, psi_goal, Q)
        around = _equations(arm, sew, np.repeat(T_goal, 14, axis=0), np.repeat(psi_goal, 14), (Q[:, None] + offsets).reshape(-1, 7)).reshape(len(Q), 14, 7)
        J = np.swapaxes(around[:, :7] - around[:, 7:], 1, 2) / (2 * DIFF_RAD)
        step = (np.linalg.pinv(J) @ F[..., None])[..., 0]  # least squares: J is singular at a double root
        better = np.abs(_equations(arm, sew, T_goal, psi_goal, Q - step)).max(axis=1) < np.abs(F).max(axis=1)
        Q = np.where(better[:, None], Q - step, Q)
    Q = np.angle(np.exp(1j * Q))  # into (-pi, pi]
    residual = np.abs(_equations(arm, sew, T_goal, psi_goal, Q)).max(axis=1) if len(Q) else np.zeros(0)
    keep = residual <= RESIDUAL_TOLERANCE
    out = []
    for n in range(len(T)):
        mine = keep & (goal == n)
        q = Q[mine]
        unique = np.unique(np.round(q, 9), axis=0, return_index=True)[1] if len(q) else np.zeros(0, dtype=int)  # a root bracketed twice (at a sample) once
        unique = np.sort(unique)
        out.append(SewSolutions(q[unique], x[mine][unique], branch[mine][unique], residual[mine][unique]))
    return out


def solve(arm: SewChain, T: np.ndarray, psi: float, sew: SewAngle = SewAngle(), samples: int = SEARCH_SAMPLES) -> SewSolutions:
    """Every solution of the hand pose ``T`` (4, 4, chain base frame) at SEW angle ``psi`` [rad] (module docstring), limits not applied."""
    return solve_many(arm, T[None], np.array([psi]), sew, samples)[0]


def into_limits(Q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Each angle of Q (M, 7) moved by a multiple of 2 pi into [lower, upper] where one lands there (limits that reach past +-pi)."""
    shifted = Q + 2 * np.pi * np.ceil((lower - Q) / (2 * np.pi))  # the smallest equivalent angle >= lower
    return np.where(shifted <= upper, shifted, Q)


def candidate_table(robot: Robot, chain: Chain, T: np.ndarray, psi: float, sew: SewAngle) -> list[dict]:
    """``dualarm ik sew``'s rows: every solution of the pose ``T`` (chain base frame) at SEW angle ``psi``, each with ``q`` [rad] (moved into the joint limits where an equivalent angle is), ``valid``, ``reason`` ("valid" or the first joint outside its limits), the position [m] and orientation [rad] errors of the chain's forward kinematics, its SEW angle [rad], the search variable where it was found (``search_rad``: the upper arm's angle from S -> W, or q1) and its branch.

    Raises:
        NotSewError: the chain is not of the family solved here (one line).
    """
    from dualarm.ik.orientation import orientation_errors

    arm = sew_chain(chain)
    found = solve(arm, T, psi, sew)
    lower, upper = robot.lower_upper(chain.joint_names)
    Q = into_limits(found.q, lower, upper)
    got = ChainKinematics.of(chain).poses(Q) if len(Q) else np.zeros((0, 4, 4))
    angles = sew.angle(*arm.points(Q)) if len(Q) else np.zeros(0)
    rotation = orientation_errors(T[:3, :3], got[:, :3, :3]) if len(Q) else np.zeros(0)
    rows = []
    for i, q in enumerate(Q):
        outside = [j for j in range(7) if not lower[j] <= q[j] <= upper[j]]
        reason = "valid" if not outside else f"outside limits: {chain.joint_names[outside[0]]} at {q[outside[0]]:.4f} [{lower[outside[0]]:.4f}, {upper[outside[0]]:.4f}]"
        rows.append(
            {
                "q": q.tolist(),
                "valid": not outside,
                "reason": reason,
                "position_error_m": float(np.linalg.norm(got[i, :3, 3] - T[:3, 3])),
                "orientation_error_rad": float(rotation[i]),
                "sew_angle_rad": float(angles[i]),
                "search_rad": float(found.search_rad[i]),
                "branch": int(found.branch[i]),
            }
        )
    return rows

"""Shoulder-elbow-wrist (SEW) angle and every inverse-kinematics solution at one SEW angle, for 7R arms that are not S-R-S.

Elias and Wen ("Redundancy parameterization and inverse kinematics of 7-DOF revolute
manipulators", 2023; arXiv 2307.13122) generalise MC-Inverse's arm angle (its eq 1) to any 7R arm:
three points S, E, W fixed on the links, and psi the angle about the shoulder-wrist line from a
reference half-plane to the half-plane holding E. With psi fixed, the remaining 6-DOF problem is
solved with the canonical subproblems of IK-Geo (Elias and Wen, arXiv 2211.05737), in closed form
or with a 1-D search.

This module solves the family of the Franka Panda, "3R-R-2R-R" (Elias and Wen's
``IK_3R_R_2R_R``): joints 1-3 meet at the shoulder S, joints 5 and 6 intersect at C, joint 4 is
the elbow, joint 7 is offset from C (on an S-R-S arm it passes through C: that arm is MC-Inverse's).
The points are E, the foot of S on the elbow axis, and W, the foot of C on axis 7. For each angle
theta of the upper arm S-E from SW in the SEW half-plane, subproblem 3 gives q7 (2 roots),
subproblem 2 gives (q5, q6) (2 roots), and q4 exists where the elbow axis's component of a vector
is right (subproblem 1's condition): an error e(theta) per branch. Its zeros are bracketed by a
sign change between neighbouring samples of a fine grid over the whole [0, pi] (as IK-Geo's
``search_1D``), and beyond it: the ends of each branch's domain (where two branches meet and e
behaves as a square root; a planar pose such as the Panda's ``ready`` has its solutions exactly
there) and the turning points of e between samples (two roots closer than the samples, or a double
root) are located and sampled too. Every root is refined by bisection, so every root in the range
is found, not the one nearest a seed. q4 follows from subproblem 1, (q1, q2) from subproblem 2 and
q3 from subproblem 1; each solution is then polished by Newton on the 7 equations.

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

#: Samples of the 1-D search over the upper arm's angle in [0, pi].
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
    """A chain is not of the family the SEW solver handles (one line naming the chain and the joints)."""


# ----------------------------------------------------------------------------- subproblems (numpy)


def _rot(k: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """exp([k] theta) for unit axes k (..., 3) and angles theta (...,) -> (..., 3, 3) (Rodrigues)."""
    k = np.broadcast_to(k, np.shape(theta) + (3,))
    K = np.zeros(k.shape + (3,))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    s, c = np.sin(theta)[..., None, None], np.cos(theta)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def sp1(p: np.ndarray, q: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Subproblem 1: the angle about unit axis k turning p towards q (exact when their k-components and norms agree)."""
    return np.arctan2(_dot(k, np.cross(p, q)), _dot(p, q) - _dot(k, p) * _dot(k, q))


def sp2(p1: np.ndarray, p2: np.ndarray, k1: np.ndarray, k2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Subproblem 2: rot(k1, t1) p1 = rot(k2, t2) p2 for non-parallel unit axes; (t1, t2), each (..., 2), NaN where there is no exact solution.

    The common vector c = a k1 + b k2 + g (k1 x k2) keeps p1's component along k1 and p2's along k2,
    with g^2 from |c| = |p1|.
    """
    c12 = _dot(k1, k2)
    n = np.cross(k1, k2)
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
    B = _dot(p2, np.cross(k, p1))
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


@dataclass(frozen=True)
class SewChain:
    """A 3R-R-2R-R arm as products of exponentials at q = 0 in its chain base frame.

    Attributes:
        chain: the chain.
        axes: h1..h7, unit (7, 3).
        shoulder: S, where axes 1-3 meet [m].
        elbow: E at q = 0, the foot of S on axis 4 [m].
        crossing: C, where axes 5 and 6 meet [m].
        wrist: W at q = 0, the foot of C on axis 7 [m].
        tool: the tip's position from W at q = 0 [m] (3,).
        tool_rotation: the tip's rotation at q = 0 (3, 3).
    """

    chain: Chain
    axes: np.ndarray
    shoulder: np.ndarray
    elbow: np.ndarray
    crossing: np.ndarray
    wrist: np.ndarray
    tool: np.ndarray
    tool_rotation: np.ndarray

    @property
    def p4(self) -> np.ndarray:
        """S -> E at q = 0."""
        return self.elbow - self.shoulder

    @property
    def p5(self) -> np.ndarray:
        """E -> C at q = 0."""
        return self.crossing - self.elbow

    @property
    def p7(self) -> np.ndarray:
        """C -> W at q = 0."""
        return self.wrist - self.crossing

    def rotations(self, Q: np.ndarray) -> np.ndarray:
        """R_0i for i = 1..7 at configurations Q (N, 7): (N, 7, 3, 3), products of exp([h_j] q_j)."""
        R = np.empty(Q.shape + (3, 3))
        acc = np.broadcast_to(np.eye(3), Q.shape[:1] + (3, 3))
        for i in range(7):
            acc = acc @ _rot(self.axes[i], Q[:, i])
            R[:, i] = acc
        return R

    def points_and_poses(self, Q: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """(S, E, W), each (N, 3) [m], and the tip poses (N, 4, 4) at configurations Q (N, 7), from one product of exponentials."""
        R = self.rotations(Q)
        S = np.broadcast_to(self.shoulder, (len(Q), 3))
        E = S + R[:, 2] @ self.p4
        W = E + R[:, 3] @ self.p5 + R[:, 5] @ self.p7
        T = np.tile(np.eye(4), (len(Q), 1, 1))
        T[:, :3, :3] = R[:, 6] @ self.tool_rotation
        T[:, :3, 3] = W + R[:, 6] @ self.tool
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
    """The 3R-R-2R-R geometry of ``chain`` (once per chain).

    Raises:
        NotSewError: one line naming the chain and what it lacks: 7 revolute joints, axes 1-3
            meeting, axes 5 and 6 meeting; or an S-R-S arm (axis 7 through C), which MC-Inverse
            solves.
    """
    movable = [j for j in chain.joints if j.movable]
    names = [j.name for j in movable]
    if len(movable) != 7 or any(j.type == "prismatic" for j in movable):
        raise NotSewError(f"chain '{chain.name}' has {len(movable)} movable joints; the SEW solver needs 7 revolute joints", chain.name)
    check = _axis_lines(chain, np.random.default_rng(7).uniform(-0.8, 0.8, 7))  # no coincidence of the zero pose
    for idx in ((0, 1, 2), (4, 5)):
        _, miss = _meeting_point([check[i] for i in idx])
        if miss > INTERSECTION_TOLERANCE_M:
            raise NotSewError(
                f"chain '{chain.name}': the axes of {', '.join(names[i] for i in idx)} do not meet in one point (miss {miss:.3g} m); "
                "the SEW solver handles arms whose joints 1-3 and 5-6 meet (3R-R-2R-R, as the Franka Panda)",
                chain.name,
            )
    lines = _axis_lines(chain, np.zeros(7))
    S, _ = _meeting_point(lines[0:3])
    C, _ = _meeting_point(lines[4:6])
    E, W = _foot(S, lines[3]), _foot(C, lines[6])
    if np.linalg.norm(W - C) <= INTERSECTION_TOLERANCE_M:
        raise NotSewError(f"chain '{chain.name}' is S-R-S (the axis of {names[6]} passes through where {names[4]} and {names[5]} meet): use mc-inverse", chain.name)
    tip = ChainKinematics.of(chain).pose(np.zeros(7))
    return SewChain(
        chain=chain,
        axes=np.array([d for _, d in lines]),
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
        upper_arm_rad: (M,) the angle of S -> E from S -> W at which each was found [rad].
        branch: (M,) which of the 8 branches (q7 root, (q5, q6) root, (q1, q2) root) it is, 0-7.
        residual: (M,) the largest error of the pose (position [m], rotation: the vector part of
            R_goal^T R) and the SEW angle [rad] each reproduces, by products of exponentials.
    """

    q: np.ndarray
    upper_arm_rad: np.ndarray
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


class _Search:
    """The 1-D search's function for N goals at once: the error of subproblem 1's condition for q4 along the upper arm's angle, per (q7, (q5, q6)) branch."""

    def __init__(self, arm: SewChain, sew: SewAngle, T: np.ndarray, psi: np.ndarray):
        self.arm = arm
        self.R07 = np.einsum("nij,kj->nik", T[:, :3, :3], arm.tool_rotation)  # R_0T R_T0^T
        self.p17 = T[:, :3, 3] - _mv(self.R07, arm.tool) - arm.shoulder  # S -> W
        self.e_sw = self.p17 / np.linalg.norm(self.p17, axis=1, keepdims=True)
        e_ce = _mv(_rot(self.e_sw, psi), sew.reference_direction(self.e_sw))
        self.n = np.cross(self.e_sw, e_ce)  # normal of the half-plane holding the elbow

    def __call__(self, pose: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For goals ``pose`` (M,) (indices) at upper-arm angles ``theta`` (M,): e (M, 4), (q5, q6, q7) (M, 4, 3), and S -> E (M, 3)."""
        arm, h = self.arm, self.arm.axes
        P4, P5, P7 = arm.p4, arm.p5, arm.p7
        p14 = _mv(_rot(self.n[pose], theta), self.e_sw[pose]) * np.linalg.norm(P4)
        R07 = self.R07[pose]
        d = np.einsum("nji,nj->ni", R07, self.p17[pose] - p14)  # R07^T (p17 - p14)
        local = np.einsum("nji,nj->ni", R07, p14)  # R07^T p14
        t7 = sp3(P7, d, -h[6], float(np.linalg.norm(P5)))  # |R67^T P7 - d| = |P5|
        errors, q567 = [], []
        for i7 in range(2):
            R67 = _rot(h[6], t7[:, i7])
            t5, t6 = sp2(P5, _mv(R67, d) - P7, -h[4], h[5])
            for i56 in range(2):
                R47 = _rot(h[4], t5[:, i56]) @ _rot(h[5], t6[:, i56]) @ R67
                errors.append(h[3] @ P4 - _mv(R47, local) @ h[3])
                q567.append(np.stack([t5[:, i56], t6[:, i56], t7[:, i7]], -1))
        return np.stack(errors, -1), np.stack(q567, 1), p14

    def on_branch(self, pose: np.ndarray, theta: np.ndarray, branch: np.ndarray) -> np.ndarray:
        return self(pose, theta)[0][np.arange(len(theta)), branch]


def _brackets(search: _Search, N: int, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(goal, branch, lo, hi) of every bracketed root of e on the grid of ``samples`` angles over [0, pi], with the ends of each branch's domain and its turning points towards zero sampled too (module docstring)."""
    grid = np.linspace(0.0, np.pi, samples)
    found: tuple[list[np.ndarray], ...] = ([], [], [], [])  # goals, branches, lows, highs

    def add(goal, branch, lo, hi):
        for column, value in zip(found, (goal, branch, lo, hi)):
            column.append(value)

    for first in range(0, N, CHUNK_GOALS):
        block = np.arange(first, min(N, first + CHUNK_GOALS))
        pose = np.repeat(block, samples)
        e = search(pose, np.tile(grid, len(block)))[0].reshape(len(block), samples, 4)
        finite = np.isfinite(e)
        # sign changes between neighbours
        a, c = e[:, :-1], e[:, 1:]
        g, k, b = np.nonzero(finite[:, :-1] & finite[:, 1:] & ((a == 0) | (np.sign(a) != np.sign(c))))
        add(block[g], b, grid[k], grid[k + 1])
        # the end of a branch's domain between two samples: found by bisection; a root between it
        # and the first sample inside has no sign change on the grid
        g, k, b = np.nonzero(finite[:, :-1] != finite[:, 1:])
        lo, hi, lo_inside = grid[k], grid[k + 1], finite[g, k, b]
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            with_lo = np.isfinite(search.on_branch(block[g], mid, b)) == lo_inside
            lo, hi = np.where(with_lo, mid, lo), np.where(with_lo, hi, mid)
        edge = np.where(lo_inside, lo, hi)
        inside = np.where(lo_inside, k, k + 1)
        e_edge = search.on_branch(block[g], edge, b)
        crossed = np.isfinite(e_edge) & (np.sign(e_edge) != np.sign(e[g, inside, b]))
        add(block[g][crossed], b[crossed], np.minimum(edge, grid[inside])[crossed], np.maximum(edge, grid[inside])[crossed])
        # a root at the end itself (two branches meeting there with e = 0, as at a planar home
        # pose): e behaves as sqrt near an end, so in doubles it gets only to ~1e-7 of it; kept for the polish
        at_end = ~crossed & (np.abs(e_edge) <= TOUCHING_M)
        add(block[g][at_end], b[at_end], edge[at_end], edge[at_end])
        # two roots closer than the samples: where a branch turns back towards zero between
        # samples of one sign, its turning point (golden section) splits the pair
        before, here, after = e[:, :-2], e[:, 1:-1], e[:, 2:]
        same = (np.sign(before) == np.sign(here)) & (np.sign(here) == np.sign(after))
        g, k, b = np.nonzero(finite[:, :-2] & finite[:, 1:-1] & finite[:, 2:] & same & (np.abs(here) <= np.minimum(np.abs(before), np.abs(after))))
        lo, hi, toward = grid[k], grid[k + 2], -np.sign(e[g, k + 1, b])
        for _ in range(BISECTION_STEPS):
            m1, m2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
            f1 = np.nan_to_num(toward * search.on_branch(block[g], m1, b), nan=-np.inf)
            f2 = np.nan_to_num(toward * search.on_branch(block[g], m2, b), nan=-np.inf)
            higher = f2 >= f1
            lo, hi = np.where(higher, m1, lo), np.where(higher, hi, m2)
        turning = 0.5 * (lo + hi)
        e_turning = toward * search.on_branch(block[g], turning, b)
        crossed = e_turning > 0
        add(block[g][crossed], b[crossed], grid[k][crossed], turning[crossed])
        add(block[g][crossed], b[crossed], turning[crossed], grid[k + 2][crossed])
        # a double root (e touching zero, as at a planar configuration, where two solutions
        # coincide) may miss zero by rounding either way: kept, for the polish to settle
        touching = ~crossed & (np.abs(e_turning) <= TOUCHING_M)
        add(block[g][touching], b[touching], turning[touching], turning[touching])
    goal, branch, lo, hi = (np.concatenate(column) for column in found)
    return goal, branch, lo, hi


def solve_many(arm: SewChain, T: np.ndarray, psi: np.ndarray, sew: SewAngle = SewAngle(), samples: int = SEARCH_SAMPLES) -> list[SewSolutions]:
    """Every solution of each hand pose ``T`` (N, 4, 4, chain base frame) at its SEW angle ``psi`` (N,) [rad] (module docstring), limits not applied; one :class:`SewSolutions` per pose."""
    T = np.asarray(T, dtype=float).reshape(-1, 4, 4)
    psi = np.broadcast_to(np.asarray(psi, dtype=float), len(T))
    h = arm.axes
    search = _Search(arm, sew, T, psi)
    goal, branch, lo, hi = _brackets(search, len(T), samples)
    goal, branch = goal.astype(int), branch.astype(int)
    e_lo = search.on_branch(goal, lo, branch)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        e_mid = search.on_branch(goal, mid, branch)
        with_lo = np.isfinite(e_mid) & (np.sign(e_mid) == np.sign(e_lo))
        with_hi = np.isfinite(e_mid) & ~with_lo
        lo, e_lo, hi = np.where(with_lo, mid, lo), np.where(with_lo, e_mid, e_lo), np.where(with_hi, mid, hi)
    theta = 0.5 * (lo + hi)
    _, q567, p14 = search(goal, theta)
    q5, q6, q7 = q567[np.arange(len(theta)), branch].T
    R07 = search.R07[goal]
    R47 = _rot(h[4], q5) @ _rot(h[5], q6) @ _rot(h[6], q7)
    q4 = sp1(arm.p4, _mv(R47, np.einsum("nji,nj->ni", R07, p14)), -h[3])
    R03 = R07 @ np.swapaxes(R47, 1, 2) @ np.swapaxes(_rot(h[3], q4), 1, 2)
    t2, t1 = sp2(h[2], _mv(R03, h[2]), h[1], -h[0])
    rows = []
    for i12 in range(2):
        q1, q2 = t1[:, i12], t2[:, i12]
        R23 = np.swapaxes(_rot(h[1], q2), 1, 2) @ np.swapaxes(_rot(h[0], q1), 1, 2) @ R03
        q3 = sp1(h[1], _mv(R23, h[1]), h[2])
        rows.append(np.stack([q1, q2, q3, q4, q5, q6, q7], -1))
    Q = np.concatenate(rows)
    goal, theta, branch = np.tile(goal, 2), np.tile(theta, 2), np.concatenate([2 * branch, 2 * branch + 1])
    ok = np.all(np.isfinite(Q), axis=1)
    Q, goal, theta, branch = Q[ok], goal[ok], theta[ok], branch[ok]
    T_goal, psi_goal = T[goal], psi[goal]
    offsets = DIFF_RAD * np.concatenate([np.eye(7), -np.eye(7)])  # central differences, all 14 in one call
    for _ in range(POLISH_STEPS):  # roots near a branch's end or a double root are found to ~1e-8 rad only
        F = _equations(arm, sew, T_goal, psi_goal, Q)
        around = _equations(arm, sew, np.repeat(T_goal, 14, axis=0), np.repeat(psi_goal, 14), (Q[:, None] + offsets).reshape(-1, 7)).reshape(len(Q), 14, 7)
        J = np.swapaxes(around[:, :7] - around[:, 7:], 1, 2) / (2 * DIFF_RAD)
        step = np.stack([np.linalg.lstsq(Jn, Fn, rcond=None)[0] for Jn, Fn in zip(J, F)]) if len(Q) else Q  # least squares: J is singular at a double root
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
        out.append(SewSolutions(q[unique], theta[mine][unique], branch[mine][unique], residual[mine][unique]))
    return out


def solve(arm: SewChain, T: np.ndarray, psi: float, sew: SewAngle = SewAngle(), samples: int = SEARCH_SAMPLES) -> SewSolutions:
    """Every solution of the hand pose ``T`` (4, 4, chain base frame) at SEW angle ``psi`` [rad] (module docstring), limits not applied."""
    return solve_many(arm, T[None], np.array([psi]), sew, samples)[0]


def into_limits(Q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Each angle of Q (M, 7) moved by a multiple of 2 pi into [lower, upper] where one lands there (limits that reach past +-pi)."""
    shifted = Q + 2 * np.pi * np.ceil((lower - Q) / (2 * np.pi))  # the smallest equivalent angle >= lower
    return np.where(shifted <= upper, shifted, Q)


def candidate_table(robot: Robot, chain: Chain, T: np.ndarray, psi: float, sew: SewAngle) -> list[dict]:
    """``dualarm ik sew``'s rows: every solution of the pose ``T`` (chain base frame) at SEW angle ``psi``, each with ``q`` [rad] (moved into the joint limits where an equivalent angle is), ``valid``, ``reason`` ("valid" or the first joint outside its limits), the position [m] and orientation [rad] errors of the chain's forward kinematics, its SEW angle [rad], the upper arm's angle from S -> W [rad] and its branch.

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
                "upper_arm_rad": float(found.upper_arm_rad[i]),
                "branch": int(found.branch[i]),
            }
        )
    return rows

"""The SEW angle and each family's equations at one SEW angle, in CasADi: error, margins, solutions.

What :mod:`dualarm.ik.analytic.sew` searches and solves over every goal of a path at once.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import casadi as cs
import numpy as np

from dualarm.ik.analytic.subproblems import rotate, subproblem2, turn
from dualarm.model.sew import FIRST_JOINT_FAMILY, UPPER_ARM_FAMILY, SewChain, _rot
from dualarm.numerics.batched import Batched
from dualarm.numerics.compiled import compiled

#: Newton steps polishing each solution on the 7 equations (pose and SEW angle).
POLISH_STEPS = 3
#: Goals whose grids are evaluated in one mapped call (memory: samples x 4 errors x this).
CHUNK_GOALS = 64
_Built = TypeVar("_Built")


def _turn(k, theta, v):
    """exp([k] theta) v for a unit axis k, an angle theta and a vector v (Rodrigues).

    Without forming the matrix.
    """
    return rotate(k, cs.cos(theta), cs.sin(theta), v)


def sp2(p1, p2, k1: np.ndarray, k2: np.ndarray) -> tuple[list[tuple], cs.SX]:
    """Subproblem 2: rot(k1, t1) p1 = rot(k2, t2) p2 for constant non-parallel unit axes.

    Two (t1, t2), NaN where there is no exact solution (:func:`dualarm.ik.analytic.subproblems.subproblem2` of
    rot(k1, -t1) rot(k2, t2) p2 = p1), and a margin, negative exactly there (gamma^2 / |p2|^2).
    """
    roots, gamma2, _ = subproblem2(k1, k2, p2, p1)
    return [(cs.if_else(gamma2 >= 0, -t1, np.nan), cs.if_else(gamma2 >= 0, t2, np.nan)) for t1, t2 in roots], gamma2


def sp3(p1, p2, k, d) -> tuple[list, cs.SX]:
    """Subproblem 3: |rot(k, t) p1 - p2| = d.

    Two t, NaN where there is no exact solution, and a margin, negative exactly there ((r - |rhs|) / (|p1| |p2|)
    below).

    p2 . rot(k, t) p1 = A cos t + B sin t + (k.p1)(k.p2) = (|p1|^2 + |p2|^2 - d^2) / 2.
    """
    A = cs.dot(p2, p1 - cs.dot(k, p1) * k)
    B = cs.dot(p2, cs.cross(k, p1))
    rhs = (cs.dot(p1, p1) + cs.dot(p2, p2) - d**2) / 2 - cs.dot(k, p1) * cs.dot(k, p2)
    r = cs.sqrt(A**2 + B**2)
    ratio = cs.if_else(cs.fabs(rhs) <= r, rhs / cs.if_else(r > 0, r, 1), np.nan)
    phi, delta = cs.atan2(B, A), cs.acos(ratio)
    return [phi + delta, phi - delta], (r - cs.fabs(rhs)) / (cs.norm_2(p1) * cs.norm_2(p2))


@dataclass(frozen=True)
class SewAngle:
    """The SEW angle: psi about the shoulder-wrist line e_SW.

    From the reference direction e_x(e_SW) to the elbow's direction from that line.

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
    def stereographic(cls, vertical: np.ndarray | tuple[float, float, float]) -> SewAngle:
        """The stereographic SEW angle with e_r the unit ``vertical``.

        The singular half-line runs from the shoulder along -e_r (into the base, out of reach).
        """
        v = np.asarray(vertical, dtype=float) / np.linalg.norm(vertical)
        return cls(
            reference=(float(v[0]), float(v[1]), float(v[2])), singular=(float(-v[0]), float(-v[1]), float(-v[2]))
        )

    def reference_direction(self, e_sw):
        """e_x: the unit direction of psi = 0.

        Normal to the unit shoulder-wrist direction ``e_sw`` (CasADi, 3x1).
        """
        r = cs.DM(self.reference)
        if self.singular is None:
            x = r - cs.dot(e_sw, r) * e_sw
        else:
            x = cs.cross(cs.cross(e_sw - cs.DM(self.singular), r), e_sw)
        return x / cs.norm_2(x)

    def symbolic(self, S, E, W):
        """The angle psi [rad] in (-pi, pi] of points S, E, W (CasADi, 3x1 each): right-handed about S -> W."""
        e_sw = (W - S) / cs.norm_2(W - S)
        x = self.reference_direction(e_sw)
        return cs.atan2(cs.dot(e_sw, cs.cross(x, E - S)), cs.dot(x, E - S))

    def angle(self, S: np.ndarray, E: np.ndarray, W: np.ndarray) -> np.ndarray:
        """The angle psi [rad] in (-pi, pi] of points S, E, W (..., 3) (:meth:`symbolic`, in mapped calls)."""
        S, E, W = np.broadcast_arrays(*(np.asarray(p, dtype=float) for p in (S, E, W)))
        return _angle_function(self)(S.reshape(-1, 3), E.reshape(-1, 3), W.reshape(-1, 3))[0][:, 0].reshape(
            S.shape[:-1]
        )


@functools.cache
def _angle_function(sew: SewAngle) -> Batched:
    S, E, W = (cs.SX.sym(name, 3) for name in "SEW")
    return Batched(compiled(cs.Function("sew_angle", [S, E, W], [sew.symbolic(S, E, W)])))


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


#: The size of :func:`_goal`'s vector.
GOAL_SIZE = 18


def _goal(arm: SewChain, sew: SewAngle, T, psi):
    """What the search needs of a goal pose T (4x4) and SEW angle psi (CasADi), as one vector.

    The vector has :data:`GOAL_SIZE` entries (see :func:`_unpack`).
    """
    R07 = T[:3, :3] @ arm.tool_rotation.T
    W = T[:3, 3] - R07 @ arm.tool
    e_sw = (W - arm.shoulder) / cs.norm_2(W - arm.shoulder)
    n = cs.cross(e_sw, _turn(e_sw, psi, sew.reference_direction(e_sw)))
    return cs.vertcat(cs.vec(R07), W, e_sw, n)


def _unpack(goal) -> tuple:
    """:func:`_goal`'s vector as R_07, the wrist point W [m], e_SW, and the normal n.

    R_07 is the tip's rotation without its rotation at q = 0; n is the normal of the half-plane that must hold the
    elbow.
    """
    return cs.reshape(goal[:9], 3, 3), goal[9:12], goal[12:15], goal[15:18]


def _upper_arm_search(arm: SewChain, goal: cs.SX, x: cs.SX) -> tuple[list, list, list]:
    """3R-R-2R-R: x is the upper arm's angle from S -> W in the SEW half-plane, over [0, pi].

    Subproblem 3 gives q7 (2 roots), subproblem 2 (q5, q6) (2 roots); e is the error of subproblem 1's condition
    for q4 (the elbow axis's component). Then q4 by subproblem 1, (q1, q2) by subproblem 2 (2 roots), q3 by
    subproblem 1.

    Returns:
        the error e of the 4 branches, their margins (negative exactly where the branch's
        subproblems have no solution), and each branch's 2 configurations (7x1).
    """
    h, (R07, W, e_sw, n) = arm.axes, _unpack(goal)
    P4, P5, P7 = arm.elbow - arm.shoulder, arm.crossing - arm.elbow, arm.wrist - arm.crossing
    p14 = _turn(n, x, e_sw) * float(np.linalg.norm(P4))  # S -> E
    d = R07.T @ (W - arm.shoulder - p14)  # R07^T (S -> W - S -> E)
    local = R07.T @ p14
    errors, margins, configurations = [], [], []
    t7s, m7 = sp3(P7, d, -h[6], float(np.linalg.norm(P5)))  # |R67^T P7 - d| = |P5|
    for t7 in t7s:
        local7 = _turn(h[6], t7, local)
        t56s, m56 = sp2(P5, _turn(h[6], t7, d) - P7, -h[4], h[5])
        for t5, t6 in t56s:
            margins.append(cs.if_else(m7 < 0, m7, m56))
            errors.append(
                cs.dot(h[3], P4) - cs.dot(h[3], _turn(h[4], t5, _turn(h[5], t6, local7)))
            )  # vectors turned: fewer operations on the grid
            R47 = _rot(h[4], t5) @ _rot(h[5], t6) @ _rot(h[6], t7)
            q4 = turn(-h[3], P4, R47 @ local)
            R03 = R07 @ R47.T @ _rot(h[3], q4).T
            rows = []
            for t2, t1 in sp2(h[2], R03 @ h[2], h[1], -h[0])[0]:
                q3 = turn(h[2], h[1], (_rot(h[0], t1) @ _rot(h[1], t2)).T @ R03 @ h[1])
                rows.append(cs.vertcat(t1, t2, q3, q4, t5, t6, t7))
            configurations.append(rows)
    return errors, margins, configurations


def _first_joint_search(arm: SewChain, goal: cs.SX, x: cs.SX) -> tuple[list, list, list]:
    """R-2R-R-3R: x is q1, over [-pi, pi].

    C turns with q1 about axis 1; |C - W| fixes q4 (subproblem 3, 2 roots); (q2, q3) turn C -> W onto the goal's
    (subproblem 2, 2 roots); e is E's distance from the SEW plane (zero on both of its half-planes: the one beyond
    S -> W fails the SEW-angle residual). Then (q5, q6) by subproblem 2 (2 roots) and q7 by subproblem 1.

    Returns:
        the error e of the 4 branches, their margins (negative exactly where the branch's
        subproblems have no solution), and each branch's 2 configurations (7x1).
    """
    h, p4, (R07, W, _, n) = arm.axes, arm.axis_points[3], _unpack(goal)
    C = arm.shoulder + _turn(h[0], x, arm.crossing - arm.shoulder)
    u = _turn(h[0], -x, W - C)  # R2 R3 (C -> W after q4) must be this
    errors, margins, configurations = [], [], []
    t4s, m4 = sp3(arm.wrist - p4, arm.crossing - p4, h[3], cs.norm_2(W - C))
    for t4 in t4s:
        v = p4 + _turn(h[3], t4, arm.wrist - p4) - arm.crossing  # C -> W at q4 alone
        t23s, m23 = sp2(u, v, -h[1], h[2])
        for t2, t3 in t23s:
            margins.append(cs.if_else(m4 < 0, m4, m23))
            errors.append(
                cs.dot(n, C + _turn(h[0], x, _turn(h[1], t2, _turn(h[2], t3, arm.elbow - arm.crossing))) - arm.shoulder)
            )
            R03 = _rot(h[0], x) @ _rot(h[1], t2) @ _rot(h[2], t3)
            R47 = (R03 @ _rot(h[3], t4)).T @ R07
            rows = []
            for t5, t6 in sp2(R47 @ h[6], h[6], -h[4], h[5])[0]:
                q7 = turn(h[6], h[5], (_rot(h[4], t5) @ _rot(h[5], t6)).T @ R47 @ h[5])
                rows.append(cs.vertcat(x, t2, t3, t4, t5, t6, q7))
            configurations.append(rows)
    return errors, margins, configurations


#: Each family's search: the span of its variable and the builder of its errors, margins and
#: configurations.
SEARCHES: dict[str, tuple[tuple[float, float], Callable[[SewChain, cs.SX, cs.SX], tuple[list, list, list]]]] = {
    UPPER_ARM_FAMILY: ((0.0, np.pi), _upper_arm_search),
    FIRST_JOINT_FAMILY: ((-np.pi, np.pi), _first_joint_search),
}


@dataclass(frozen=True)
class _Solver:
    """The CasADi Functions of one arm's search at one SEW-angle definition, batched.

    Batched by :class:`dualarm.numerics.batched.Batched`.

    Attributes:
        span: the search variable's range [rad].
        goal: ``(T (4x4), psi) -> g (18)``: what the search needs of a goal (:func:`_goal`).
        grid: ``g -> (e, m) (4 x samples each)``: the error and margin of the 4 branches on the grid over
            ``span``.
        errors: per branch, ``(g, x) -> (e, m)``: its error (NaN where it has no solution) and its
            margin (negative exactly there: defined everywhere, so a branch that exists only
            between two samples shows as a margin rising towards zero).
        configurations: ``(g, x) -> Q (7x8)`` [rad]: column 2 b + j the last subproblem's root j on branch
            b.
        equations: ``(T, psi, q) -> (F (7), dF/dq (7x7))``: what a solution must zero, the position
            error [m], the rotation error (the vector part of R_goal^T R) and the SEW angle's error [rad],
            and its Jacobian (by CasADi's algorithmic differentiation).
    """

    span: tuple[float, float]
    goal: Batched
    grid: Batched
    errors: tuple[Batched, ...]
    configurations: Batched
    equations: Batched

    @classmethod
    def of(cls, arm: SewChain, sew: SewAngle, samples: int) -> _Solver:
        span, search = SEARCHES[arm.family]
        T, psi, g, x, q = (
            cs.SX.sym("T", 4, 4),
            cs.SX.sym("psi"),
            cs.SX.sym("g", GOAL_SIZE),
            cs.SX.sym("x"),
            cs.SX.sym("q", 7),
        )
        goal = compiled(cs.Function("sew_goal", [T, psi], [_goal(arm, sew, T, psi)], {"cse": True}))
        errors, margins, configurations = search(arm, g, x)
        e = compiled(cs.Function("sew_errors", [g, x], [cs.vertcat(*errors), cs.vertcat(*margins)], {"cse": True}))
        on_branch = tuple(
            Batched(compiled(cs.Function(f"sew_errors_{b}", [g, x], [errors[b], margins[b]], {"cse": True})))
            for b in range(len(errors))
        )
        Q = compiled(
            cs.Function(
                "sew_configurations", [g, x], [cs.horzcat(*(c for rows in configurations for c in rows))], {"cse": True}
            )
        )
        E, W, got = arm.symbolic(q)
        D = T[:3, :3].T @ got[:3, :3]
        angle = sew.symbolic(cs.DM(arm.shoulder), E, W) - psi
        F = cs.vertcat(
            got[:3, 3] - T[:3, 3],
            0.5 * cs.vertcat(D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]),
            cs.atan2(cs.sin(angle), cs.cos(angle)),
        )
        equations = compiled(cs.Function("sew_equations", [T, psi, q], [F, cs.jacobian(F, q)], {"cse": True}))
        gm = cs.MX.sym("g", GOAL_SIZE)
        grid = cs.Function("sew_grid", [gm], e.map(samples)(gm, cs.DM(np.linspace(*span, samples)).T))
        return cls(span, Batched(goal), Batched(grid, CHUNK_GOALS), on_branch, Batched(Q), Batched(equations))

    def on_branch(self, G: np.ndarray, x: np.ndarray, branch: np.ndarray, margin: bool = False) -> np.ndarray:
        """The error e (M,) of goals G (M, 18) at x (M,) on ``branch`` (M,), or its margin.

        One call per branch: a branch alone costs a fraction of all four.
        """
        out = np.empty(len(x))
        for b, errors in enumerate(self.errors):
            mine = branch == b
            if mine.any():
                out[mine] = errors(G[mine], x[mine])[margin][:, 0]
        return out

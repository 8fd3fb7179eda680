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
closer than the samples, or a double root), also between an end and the samples inside it, are
located and sampled too. Each branch's margin (negative exactly where its subproblems have no
solution, defined everywhere) finds the domains the grid does not see: a branch that exists only
between two samples (the margin peaks above zero there) and a gap narrower than a sample (it dips
below). Every root is refined by bisection, so every root in the range is found, not the one
nearest a seed; each solution is then
polished by Newton on the 7 equations, with their Jacobian from CasADi's algorithmic
differentiation.

The subproblems, each family's error and configurations, the forward kinematics (products of
exponentials of the chain's axes at q = 0 in its base frame), the SEW angle and the polish's
equations are CasADi expressions (:class:`_Solver`), evaluated over every goal of a path at once in
mapped calls (:class:`dualarm.numerics.batched.Batched`): the grid of a goal in one call, each step of
the bisections for all brackets of all goals in one call. The bracketing and its bookkeeping are
numpy (:func:`solve_many`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import casadi as cs
import numpy as np

from dualarm.ik.analytic.subproblems import rotate, subproblem2, turn
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import Chain, Robot
from dualarm.model.sew import FIRST_JOINT_FAMILY, UPPER_ARM_FAMILY, SewChain, _rot, sew_chain
from dualarm.numerics.batched import Batched
from dualarm.numerics.compiled import compiled

#: Samples of the 1-D search over its range ([0, pi] or [-pi, pi]).
SEARCH_SAMPLES = 2000
#: Bisection steps refining each bracketed root (2000 samples: pi / 2000 / 2^60 is below rounding).
BISECTION_STEPS = 60
#: Newton steps polishing each solution on the 7 equations (pose and SEW angle).
POLISH_STEPS = 3
#: The golden section's ratio, (sqrt 5 - 1) / 2.
GOLDEN = (5**0.5 - 1) / 2
#: Goals whose grids are evaluated in one mapped call (memory: samples x 4 errors x this).
CHUNK_GOALS = 64
#: A turning point of the search's error, or the end of a branch's domain, this close to zero is a root [m].
TOUCHING_M = 1e-6
#: Solutions of one goal closer than this are one [rad] (a solution is found to ~1e-10 rad, to ~1e-8 where two branches meet).
SAME_SOLUTION_RAD = 1e-7
#: A candidate reproducing the pose (position [m], rotation) or the SEW angle [rad] worse than this is dropped.
RESIDUAL_TOLERANCE = 1e-9


_Built = TypeVar("_Built")


# ----------------------------------------------------------------------------- subproblems (CasADi)


def _turn(k, theta, v):
    """exp([k] theta) v for a unit axis k, an angle theta and a vector v, without forming the matrix (Rodrigues)."""
    return rotate(k, cs.cos(theta), cs.sin(theta), v)


def sp2(p1, p2, k1: np.ndarray, k2: np.ndarray) -> tuple[list[tuple], cs.SX]:
    """Subproblem 2: rot(k1, t1) p1 = rot(k2, t2) p2 for constant non-parallel unit axes; two (t1, t2), NaN where there is no exact solution (:func:`dualarm.ik.analytic.subproblems.subproblem2` of rot(k1, -t1) rot(k2, t2) p2 = p1), and a margin, negative exactly there (gamma^2 / |p2|^2)."""
    roots, gamma2, _ = subproblem2(k1, k2, p2, p1)
    return [(cs.if_else(gamma2 >= 0, -t1, np.nan), cs.if_else(gamma2 >= 0, t2, np.nan)) for t1, t2 in roots], gamma2


def sp3(p1, p2, k, d) -> tuple[list, cs.SX]:
    """Subproblem 3: |rot(k, t) p1 - p2| = d; two t, NaN where there is no exact solution, and a margin, negative exactly there ((r - |rhs|) / (|p1| |p2|) below).

    p2 . rot(k, t) p1 = A cos t + B sin t + (k.p1)(k.p2) = (|p1|^2 + |p2|^2 - d^2) / 2.
    """
    A = cs.dot(p2, p1 - cs.dot(k, p1) * k)
    B = cs.dot(p2, cs.cross(k, p1))
    rhs = (cs.dot(p1, p1) + cs.dot(p2, p2) - d**2) / 2 - cs.dot(k, p1) * cs.dot(k, p2)
    r = cs.sqrt(A**2 + B**2)
    ratio = cs.if_else(cs.fabs(rhs) <= r, rhs / cs.if_else(r > 0, r, 1), np.nan)
    phi, delta = cs.atan2(B, A), cs.acos(ratio)
    return [phi + delta, phi - delta], (r - cs.fabs(rhs)) / (cs.norm_2(p1) * cs.norm_2(p2))


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
    def stereographic(cls, vertical: np.ndarray | tuple[float, float, float]) -> SewAngle:
        """The stereographic SEW angle with e_r the unit ``vertical`` and the singular half-line from the shoulder along -e_r (into the base, out of reach)."""
        v = np.asarray(vertical, dtype=float) / np.linalg.norm(vertical)
        return cls(
            reference=(float(v[0]), float(v[1]), float(v[2])), singular=(float(-v[0]), float(-v[1]), float(-v[2]))
        )

    def reference_direction(self, e_sw):
        """e_x: the unit direction of psi = 0, normal to the unit shoulder-wrist direction ``e_sw`` (CasADi, 3x1)."""
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


#: The size of :func:`_goal`'s vector.
GOAL_SIZE = 18


def _goal(arm: SewChain, sew: SewAngle, T, psi):
    """What the search needs of a goal pose T (4x4) and SEW angle psi (CasADi), as one vector of :data:`GOAL_SIZE` (see :func:`_unpack`)."""
    R07 = T[:3, :3] @ arm.tool_rotation.T
    W = T[:3, 3] - R07 @ arm.tool
    e_sw = (W - arm.shoulder) / cs.norm_2(W - arm.shoulder)
    n = cs.cross(e_sw, _turn(e_sw, psi, sew.reference_direction(e_sw)))
    return cs.vertcat(cs.vec(R07), W, e_sw, n)


def _unpack(goal) -> tuple:
    """:func:`_goal`'s vector as R_07 (the tip's rotation without its rotation at q = 0), the wrist point W [m], e_SW, and the normal n of the half-plane that must hold the elbow."""
    return cs.reshape(goal[:9], 3, 3), goal[9:12], goal[12:15], goal[15:18]


def _upper_arm_search(arm: SewChain, goal: cs.SX, x: cs.SX) -> tuple[list, list, list]:
    """3R-R-2R-R: x is the upper arm's angle from S -> W in the SEW half-plane, over [0, pi]. Subproblem 3 gives q7 (2 roots), subproblem 2 (q5, q6) (2 roots); e is the error of subproblem 1's condition for q4 (the elbow axis's component). Then q4 by subproblem 1, (q1, q2) by subproblem 2 (2 roots), q3 by subproblem 1.

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
    """R-2R-R-3R: x is q1, over [-pi, pi]. C turns with q1 about axis 1; |C - W| fixes q4 (subproblem 3, 2 roots); (q2, q3) turn C -> W onto the goal's (subproblem 2, 2 roots); e is E's distance from the SEW plane (zero on both of its half-planes: the one beyond S -> W fails the SEW-angle residual). Then (q5, q6) by subproblem 2 (2 roots) and q7 by subproblem 1.

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


#: Each family's search: the span of its variable and the builder of its errors, margins and configurations.
SEARCHES: dict[str, tuple[tuple[float, float], Callable[[SewChain, cs.SX, cs.SX], tuple[list, list, list]]]] = {
    UPPER_ARM_FAMILY: ((0.0, np.pi), _upper_arm_search),
    FIRST_JOINT_FAMILY: ((-np.pi, np.pi), _first_joint_search),
}


@dataclass(frozen=True)
class _Solver:
    """The CasADi Functions of one arm's search at one SEW-angle definition, batched (:class:`dualarm.numerics.batched.Batched`).

    Attributes:
        span: the search variable's range [rad].
        goal: ``(T (4x4), psi) -> g (18)``: what the search needs of a goal (:func:`_goal`).
        grid: ``g -> (e, m) (4 x samples each)``: the error and margin of the 4 branches on the grid over ``span``.
        errors: per branch, ``(g, x) -> (e, m)``: its error (NaN where it has no solution) and its
            margin (negative exactly there: defined everywhere, so a branch that exists only
            between two samples shows as a margin rising towards zero).
        configurations: ``(g, x) -> Q (7x8)`` [rad]: column 2 b + j the last subproblem's root j on branch b.
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
        """The error e (M,) of goals G (M, 18) at x (M,) on ``branch`` (M,), or its margin (one call per branch: a branch alone costs a fraction of all four)."""
        out = np.empty(len(x))
        for b, errors in enumerate(self.errors):
            mine = branch == b
            if mine.any():
                out[mine] = errors(G[mine], x[mine])[margin][:, 0]
        return out


def _maximise(f: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The x in [lo, hi] (M,) where f (unimodal there; NaN counts as -inf) is largest, by golden section; f is given both trial points of all M at once (2M,)."""
    for _ in range(BISECTION_STEPS):
        m1, m2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
        f1, f2 = np.nan_to_num(f(np.concatenate([m1, m2])), nan=-np.inf).reshape(2, -1)
        higher = f2 >= f1
        lo, hi = np.where(higher, m1, lo), np.where(higher, hi, m2)
    return 0.5 * (lo + hi)


def _brackets(solver: _Solver, G: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(goal, branch, lo, hi) of every bracketed root of e on the grid of ``samples`` values of x over the search's span, with the ends of each branch's domain, its turning points towards zero, and the branches that exist only between two samples (where the margin rises above zero) sampled too (module docstring).

    The grid is evaluated :data:`CHUNK_GOALS` goals at a time; the ends, turning points and narrow
    domains of all goals are then refined together, one batched step at a time.
    """
    grid = np.linspace(*solver.span, samples)
    found: tuple[list[np.ndarray], ...] = ([], [], [], [])  # goals, branches, lows, highs
    edges: tuple[list[np.ndarray], ...] = (
        [],
        [],
        [],
        [],
        [],
        [],
    )  # goals, branches, x outside the domain, x inside, e there, e one sample further in
    turns: tuple[list[np.ndarray], ...] = (
        [],
        [],
        [],
        [],
        [],
    )  # goals, branches, the interval of the turn, sign of e there
    narrow: tuple[list[np.ndarray], ...] = ([], [], [])  # goals, branches, grid index before the margin's peak
    pinched: tuple[list[np.ndarray], ...] = (
        [],
        [],
        [],
        [],
    )  # goals, branches, grid index before the margin's dip, e at the 4 samples around

    def add(to, *values):
        for column, value in zip(to, values):
            column.append(value)

    for first in range(0, len(G), CHUNK_GOALS):
        block = np.arange(first, min(len(G), first + CHUNK_GOALS))
        e, m = (values.transpose(0, 2, 1) for values in solver.grid(G[block]))  # (goals, samples, 4)
        finite = np.isfinite(e)
        # sign changes between neighbours
        a, c = e[:, :-1], e[:, 1:]
        g, k, b = np.nonzero(finite[:, :-1] & finite[:, 1:] & ((a == 0) | (np.sign(a) != np.sign(c))))
        add(found, block[g], b, grid[k], grid[k + 1])
        # the end of a branch's domain between two samples
        g, k, b = np.nonzero(finite[:, :-1] != finite[:, 1:])
        inside = np.where(finite[g, k, b], k, k + 1)
        further = np.clip(np.where(finite[g, k, b], k - 1, k + 2), 0, samples - 1)
        add(
            edges,
            block[g],
            b,
            grid[np.where(finite[g, k, b], k + 1, k)],
            grid[inside],
            e[g, inside, b],
            np.where(further == inside, np.nan, e[g, further, b]),
        )
        # two roots closer than the samples: a branch turning back towards zero between samples of one sign
        before, here, after = e[:, :-2], e[:, 1:-1], e[:, 2:]
        same = (np.sign(before) == np.sign(here)) & (np.sign(here) == np.sign(after))
        g, k, b = np.nonzero(
            finite[:, :-2]
            & finite[:, 1:-1]
            & finite[:, 2:]
            & same
            & (np.abs(here) <= np.minimum(np.abs(before), np.abs(after)))
        )
        add(turns, block[g], b, grid[k], grid[k + 2], np.sign(e[g, k + 1, b]))
        # a branch whose whole domain lies between samples: its margin peaks below zero on the grid
        outside = ~finite[:, :-2] & ~finite[:, 1:-1] & ~finite[:, 2:]
        g, k, b = np.nonzero(outside & (m[:, 1:-1] >= m[:, :-2]) & (m[:, 1:-1] >= m[:, 2:]))
        add(narrow, block[g], b, k)
        # a gap in a branch's domain between samples (where two branches meet and part): its margin dips
        g, k, b = np.nonzero(
            finite[:, :-2] & finite[:, 1:-1] & finite[:, 2:] & (m[:, 1:-1] <= m[:, :-2]) & (m[:, 1:-1] <= m[:, 2:])
        )
        around = k[:, None] + np.array([-1, 0, 2, 3])
        add(
            pinched,
            block[g],
            b,
            k,
            np.where(
                (around >= 0) & (around < samples), e[g[:, None], np.clip(around, 0, samples - 1), b[:, None]], np.nan
            ),
        )
    # the narrow domains: where the margin peaks, and if that is inside, both its ends are edges
    g, b, k = (np.concatenate(column) for column in narrow)
    peak = _maximise(
        lambda x: solver.on_branch(np.tile(G[g], (2, 1)), x, np.tile(b, 2), margin=True), grid[k], grid[k + 2]
    )
    e_peak = solver.on_branch(G[g], peak, b)
    g, b, k, peak, e_peak = (v[np.isfinite(e_peak)] for v in (g, b, k, peak, e_peak))
    add(
        edges,
        np.tile(g, 2),
        np.tile(b, 2),
        np.concatenate([grid[k], grid[k + 2]]),
        np.tile(peak, 2),
        np.tile(e_peak, 2),
        np.full(2 * len(g), np.nan),
    )
    # the gaps: where the margin dips, and if that is outside, the samples either side have an edge there
    g, b, k = (np.concatenate(column) for column in pinched[:3])
    dip = _maximise(
        lambda x: -solver.on_branch(np.tile(G[g], (2, 1)), x, np.tile(b, 2), margin=True), grid[k], grid[k + 2]
    )
    g, b, k, dip, e_around = (
        v[~np.isfinite(solver.on_branch(G[g], dip, b))] for v in (g, b, k, dip, np.concatenate(pinched[3]))
    )
    add(
        edges,
        np.tile(g, 2),
        np.tile(b, 2),
        np.tile(dip, 2),
        np.concatenate([grid[k], grid[k + 2]]),
        np.concatenate([e_around[:, 1], e_around[:, 2]]),
        np.concatenate([e_around[:, 0], e_around[:, 3]]),
    )
    # the ends, by bisection on where e is defined: a root between an end and the point inside
    # has no sign change on the grid
    g, b, out, inside, e_inside, e_further = (np.concatenate(column) for column in edges)
    edge = inside.copy()
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (out + edge)
        active = np.flatnonzero((mid != out) & (mid != edge))  # not yet at rounding
        defined = np.isfinite(solver.on_branch(G[g[active]], mid[active], b[active]))
        out[active], edge[active] = (
            np.where(defined, out[active], mid[active]),
            np.where(defined, mid[active], edge[active]),
        )
    e_edge = solver.on_branch(G[g], edge, b)
    crossed = np.isfinite(e_edge) & (np.sign(e_edge) != np.sign(e_inside))
    add(found, g[crossed], b[crossed], np.minimum(edge, inside)[crossed], np.maximum(edge, inside)[crossed])
    # a root at the end itself (two branches meeting there with e = 0, as at a planar home pose):
    # e behaves as sqrt near an end, so in doubles it gets only to ~1e-7 of it; kept for the polish
    at_end = ~crossed & (np.abs(e_edge) <= TOUCHING_M)
    add(found, g[at_end], b[at_end], edge[at_end], edge[at_end])
    # a turn towards zero between the end and the sample further in than the one inside (as e
    # bends near an end, two roots may lie there)
    sign = np.sign(e_inside)
    turn = (
        ~crossed & ~at_end & (np.sign(e_edge) == sign) & (np.sign(e_further) != -sign)
    )  # not a sign change already found
    further = np.where(np.isfinite(e_further), inside + np.sign(inside - edge) * (grid[1] - grid[0]), inside)
    add(turns, g[turn], b[turn], np.minimum(further, edge)[turn], np.maximum(further, edge)[turn], sign[turn])
    # the turning points split the pairs
    g, b, lo, hi, sign = (np.concatenate(column) for column in turns)
    toward = -sign
    turning = _maximise(
        lambda x: np.tile(toward, 2) * solver.on_branch(np.tile(G[g], (2, 1)), x, np.tile(b, 2)), lo, hi
    )
    e_turning = toward * solver.on_branch(G[g], turning, b)
    crossed = e_turning > 0
    add(found, g[crossed], b[crossed], lo[crossed], turning[crossed])
    add(found, g[crossed], b[crossed], turning[crossed], hi[crossed])
    # a double root (e touching zero, as at a planar configuration, where two solutions coincide)
    # may miss zero by rounding either way: kept, for the polish to settle
    touching = ~crossed & (np.abs(e_turning) <= TOUCHING_M)
    add(found, g[touching], b[touching], turning[touching], turning[touching])
    goal, branch, lo, hi = (np.concatenate(column) for column in found)
    return goal.astype(int), branch.astype(int), lo, hi


def solve_many(
    arm: SewChain, T: np.ndarray, psi: np.ndarray, sew: SewAngle = SewAngle(), samples: int = SEARCH_SAMPLES
) -> list[SewSolutions]:
    """Every solution of each hand pose ``T`` (N, 4, 4, chain base frame) at its SEW angle ``psi`` (N,) [rad] (module docstring), limits not applied; one :class:`SewSolutions` per pose."""
    T = np.asarray(T, dtype=float).reshape(-1, 4, 4)
    psi = np.broadcast_to(np.asarray(psi, dtype=float), len(T))
    solver = arm.cached(("solver", sew, samples), lambda: _Solver.of(arm, sew, samples))
    G = solver.goal(T, psi)[0]
    goal, branch, lo, hi = _brackets(solver, G, samples)
    e_lo = solver.on_branch(G[goal], lo, branch)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        active = np.flatnonzero((mid != lo) & (mid != hi))  # not yet at rounding
        mid = mid[active]
        e_mid = solver.on_branch(G[goal[active]], mid, branch[active])
        with_lo = np.isfinite(e_mid) & (np.sign(e_mid) == np.sign(e_lo[active]))
        with_hi = np.isfinite(e_mid) & ~with_lo
        lo[active], e_lo[active], hi[active] = (
            np.where(with_lo, mid, lo[active]),
            np.where(with_lo, e_mid, e_lo[active]),
            np.where(with_hi, mid, hi[active]),
        )
    x = 0.5 * (lo + hi)
    Q = solver.configurations(G[goal], x)[0].transpose(0, 2, 1)[
        np.arange(len(x))[:, None], 2 * branch[:, None] + np.arange(2)
    ]  # (M, 2, 7)
    Q, goal, x, branch = (
        Q.reshape(-1, 7),
        np.repeat(goal, 2),
        np.repeat(x, 2),
        (2 * branch[:, None] + np.arange(2)).ravel(),
    )
    ok = np.all(np.isfinite(Q), axis=1)
    Q, goal, x, branch = Q[ok], goal[ok], x[ok], branch[ok]
    T_goal, psi_goal = T[goal], psi[goal]
    for _ in range(POLISH_STEPS):  # roots near a branch's end or a double root are found to ~1e-8 rad only
        F, J = solver.equations(T_goal, psi_goal, Q)
        step = (np.linalg.pinv(J) @ F[..., None])[..., 0]  # least squares: J is singular at a double root
        better = np.abs(solver.equations(T_goal, psi_goal, Q - step)[0]).max(axis=1) < np.abs(F).max(axis=1)
        Q = np.where(better[:, None], Q - step, Q)
    Q = np.angle(np.exp(1j * Q))  # into (-pi, pi]
    residual = np.abs(solver.equations(T_goal, psi_goal, Q)[0]).max(axis=1) if len(Q) else np.zeros(0)
    keep = residual <= RESIDUAL_TOLERANCE
    out = []
    for n in range(len(T)):
        mine = keep & (goal == n)
        q = Q[mine]
        apart = np.abs(np.angle(np.exp(1j * (q[:, None] - q[None])))).max(axis=-1) > SAME_SOLUTION_RAD
        unique = np.array(
            [i for i in range(len(q)) if apart[i, :i].all()], dtype=int
        )  # a root bracketed twice (at a sample, or polished onto another) once
        out.append(SewSolutions(q[unique], x[mine][unique], branch[mine][unique], residual[mine][unique]))
    return out


def solve(
    arm: SewChain, T: np.ndarray, psi: float, sew: SewAngle = SewAngle(), samples: int = SEARCH_SAMPLES
) -> SewSolutions:
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
        reason = (
            "valid"
            if not outside
            else f"outside limits: {chain.joint_names[outside[0]]} at {q[outside[0]]:.4f} [{lower[outside[0]]:.4f}, {upper[outside[0]]:.4f}]"
        )
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

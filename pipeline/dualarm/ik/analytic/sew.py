"""Shoulder-elbow-wrist (SEW) angle and every inverse-kinematics solution at one SEW angle.

For 7R arms that need not be S-R-S. Elias and Wen ("Redundancy parameterization and inverse kinematics of 7-DOF revolute
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

from collections.abc import Callable

import numpy as np

from dualarm.ik.analytic.sew_equations import CHUNK_GOALS, POLISH_STEPS, SewAngle, SewSolutions, _Solver
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import Chain, Robot
from dualarm.model.sew import SewChain, sew_chain

#: Samples of the 1-D search over its range ([0, pi] or [-pi, pi]).
SEARCH_SAMPLES = 2000
#: Bisection steps refining each bracketed root (2000 samples: pi / 2000 / 2^60 is below rounding).
BISECTION_STEPS = 60
#: The golden section's ratio, (sqrt 5 - 1) / 2.
GOLDEN = (5**0.5 - 1) / 2
#: A turning point of the search's error, or the end of a branch's domain, this close to zero is a root
#: [m].
TOUCHING_M = 1e-6
#: Solutions of one goal closer than this are one [rad] (a solution is found to ~1e-10 rad, to ~1e-8 where
#: two branches meet).
SAME_SOLUTION_RAD = 1e-7
#: A candidate reproducing the pose (position [m], rotation) or the SEW angle [rad] worse than this is
#: dropped.
RESIDUAL_TOLERANCE = 1e-9


def _maximise(f: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The x in [lo, hi] (M,) where f (unimodal there; NaN counts as -inf) is largest, by golden section.

    f is given both trial points of all M at once (2M,).
    """
    for _ in range(BISECTION_STEPS):
        m1, m2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
        f1, f2 = np.nan_to_num(f(np.concatenate([m1, m2])), nan=-np.inf).reshape(2, -1)
        higher = f2 >= f1
        lo, hi = np.where(higher, m1, lo), np.where(higher, hi, m2)
    return 0.5 * (lo + hi)


def _brackets(solver: _Solver, G: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(goal, branch, lo, hi) of every bracketed root of e on the grid of ``samples`` values of x.

    The grid covers the search's span, with the ends of each branch's domain, its turning points towards zero, and
    the branches that exist only between two samples (where the margin rises above zero) sampled too (module
    docstring).

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
        for column, value in zip(to, values, strict=True):
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
    """Every solution of each hand pose ``T`` (N, 4, 4, chain base frame) at its SEW angle ``psi``.

    ``psi`` is (N,) [rad]. See the module docstring; limits not applied; one :class:`SewSolutions` per pose.
    """
    T = np.asarray(T, dtype=float).reshape(-1, 4, 4)
    if not len(T):  # nothing to solve (a search with no candidate left)
        return []
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
    """Every solution of the hand pose ``T`` (4, 4, chain base frame) at SEW angle ``psi`` [rad].

    See the module docstring; limits not applied.
    """
    return solve_many(arm, T[None], np.array([psi]), sew, samples)[0]


def into_limits(Q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Each angle of Q (M, 7) moved by a multiple of 2 pi into [lower, upper] where one lands there.

    For limits that reach past +-pi. A joint without limits (continuous: -inf, inf) keeps its angle.
    """
    bounded = np.isfinite(lower)
    with np.errstate(invalid="ignore"):
        shifted = Q + 2 * np.pi * np.ceil((lower - Q) / (2 * np.pi))  # the smallest equivalent angle >= lower
    return np.where(bounded & (shifted <= upper), shifted, Q)


def candidate_table(robot: Robot, chain: Chain, T: np.ndarray, psi: float, sew: SewAngle) -> list[dict]:
    """``dualarm ik sew``'s rows: every solution of the pose ``T`` (chain base frame) at SEW angle ``psi``.

    Each with ``q`` [rad] (moved into the joint limits where an equivalent angle is), ``valid``, ``reason``
    ("valid" or the first joint outside its limits), the position [m] and orientation [rad] errors of the chain's
    forward kinematics, its SEW angle [rad], the search variable where it was found (``search_rad``: the upper
    arm's angle from S -> W, or q1) and its branch.

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
            else (
                f"outside limits: {chain.joint_names[outside[0]]} at {q[outside[0]]:.4f} "
                f"[{lower[outside[0]]:.4f}, {upper[outside[0]]:.4f}]"
            )
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

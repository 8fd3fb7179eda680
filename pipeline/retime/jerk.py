"""Jerk-limited, near time-optimal timing that stays on the joint path (``[retime] timing = "jerk-limited"``).

All active joints (both arms) follow ONE path parameter s, the cumulative joint-space chord length
[rad] (:func:`dualarm.retime.topp.chord_parameter`), and q(t) = P(s(t)) exactly: the trajectory
never leaves the path, whatever the timing.

The path is cut into pieces at its sharp turns: where the joint-space direction between
consecutive samples turns by more than acos(:data:`TURN_COSINE`) (the corners of a polygon the
hand draws, where the task brings the hand to rest), and at both ends. Each piece is timed rest to
rest, so the joints' velocities are continuous across the cuts.

P(s) on a piece is the interpolating spline of degree min(5, samples - 1) through its samples
(``scipy.interpolate.make_interp_spline``): with degree 5, q'''(s) is continuous, so the joint jerk
q''' = P'''(s) s'^3 + 3 P''(s) s' s'' + P'(s) s''' is bounded.

The timing of a piece is one nonlinear program (CasADi, solved by IPOPT; Debrouwere et al. 2013
set out time-optimal path following as such a program): on :data:`NODES` + 1 fixed values of s
(denser at both rest ends), the unknowns are the path velocity s' and acceleration s'' at each
node, and on each interval its duration and a constant path jerk s'''; s moves between nodes by
the exact triple integrator. The joint velocity, acceleration and jerk (the jerk with both
neighbouring intervals' s''') are kept within :data:`MARGIN` of the limits at every node, and the
total time is minimised. The program is built once per number of joints, the path's derivatives
being its parameters.

Between the nodes the limits can be exceeded a little; so each piece's timing is checked
analytically at :data:`CHECK_STEP_S` steps and on both sides of every node, and slowed down
uniformly by k = max(velocity ratio, sqrt(acceleration ratio), cbrt(jerk ratio)) where it exceeds
one (t -> k t scales the velocity by 1/k, the acceleration by 1/k^2, the jerk by 1/k^3).

A piece equal to an earlier one (within :data:`SAME_PIECE_RAD`: a repetition) reuses its timing, so
repeated paths give bit-identical repeated trajectories and are solved once.

Units: joint positions [rad], velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3], times
[s]; s in [rad].
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import casadi as cs
import numpy as np
from scipy.interpolate import BSpline, make_interp_spline

from dualarm.errors import StageError
from dualarm.ik.joint_path import JointPath
from dualarm.retime.timing import STAGE, Timing, still
from dualarm.retime.topp import chord_parameter

#: The path is cut where the direction between consecutive samples turns more than acos(this).
TURN_COSINE = 0.9
#: Intervals of a piece's program.
NODES = 40
#: Share of each limit the program may use at its nodes (the check takes up the rest).
MARGIN = 1 - 2e-3
#: Time step of the analytic check of each piece's limits [s].
CHECK_STEP_S = 1e-4
#: Pieces closer than this (every joint of every sample) share one timing [rad].
SAME_PIECE_RAD = 1e-10
#: IPOPT's settings: a monotone barrier from 1e-3 halved the solve time against the adaptive default on the triangle.
IPOPT = {"print_level": 0, "sb": "yes", "tol": 1e-8, "max_iter": 500, "mu_strategy": "monotone", "mu_init": 1e-3, "linear_solver": "mumps"}
#: IPOPT's return statuses that count as solved.
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass(frozen=True)
class PieceTiming:
    """The timing of one piece: s(t) piecewise cubic (constant path jerk per interval), run ``stretch`` times slower.

    Attributes:
        path: P(s) [rad], (n,) per s.
        s: the program's nodes (K + 1,) [rad].
        sd, sdd: s' [rad/s] and s'' [rad/s^2] at the nodes (K + 1,).
        sddd: s''' on each interval (K,) [rad/s^3].
        dt: each interval's duration (K,) [s].
        stretch: the uniform slow-down after the check (>= 1).
    """

    path: BSpline
    s: np.ndarray
    sd: np.ndarray
    sdd: np.ndarray
    sddd: np.ndarray
    dt: np.ndarray
    stretch: float = 1.0

    @property
    def starts_s(self) -> np.ndarray:
        """Each node's time before the stretch (K + 1,) [s]."""
        return np.concatenate([[0.0], np.cumsum(self.dt)])

    @property
    def duration_s(self) -> float:
        """The piece's duration [s]."""
        return self.stretch * float(self.dt.sum())

    def path_state(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        """The path state at times ``t`` (M,) [s] of the stretched piece: s [rad], s' [rad/s], s'' [rad/s^2], s''' [rad/s^3]."""
        starts, k = self.starts_s, self.stretch
        tau = np.clip(np.asarray(t, dtype=float) / k, 0.0, starts[-1])
        i = np.clip(np.searchsorted(starts, tau, side="right") - 1, 0, len(self.dt) - 1)
        h = tau - starts[i]
        s = self.s[i] + self.sd[i] * h + self.sdd[i] * h**2 / 2 + self.sddd[i] * h**3 / 6
        sd = self.sd[i] + self.sdd[i] * h + self.sddd[i] * h**2 / 2
        sdd = self.sdd[i] + self.sddd[i] * h
        return np.clip(s, self.s[0], self.s[-1]), sd / k, sdd / k**2, self.sddd[i] / k**3

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        """The joints at times ``t`` (M,) [s]: q [rad], qd [rad/s], qdd [rad/s^2] and the jerk [rad/s^3], each (M, n)."""
        s, sd, sdd, sddd = self.path_state(t)
        d1, d2, d3 = (self.path(s, m) for m in (1, 2, 3))
        return (
            self.path(s),
            d1 * sd[:, None],
            d2 * sd[:, None] ** 2 + d1 * sdd[:, None],
            d3 * sd[:, None] ** 3 + 3 * d2 * (sd * sdd)[:, None] + d1 * sddd[:, None],
        )

    def ratios(self, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray) -> tuple[float, float, float]:
        """The largest velocity, acceleration and jerk ratios, every :data:`CHECK_STEP_S` and on both sides of every node."""
        end = self.duration_s
        nodes = self.stretch * self.starts_s
        t = np.concatenate([np.linspace(0.0, end, max(50, int(end / CHECK_STEP_S)) + 1), np.clip(nodes - 1e-12, 0, end), np.clip(nodes + 1e-12, 0, end)])
        _, qd, qdd, qddd = self(np.sort(t))
        return float((np.abs(qd) / velocity).max()), float((np.abs(qdd) / acceleration).max()), float((np.abs(qddd) / jerk).max())


def jerk_limited(path: JointPath, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray) -> Timing:
    """The jerk-limited timing of ``path`` (module docstring).

    Args:
        path: the IK output, finite.
        velocity, acceleration, jerk: validated limits per joint (n,), symmetric [rad/s, rad/s^2, rad/s^3].

    Returns:
        A ``jerk-limited`` timing; a path that does not move gives one at rest of duration 0.

    Raises:
        StageError: IPOPT does not solve a piece's program (naming the piece's samples).
    """
    s, kept, of_sample = chord_parameter(path.q)
    if len(kept) == 1:
        return still(path, method="jerk-limited")
    q = path.q[kept]
    cuts = pieces(q)
    timings: list[PieceTiming] = []
    solved: list[tuple[np.ndarray, PieceTiming]] = []
    for first, last in zip(cuts[:-1], cuts[1:]):
        samples = q[first : last + 1]
        same = next((timing for earlier, timing in solved if earlier.shape == samples.shape and np.abs(earlier - samples).max() <= SAME_PIECE_RAD), None)
        if same is None:
            same = _time_piece(samples, s[first : last + 1] - s[first], velocity, acceleration, jerk, (int(kept[first]), int(kept[last])))
            solved.append((samples, same))
        timings.append(same)
    starts = np.concatenate([[0.0], np.cumsum([p.duration_s for p in timings])])
    evaluate = _Pieces(tuple(timings), starts)
    passes = np.concatenate([starts[i] + _passing(timings[i], s[cuts[i] : cuts[i + 1]] - s[cuts[i]]) for i in range(len(timings))] + [starts[-1:]])
    return Timing(
        method="jerk-limited",
        joint_names=path.joint_names,
        duration_s=float(starts[-1]),
        sample_times_s=passes[of_sample],
        rep=path.rep,
        evaluate=evaluate,
        stretch=max(p.stretch for p in timings),
        fixed=path.fixed,
    )


def pieces(q: np.ndarray) -> np.ndarray:
    """Where the distinct samples ``q`` (K, n) are cut: both ends and every sample where the direction turns more than acos(:data:`TURN_COSINE`) (increasing indices)."""
    step = np.diff(q, axis=0)
    direction = step / np.linalg.norm(step, axis=1, keepdims=True)
    turns = np.flatnonzero(np.einsum("ij,ij->i", direction[1:], direction[:-1]) < TURN_COSINE) + 1
    return np.concatenate([[0], turns, [len(q) - 1]])


@dataclass(frozen=True)
class _Pieces:
    """The pieces' timings one after the other: (t) -> (q, qd, qdd), each (M, n)."""

    pieces: tuple[PieceTiming, ...]
    starts: np.ndarray

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.starts[-1])
        which = np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        n = self.pieces[0].path.c.shape[-1]
        q, qd, qdd = (np.empty((len(t), n)) for _ in range(3))
        for i, piece in enumerate(self.pieces):
            mine = which == i
            if mine.any():
                q[mine], qd[mine], qdd[mine], _ = piece(t[mine] - self.starts[i])
        return q, qd, qdd


def _passing(piece: PieceTiming, s: np.ndarray) -> np.ndarray:
    """When the piece passes the path parameters ``s`` (M,) [s]: s(t) does not decrease at the nodes, so bisection on each."""
    lo, hi = np.zeros(len(s)), np.full(len(s), piece.duration_s)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        before = piece.path_state(mid)[0] < s
        lo, hi = np.where(before, mid, lo), np.where(before, hi, mid)
    return np.where(s <= piece.s[0], 0.0, hi)


def _time_piece(q: np.ndarray, s: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray, samples: tuple[int, int]) -> PieceTiming:
    """One piece's timing, its samples ``q`` (m, n) at chord lengths ``s`` (m,) [rad]: its program solved (:func:`_program`), then checked and stretched (module docstring)."""
    path = make_interp_spline(s, q, k=min(5, len(q) - 1))
    nodes = s[-1] * (1 - np.cos(np.linspace(0.0, np.pi, NODES + 1))) / 2  # denser at both rest ends
    d1, d2, d3 = (path(nodes, m) for m in (1, 2, 3))
    solver, lbg, ubg = _program(q.shape[1])
    cap = MARGIN * np.min(velocity / np.maximum(np.abs(d1), 1e-12), axis=1)  # s' within every joint's velocity limit
    sd0 = _first_guess(nodes, d1, d2, cap, MARGIN * acceleration)
    dt0 = 2 * np.diff(nodes) / np.maximum(sd0[:-1] + sd0[1:], 1e-6)
    sdd0 = np.append(np.diff(sd0) / dt0, 0.0)
    K = NODES
    lbx = np.concatenate([np.zeros(K + 1), np.full(K + 1, -np.inf), np.full(K, -np.inf), np.full(K, 1e-5)])
    ubx = np.concatenate([cap, np.full(K + 1, np.inf), np.full(K, np.inf), np.full(K, np.inf)])
    for end in (0, K):  # rest at both ends
        ubx[end] = lbx[K + 1 + end] = ubx[K + 1 + end] = 0.0
    parameters = np.concatenate([np.diff(nodes), *(d.T.ravel() for d in (d1, d2, d3)), 1 / acceleration, 1 / jerk])
    result = solver(x0=np.concatenate([sd0, sdd0, np.diff(sdd0) / dt0, dt0]), p=parameters, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    status = solver.stats()["return_status"]
    if status not in SOLVED:
        raise StageError(f"{STAGE}: jerk-limited: IPOPT did not time the piece from sample {samples[0]} to {samples[1]} ({status})", stage=STAGE, sample=samples[0])
    x = np.asarray(result["x"]).ravel()
    piece = PieceTiming(path, nodes, x[: K + 1], x[K + 1 : 2 * K + 2], x[2 * K + 2 : 3 * K + 2], x[3 * K + 2 :])
    rv, ra, rj = piece.ratios(velocity, acceleration, jerk)
    k = max(1.0, rv, np.sqrt(ra), np.cbrt(rj))
    return replace(piece, stretch=k * (1 + 1e-9) if k > 1 else 1.0)


@functools.lru_cache(maxsize=None)
def _program(n: int) -> tuple[cs.Function, np.ndarray, np.ndarray]:
    """A piece's program for ``n`` joints (module docstring): the IPOPT solver and the bounds of its constraints.

    Variables: s' (K + 1), s'' (K + 1), s''' (K), dt (K). Parameters: the nodes' spacing (K), P', P'',
    P''' at the nodes ((K + 1) x n each, column-major), 1 / the acceleration and 1 / the jerk limits (n each).
    """
    K = NODES
    sd, sdd, sddd, dt = cs.SX.sym("sd", K + 1), cs.SX.sym("sdd", K + 1), cs.SX.sym("sddd", K), cs.SX.sym("dt", K)
    ds = cs.SX.sym("ds", K)
    d1, d2, d3 = (cs.SX.sym(f"d{m}", K + 1, n) for m in (1, 2, 3))
    inverse_a, inverse_j = cs.SX.sym("inverse_a", n), cs.SX.sym("inverse_j", n)

    def columns(x: cs.SX) -> cs.SX:  # a value per node, for every joint
        return cs.repmat(x, 1, n)

    def rows(x: cs.SX, count: int) -> cs.SX:  # a value per joint, for every node
        return cs.repmat(x.T, count, 1)

    triple = [  # the exact triple integrator over each interval
        sd[:-1] * dt + sdd[:-1] * dt**2 / 2 + sddd * dt**3 / 6 - ds,
        sd[:-1] + sdd[:-1] * dt + sddd * dt**2 / 2 - sd[1:],
        sdd[:-1] + sddd * dt - sdd[1:],
    ]
    acc = (d2 * columns(sd**2) + d1 * columns(sdd)) * rows(inverse_a, K + 1)
    base = d3 * columns(sd**3) + 3 * d2 * columns(sd * sdd)
    jerks = [(base[at, :] + d1[at, :] * columns(sddd)) * rows(inverse_j, K) for at in (slice(0, K), slice(1, K + 1))]  # each node with the jerk after it, and before it
    g = cs.vertcat(*triple, cs.vec(acc), *(cs.vec(j) for j in jerks))
    bound = np.concatenate([np.zeros(3 * K), np.full((K + 1) * n + 2 * K * n, MARGIN)])
    lower = np.concatenate([np.zeros(3 * K), -bound[3 * K :]])
    problem = {"x": cs.vertcat(sd, sdd, sddd, dt), "p": cs.vertcat(ds, cs.vec(d1), cs.vec(d2), cs.vec(d3), inverse_a, inverse_j), "f": cs.sum1(dt), "g": g}
    solver = cs.nlpsol("jerk_limited", "ipopt", problem, {"print_time": False, **{f"ipopt.{k}": v for k, v in IPOPT.items()}})
    return solver, lower, bound


def _first_guess(s: np.ndarray, d1: np.ndarray, d2: np.ndarray, cap: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    """A starting s' (K + 1,) [rad/s] for the program: constant path acceleration between nodes within the velocity cap and the acceleration limits, backward then forward (numerical integration, as TOPP's), at 90 %."""
    ds = np.diff(s)
    moving = np.abs(d1) > 1e-12

    def bounds(k: int, b: float) -> tuple[float, float]:  # s'' allowed at node k for s'^2 = b
        m = moving[k]
        ends = np.stack([(-acceleration[m] - d2[k, m] * b) / d1[k, m], (acceleration[m] - d2[k, m] * b) / d1[k, m]])
        return float(ends.min(axis=0).max()), float(ends.max(axis=0).min())

    cap2 = cap**2
    back = np.zeros(len(s))
    for k in range(len(s) - 2, -1, -1):
        lo, hi = bounds(k + 1, back[k + 1])
        back[k] = min(cap2[k], back[k + 1] - 2 * ds[k] * min(lo, 0.0)) if lo < hi else 0.0
    forward = np.zeros(len(s))
    for k in range(len(s) - 1):
        lo, hi = bounds(k, forward[k])
        forward[k + 1] = min(back[k + 1], forward[k] + 2 * ds[k] * max(hi, 0.0))
    return 0.9 * np.sqrt(np.maximum(forward, 0.0))

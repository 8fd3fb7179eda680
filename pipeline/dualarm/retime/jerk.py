"""Jerk-limited, near time-optimal timing that stays on the joint path.

``[retime] timing = "jerk-limited"``, the default.

All active joints (both arms) follow ONE path parameter s, the cumulative joint-space chord length
[rad] (:func:`dualarm.retime.topp.chord_parameter`), and q(t) = P(s(t)) exactly: the trajectory
never leaves the curve P, whatever the timing.

Pieces (:func:`pieces`). The path is cut where the joint-space direction turns by more than
acos(:data:`TURN_COSINE`): between a sample's steps in and out, and between chords of at least
:data:`TURN_CHORD_RAD` before and after it (the corners of a polygon the hand draws and the
reversals of a gesture, where the task brings the hands to rest; a chord that long is not turned
by the IK's rounding noise, ~1e-7 rad between samples at rest). Each piece is timed rest to rest,
so the joints' velocities and accelerations are continuous (0) across the cuts.

The curve (:func:`fit`). P(s) on a piece is a quintic least-squares B-spline through both end
samples and within :data:`FIT_RAD` of every other (``scipy.interpolate.make_lsq_spline``, its
knots doubled until it fits). An interpolating spline would pass the IK's noise on to P''' (up
to 246 rad/rad^3 on the circle, against 8 for the fit) and so to the jerk. Where no spline fits
because samples near an end wander (a hook, ~1e-6 rad, while the task is at rest), those samples
become straight pieces of their own; where the samples wiggle further in (TV-GDD's wrist pitch on
the ball game, by up to 8e-5 rad with a 0.19 s period), P is the interpolating quintic, and the
timing slows down to keep its jerk. q''' = P''' s'^3 + 3 P'' s' s'' + P' s''' is bounded.

The timing of a piece. A straight piece (two samples) is timed by Ruckig on s, within the limits of
s that keep each joint within :data:`MARGIN` of its own: exact and time-optimal (:func:`_bounded`). So is a parabola
through three samples (a piece between two turns a sample apart), within limits of s that hold on the whole piece:
on the ball game's two, IPOPT took 76 and 201 iterations (0.35 and 0.76 s) for 5.6 and 7.9 ms of motion, Ruckig 3 ms
for 0.7 ms more each. Any other is one
nonlinear program (CasADi, solved by IPOPT; Debrouwere et al. 2013 set out time-optimal path
following as such a program): on K + 1 values of s, the nodes, the unknowns are the path velocity
s' and acceleration s'' at each node, and on each interval its duration and a constant path jerk
s'''; s moves between nodes by the exact triple integrator. The joint velocity, acceleration and
jerk (the jerk with both neighbouring intervals' s''') are kept within :data:`MARGIN` of the limits
at every node, and the total time is minimised. The program is solved in units of the piece's
length and its first guess's duration, where its unknowns are of order one. The solution's jerks
are then integrated exactly, after the least change that ends the piece at rest (:func:`_exact`).

The check. Between the nodes the limits can be exceeded; so each timing is checked analytically,
on both sides of every node and every :data:`REFINE_CHECK_STEP_S` while refining, every :data:`CHECK_STEP_S` at the
end. While refining, each interval where a limit is exceeded by
more than :data:`REFINE_ABOVE` is halved (in s), and the program solved again from the last
timing: from :data:`NODES` intervals (denser at both rest ends) up to :data:`MAX_NODES`. Once at most
:data:`TIGHTEN_AT_MOST` intervals exceed, those that exceed by at most :data:`HALVE_ABOVE` keep their nodes instead,
and the limits at both are tightened by the interval's slow-down: the same program, not built again, and a slow-down
there rather than the whole piece's stretch (the circle's last two of eight programs added 4 and 2 nodes, 0.2 s of its
0.87 s of compute). At each
node a program bounds the acceleration and jerk of only the :data:`LOADED` joints nearest their limits
in its first guess (:func:`_loaded`); the others' constraints only cost IPOPT time (the ball game, 14
joints: 1.34 s of compute per s of motion with all, 0.43 with 3, and with 2 its motion took 9.0 s, not
3.49). A joint left out that exceeds its limit is found by the check,
its interval refined and the joint selected there next. Then the ratios of every joint are bounded between each
two of those points (no peak between them passes the bound: :meth:`PieceTiming._bounds`), and what exceeds is
removed by a uniform slow-down of the piece,
k = max(velocity ratio, sqrt(acceleration ratio), cbrt(jerk ratio)) (t -> k t scales the velocity by 1/k, the
acceleration by 1/k^2, the jerk by 1/k^3).

A piece equal to an earlier one (within :data:`SAME_PIECE_RAD`: a repetition) reuses its timing, so
repeated paths give bit-identical repeated trajectories and are solved once.

Fallbacks (:func:`_time_piece`). When IPOPT does not solve a piece's first program, the program is
solved again from a first guess at :data:`WARM_START_SHARE` of its speed, and if that fails too the
piece is timed by Ruckig on s within limits of s that keep every joint within its own wherever on
the piece (:func:`_bounded`, feasible by construction). Either is reported
(:attr:`dualarm.retime.timing.Timing.fallbacks`, with the piece's duration and its velocity- and
acceleration-limited bound), so a finite path is always timed. A path that jumps is not a path:
:func:`dualarm.retime.stage.check_jumps` refuses it before it is timed.

Units: joint positions [rad], velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3], times
[s]; s in [rad].
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from math import factorial

import casadi as cs
import numpy as np
from ruckig import InputParameter, Ruckig, Trajectory
from scipy.interpolate import BSpline, make_interp_spline, make_lsq_spline
from scipy.optimize import lsq_linear

from dualarm.contracts.joint_path import JointPath
from dualarm.errors import StageError
from dualarm.retime.timing import STAGE, Fallback, Timing, still
from dualarm.retime.topp import chord_parameter

#: The path is cut where its direction turns more than acos(this) ...
TURN_COSINE = 0.9
#: ... between chords at least this long before and after a sample [rad].
TURN_CHORD_RAD = 1e-4
#: The path's spline P passes within this of every sample [rad] (half the 1e-6 rad the path may
#: deviate).
FIT_RAD = 5e-7
#: Intervals of a piece's first program ...
NODES = 40
#: ... and of its last: intervals exceeding a limit by more than REFINE_ABOVE (a share) are halved up to
#: this, ...
MAX_NODES = 400
REFINE_ABOVE = 1e-2
#: ... but once at most TIGHTEN_AT_MOST intervals exceed, those exceeding by at most HALVE_ABOVE have their nodes'
#: limits tightened instead (the same program solved again), in at most REFINE_ROUNDS programs after the first.
TIGHTEN_AT_MOST = 4
HALVE_ABOVE = 5e-2
REFINE_ROUNDS = 16
#: Programs are built with a multiple of this many intervals (:func:`_solve`): the bench's four paths needed 5 programs,
#: not 17, and the circle 46-47 ms of compute per s of motion, not 53-54 (a script timing ``plan`` as the bench does).
PROGRAM_STEP = 32
#: Share of each limit a program may use at its nodes (the check takes up the rest), and a straight piece
#: everywhere.
MARGIN = 1 - 2e-3
#: Time step of the analytic check of each piece's limits [s] (and of its bounds between the points), and of the
#: ratios that choose the refinements (the same durations as at 0.5 ms on the circle and the triangle; the circle's
#: checks took 67 ms, not 139).
CHECK_STEP_S = 5e-4
REFINE_CHECK_STEP_S = 2e-3
#: The final check looks between two of its points where the bound of the ratio between them could pass the largest
#: ratio (or 1) by more than ZOOM_ABOVE (a share), up to ZOOM_ROUNDS times, ZOOM_POINTS points at most each time
#: (:meth:`PieceTiming._peaks`).
ZOOM_ABOVE = 1e-7
ZOOM_ROUNDS = 4
ZOOM_POINTS = 100_000
#: At each node, the programs constrain the acceleration and jerk of this many joints, those nearest their limits in
#: the program's first guess (:func:`_loaded`); every joint's velocity, and the final check covers every joint.
LOADED = 3
#: Pieces closer than this (every joint of every sample) share one timing [rad].
SAME_PIECE_RAD = 1e-10
#: IPOPT's settings: a monotone barrier from 1e-3 halved the solve time against the adaptive default on the
#: triangle.
IPOPT = {
    "print_level": 0,
    "sb": "yes",
    "tol": 1e-8,
    "max_iter": 500,
    "mu_strategy": "monotone",
    "mu_init": 1e-3,
    "linear_solver": "mumps",
}
#: ... and those of a program solved from a timing on the same or coarser nodes, nearly optimal: the barrier from
#: 1e-6, the first guess pushed only 1e-6 into the bounds (the circle's programs took 160 IPOPT iterations, not 215).
IPOPT_WARM = {
    "mu_init": 1e-6,
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-6,
    "warm_start_mult_bound_push": 1e-6,
}
#: The fallbacks of a piece whose program IPOPT does not solve from its first guess, in order: the program from the
#: first guess at this share of its speed, then Ruckig on s within limits that hold wherever on the piece.
WARM_START_SHARE = 0.3
FALLBACKS = ("warm start", "worst-case limits")
#: Rounds of knot insertion around the samples a curve fitted within the position limits misses (:func:`within`), and
#: the weight of the third differences of its coefficients in that fit (relative to a sample's).
CLIP_REFINEMENTS = 8
BOUNDED_FIT_SMOOTHING = 1e-3
#: Points per knot interval where a piece's worst-case derivatives are taken (and at each knot).
WORST_CASE_POINTS = 16
#: IPOPT's return statuses that count as solved.
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass(frozen=True)
class PieceTiming:
    """The timing of one piece: s(t) piecewise cubic, run ``stretch`` times slower.

    Piecewise cubic: a constant path jerk per interval.

    Attributes:
        path: P(s) [rad], (n,) per s.
        s: s at each interval's start and at the end (K + 1,) [rad], from 0 to the piece's length.
        sd, sdd: s' [rad/s] and s'' [rad/s^2] there (K + 1,), 0 at both ends.
        sddd: s''' on each interval (K,) [rad/s^3].
        dt: each interval's duration (K,) [s].
        stretch: the uniform slow-down after the check (>= 1).
        fallback: how the piece was timed when the program failed from its first guess (:data:`FALLBACKS`), else
            "".
    """

    path: BSpline
    s: np.ndarray
    sd: np.ndarray
    sdd: np.ndarray
    sddd: np.ndarray
    dt: np.ndarray
    stretch: float = 1.0
    fallback: str = ""

    @property
    def starts_s(self) -> np.ndarray:
        """Each node's time before the stretch (K + 1,) [s]."""
        return np.concatenate([[0.0], np.cumsum(self.dt)])

    @property
    def duration_s(self) -> float:
        """The piece's duration [s]."""
        return self.stretch * float(self.dt.sum())

    def path_state(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        """The path state at times ``t`` (M,) [s] of the stretched piece.

        s [rad], s' [rad/s], s'' [rad/s^2], s''' [rad/s^3].
        """
        starts, k = self.starts_s, self.stretch
        tau = np.clip(np.asarray(t, dtype=float) / k, 0.0, starts[-1])
        i = np.clip(np.searchsorted(starts, tau, side="right") - 1, 0, len(self.dt) - 1)
        h = tau - starts[i]
        s = self.s[i] + self.sd[i] * h + self.sdd[i] * h**2 / 2 + self.sddd[i] * h**3 / 6
        sd = self.sd[i] + self.sdd[i] * h + self.sddd[i] * h**2 / 2
        sdd = self.sdd[i] + self.sddd[i] * h
        return np.clip(s, self.s[0], self.s[-1]), sd / k, sdd / k**2, self.sddd[i] / k**3

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        """The joints at times ``t`` (M,) [s].

        q [rad], qd [rad/s], qdd [rad/s^2] and the jerk [rad/s^3], each (M, n).
        """
        s, sd, sdd, sddd = self.path_state(t)
        return (self.path(s), *_chain([self.path(s, m) for m in (1, 2, 3)], sd, sdd, sddd))

    def excess(
        self, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray, bound: bool = True
    ) -> np.ndarray:
        """Each interval's slow-down to meet the limits (K,).

        max(velocity ratio, sqrt(acceleration ratio), cbrt(jerk ratio)) at the :meth:`check_times`, and with
        ``bound`` its upper bound between each two of them (:meth:`_bounds`), looked at more closely where it could
        pass the largest ratio or 1 (:meth:`_peaks`): a peak between two points 0.1 ms apart was 1.4e-5 of the jerk
        limit above both on an MC-Inverse path. Without, while refining, the ratios at the times.
        """
        nodes, t = self.stretch * self.starts_s, self.check_times(CHECK_STEP_S if bound else REFINE_CHECK_STEP_S)
        if bound:
            at, ratio = self._peaks(t, velocity, acceleration, jerk)
        else:
            at, ratio = t, _combined(self._shares(t, velocity, acceleration, jerk)[2])
        excess = np.zeros(len(self.dt))
        np.maximum.at(excess, np.clip(np.searchsorted(nodes, at, side="right") - 1, 0, len(self.dt) - 1), ratio)
        return excess

    def check_times(self, step_s: float) -> np.ndarray:
        """The times the check looks at (M,) [s], sorted.

        Every ``step_s``, on both sides of every node (s''' changes there), and where s passes each knot at which
        P^(4) changes at once (a quartic's or less: the bounds between two times need P four times differentiable).
        """
        end, path = self.duration_s, self.path
        knots, multiplicity = np.unique(path.t[path.k + 1 : -path.k - 1], return_counts=True)
        rough = _passing(self, knots[path.k - multiplicity < 4])  # where P^(4) jumps: a quartic, a cubic or less
        points = [np.clip(x + side, 0, end) for x in (self.stretch * self.starts_s, rough) for side in (-1e-12, 1e-12)]
        return np.sort(np.concatenate([np.linspace(0.0, end, max(50, int(end / step_s)) + 1), *points]))

    def _peaks(
        self, t: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """An upper bound of the ratio between each two consecutive times ``t`` (M,), and where (their middle).

        Where the bound could pass the largest ratio found (or 1) by more than :data:`ZOOM_ABOVE`, points are put
        between the two, as many as bring the bound's excess over the ratio at its ends (which falls with the square
        of their distance) to half that, and their bounds replace it; up to :data:`ZOOM_ROUNDS` times, with at most
        :data:`ZOOM_POINTS` points a time (the bounds that remain stand: the stretch they give is safe).
        """
        ratio, upper = self._bounds(t, velocity, acceleration, jerk)
        a, b, ends, level = t[:-1], t[1:], np.maximum(ratio[:-1], ratio[1:]), max(float(ratio.max()), 1.0)
        for _ in range(ZOOM_ROUNDS):
            zoom = upper > level * (1 + ZOOM_ABOVE)
            if not zoom.any():
                break
            n = np.ceil(np.sqrt(2 * (upper[zoom] - ends[zoom]) / (level * ZOOM_ABOVE)))
            n = np.maximum(2, (n * min(1.0, ZOOM_POINTS / n.sum())).astype(int))  # parts of each pair zoomed
            row = np.repeat(np.arange(len(n)), n + 1)
            part = (np.arange(len(row)) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)) / n[row]
            sub = a[zoom][row] + (b - a)[zoom][row] * part
            sub_ratio, sub_upper = self._bounds(sub, velocity, acceleration, jerk)
            level = max(level, float(sub_ratio.max()))
            inner = row[:-1] == row[1:]  # pairs within one zoomed pair
            a, b = np.concatenate([a[~zoom], sub[:-1][inner]]), np.concatenate([b[~zoom], sub[1:][inner]])
            ends = np.concatenate([ends[~zoom], np.maximum(sub_ratio[:-1], sub_ratio[1:])[inner]])
            upper = np.concatenate([upper[~zoom], sub_upper[inner]])
        return (a + b) / 2, upper

    def _bounds(
        self, t: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ratio at times ``t`` (M,), and an upper bound of it between each two consecutive ones (M - 1,).

        ``t`` sorted, with both sides of every node and of every knot where P^(4) changes at once among them
        (:meth:`check_times`).

        The ratio is max(velocity ratio, sqrt(acceleration ratio), cbrt(jerk ratio)) over the joints. Between two
        times h apart, |q^(m)| is at most the larger of its two values plus h^2 / 8 times a bound of |q^(m+2)| there:
        by Faa di Bruno's formula (s'''' = 0 within an interval), from bounds of |s'|, |s''|, |s'''| (s' quadratic,
        s'' linear, s''' constant) and of |P^(i)| (Taylor from the first time's s, with the largest |P^(5)| between,
        :meth:`_fifth`). Bounds, not estimates: no peak of the ratio between the times can pass them.
        """
        (s, sd, sdd, sddd), p, share = self._shares(t, velocity, acceleration, jerk, 5)
        h = np.diff(t)
        u3 = np.maximum(np.abs(sddd[:-1]), np.abs(sddd[1:]))
        u2 = np.maximum(np.abs(sdd[:-1]), np.abs(sdd[1:]))
        u1 = (np.maximum(np.abs(sd[:-1]), np.abs(sd[1:])) + h**2 * u3 / 8)[:, None]
        u2, u3 = u2[:, None], u3[:, None]
        w = h[:, None] * u1  # how far s can go between the times
        b5 = self._fifth(s)
        b4, b3, b2, b1 = (
            sum(np.abs(p[m + i][:-1]) * w**i / factorial(i) for i in range(4 - m))
            + b5 * w ** (4 - m) / factorial(4 - m)
            for m in (3, 2, 1, 0)
        )
        above = (  # bounds of |q'''|, |q''''|, |q^(5)| between the times
            b3 * u1**3 + 3 * b2 * u1 * u2 + b1 * u3,
            b4 * u1**4 + 6 * b3 * u1**2 * u2 + b2 * (3 * u2**2 + 4 * u1 * u3),
            b5 * u1**5 + 10 * b4 * u1**3 * u2 + b3 * (15 * u1 * u2**2 + 10 * u1**2 * u3) + 10 * b2 * u2 * u3,
        )
        upper = [
            np.maximum(x[:-1], x[1:]) + (h**2 / 8)[:, None] * bound / limit
            for x, bound, limit in zip(share, above, (velocity, acceleration, jerk), strict=True)
        ]
        return _combined(share), _combined(upper)

    def _fifth(self, s: np.ndarray) -> np.ndarray:
        """The largest |P^(5)| between each two consecutive path parameters ``s`` (M,), per joint (M - 1, n).

        P^(5) is constant between two knots: the largest over the knot intervals the two values span.
        """
        knots = np.unique(self.path.t)
        fifth = np.abs(self.path((knots[:-1] + knots[1:]) / 2, 5)) if self.path.k == 5 else np.zeros((1, 1))
        span = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(fifth) - 1)
        lo, hi = np.minimum(span[:-1], span[1:]), np.maximum(span[:-1], span[1:])
        largest = fifth[lo]
        for more in range(1, int((hi - lo).max(initial=0)) + 1):
            largest = np.maximum(largest, fifth[np.minimum(lo + more, hi)])
        return largest

    def _shares(
        self, t: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray, orders: int = 3
    ) -> tuple[tuple[np.ndarray, ...], list[np.ndarray], list[np.ndarray]]:
        """The path state at times ``t`` (M,), P's derivatives there and each joint's share of its limits.

        P^(1..orders) and |q'| / v, |q''| / a, |q'''| / j, each (M, n).
        """
        s, sd, sdd, sddd = state = self.path_state(t)
        n = self.path.c.shape[-1]
        p = [self.path(s, m) if m <= self.path.k else np.zeros((len(s), n)) for m in range(1, orders + 1)]
        q = _chain(p, sd, sdd, sddd)
        return state, p, [np.abs(x) / limit for x, limit in zip(q, (velocity, acceleration, jerk), strict=True)]


def _chain(
    p: list[np.ndarray], sd: np.ndarray, sdd: np.ndarray, sddd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q', q'', q''' (M, n) of q = P(s(t)), from P', P'', P''' at s (``p``) and s', s'', s''' (M,)."""
    d1, d2, d3 = p[:3]
    return (
        d1 * sd[:, None],
        d2 * sd[:, None] ** 2 + d1 * sdd[:, None],
        d3 * sd[:, None] ** 3 + 3 * d2 * (sd * sdd)[:, None] + d1 * sddd[:, None],
    )


def _combined(share: list[np.ndarray]) -> np.ndarray:
    """max(velocity share, sqrt(acceleration share), cbrt(jerk share)) (M,), the largest over the joints."""
    return np.max([share[0].max(axis=1), np.sqrt(share[1].max(axis=1)), np.cbrt(share[2].max(axis=1))], axis=0)


def jerk_limited(
    path: JointPath,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    position: tuple[np.ndarray, np.ndarray] | None = None,
) -> Timing:
    """The jerk-limited timing of ``path`` (module docstring).

    Args:
        path: the IK output, finite.
        velocity, acceleration, jerk: validated limits per joint (n,), symmetric [rad/s, rad/s^2, rad/s^3].
        position: the lower and upper position limits (n,) each [rad]: the curve stays within them wherever the
            samples do (:func:`within`); None: not bounded.

    Returns:
        A ``jerk-limited`` timing; a path that does not move gives one at rest of duration 0. The pieces timed by a
        fallback are its :attr:`~dualarm.retime.timing.Timing.fallbacks`.

    Never fails on a finite path: a piece whose program fails is timed by a fallback (:func:`_time_piece`).
    """
    s, kept, of_sample = chord_parameter(path.q)
    if len(kept) == 1:
        return still(path, method="jerk-limited")
    q = path.q[kept]
    cut = pieces(q, s, position)
    timings: list[PieceTiming] = []
    solved: list[tuple[np.ndarray, PieceTiming, float]] = []  # the samples, their timing, its fallback's bound
    fallbacks: list[Fallback] = []
    for first, last, curve in cut:
        samples = q[first : last + 1]
        same, bound = next(
            (
                (timing, bound)
                for earlier, timing, bound in solved
                if earlier.shape == samples.shape and np.abs(earlier - samples).max() <= SAME_PIECE_RAD
            ),
            (None, np.nan),
        )
        if same is None:
            same = _time_piece(curve, velocity, acceleration, jerk, (int(kept[first]), int(kept[last])))
            bound = _bound_s(curve, velocity, acceleration) if same.fallback else np.nan
            solved.append((samples, same, bound))
        if same.fallback:
            fallbacks.append(Fallback(int(kept[first]), int(kept[last]), same.fallback, same.duration_s, bound))
        timings.append(same)
    starts = np.concatenate([[0.0], np.cumsum([p.duration_s for p in timings])])
    evaluate = _Pieces(tuple(timings), starts)
    passes = np.concatenate(
        [
            start + _passing(timing, s[first:last] - s[first])
            for start, timing, (first, last, _) in zip(starts, timings, cut, strict=False)
        ]
        + [starts[-1:]]
    )
    return Timing(
        method="jerk-limited",
        joint_names=path.joint_names,
        duration_s=float(starts[-1]),
        sample_times_s=passes[of_sample],
        rep=path.rep,
        evaluate=evaluate,
        stretch=max(p.stretch for p in timings),
        fixed=path.fixed,
        fallbacks=tuple(fallbacks),
    )


def pieces(
    q: np.ndarray, s: np.ndarray, position: tuple[np.ndarray, np.ndarray] | None = None
) -> list[tuple[int, int, BSpline]]:
    """The pieces of the distinct samples ``q`` (K, n) at chord lengths ``s`` (K,) [rad], in order.

    Each one's first and last sample and its curve P over s - s[first] (module docstring).

    The path is cut at both ends and at its turns: at each sample whose step in and step out turn
    more than acos(:data:`TURN_COSINE`), and once in each run of samples whose chords in and out turn
    that much (at the sample that turns most), the chord in being from the last sample at least
    :data:`TURN_CHORD_RAD` before it (or the first), the chord out to the first sample at least as
    far after it (or the last). Then each piece gets its curve (:func:`fit`). Where none fits and
    it misses samples within :data:`TURN_CHORD_RAD` of an end (a hook), every sample from that end
    to the last it misses there is cut too, and the rest fitted again; where it misses only samples
    farther in, the curve is the interpolating quintic. Each curve is kept within the ``position``
    limits (:func:`within`); the samples of a polynomial through three that cannot be are joined by straight
    pieces.
    """
    index = np.arange(len(s))
    before = np.clip(np.searchsorted(s, s - TURN_CHORD_RAD, side="right") - 1, 0, None)
    after = np.minimum(np.searchsorted(s, s + TURN_CHORD_RAD, side="left"), len(s) - 1)
    cosine = np.ones(len(s))
    inner = (before < index) & (index < after)
    cosine[inner] = _cosines(q[index[inner]] - q[before[inner]], q[after[inner]] - q[index[inner]])
    runs = np.flatnonzero(
        np.diff(np.concatenate([[0], (cosine < TURN_COSINE).astype(int), [0]]))
    )  # where runs of turning samples start and end
    turns = [start + int(np.argmin(cosine[start:end])) for start, end in zip(runs[::2], runs[1::2], strict=True)]
    sharp = np.flatnonzero(_cosines(np.diff(q[:-1], axis=0), np.diff(q[1:], axis=0)) < TURN_COSINE) + 1
    cuts = np.unique(np.concatenate([[0], turns, sharp, [len(s) - 1]])).astype(int)
    done: list[tuple[int, int, BSpline]] = []
    todo = list(zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True))
    while todo:
        first, last = todo.pop()
        here, samples = s[first : last + 1] - s[first], q[first : last + 1]
        spline, miss = fit(here, samples)
        hook = np.flatnonzero(miss > FIT_RAD) + first  # the samples it misses
        start, end = hook[s[hook] - s[first] <= TURN_CHORD_RAD], hook[s[last] - s[hook] <= TURN_CHORD_RAD]
        if spline is None and not (len(start) or len(end)):  # wiggles further in: the interpolating quintic
            spline = make_interp_spline(here, samples, k=5)
        if spline is not None:
            bounded = within(spline, position, here, samples)
            if bounded is not None:
                done.append((first, last, bounded))
            else:  # a polynomial through three samples that leaves a limit: the straight lines between them
                todo += [(k, k + 1) for k in range(first, last)]
        else:  # hooks: cut every sample from each end to the last it misses there
            lo = max(int(start.max()), first + 1) if len(start) else first
            hi = max(lo, min(int(end.min()), last - 1)) if len(end) else last
            todo += (
                [(k, k + 1) for k in range(first, lo)]
                + ([(lo, hi)] if lo < hi else [])
                + [(k, k + 1) for k in range(hi, last)]
            )
    return sorted(done, key=lambda piece: piece[0])


def fit(s: np.ndarray, q: np.ndarray) -> tuple[BSpline | None, np.ndarray]:
    """A piece's curve P, and how far it misses each sample (m,) [rad].

    P is a quintic least-squares B-spline of the samples ``q`` (m, n) over ``s`` (m,) [rad] through both end samples
    and within :data:`FIT_RAD` of each.

    Its interior knots are equally spaced in (s / s[-1] + i / (m - 1)) / 2, i the sample's index (so
    denser where the samples are: where the task moves slowly, as it does where the path bends
    tightly), and at least :data:`TURN_CHORD_RAD` apart. Their number is doubled from 1 until the
    spline fits; with at most 6 samples the interpolating spline of degree m - 1 is P. None when no
    spline of at most min(m / 2, m - 5) intervals fits (the misses are then the densest one's).
    """
    m, k = len(s), 5
    if m <= k + 1:
        return make_interp_spline(s, q, k=m - 1), np.zeros(m)
    blend = (s / s[-1] + np.linspace(0.0, 1.0, m)) / 2
    weights = np.ones(m)
    weights[[0, -1]] = 1e6
    intervals, miss = 1, np.zeros(m)
    while intervals <= max(1, min(m // 2, m - k)):  # at most m coefficients: a least-squares problem
        inner = [s[0]]
        for knot in np.interp(np.linspace(0.0, 1.0, intervals + 1)[1:], blend, s):
            if knot - inner[-1] >= TURN_CHORD_RAD or knot == s[-1]:
                inner.append(knot)
        if inner[-2] > s[-1] - TURN_CHORD_RAD and len(inner) > 2:
            del inner[-2]
        spline = make_lsq_spline(s, q, np.concatenate([np.full(k, s[0]), inner, np.full(k, s[-1])]), k=k, w=weights)
        spline.c[[0, -1]] = q[[0, -1]]  # nearly so already (their weights): through both ends exactly, so pieces meet
        now = np.abs(spline(s) - q).max(axis=1)
        if not np.isfinite(now).all():  # knots without samples between them: no denser spline fits better
            break
        miss = now
        if miss.max() <= FIT_RAD:
            return spline, miss
        intervals *= 2
    return None, miss


def within(
    spline: BSpline, position: tuple[np.ndarray, np.ndarray] | None, s: np.ndarray, q: np.ndarray
) -> BSpline | None:
    """``spline`` kept within the ``position`` limits wherever its samples are, and on them where it can.

    ``position``: lower and upper (n,) [rad]; ``s`` (m,) [rad] and ``q`` (m, n) [rad]: the samples ``spline`` fits.

    A B-spline lies in the convex hull of its coefficients, so with every coefficient within a joint's limits
    (widened to any sample beyond them) the curve is within them everywhere, exactly. Where a coefficient is
    outside, a knot is inserted at the middle of every knot interval its B-spline spans, and each joint that had
    one is fitted again, the coefficients bounded by its limits (bounded-variable least squares,
    :func:`_bounded_fit`); while that misses a sample by more than :data:`FIT_RAD`, knots are inserted around the
    samples it misses and it is fitted again (up to :data:`CLIP_REFINEMENTS` times). The curve then bends onto
    the limit where the samples reach it, instead of overshooting between them; the last fit stands, and the
    retime stage measures what it misses as the path deviation. None for a curve of degree 2 or less that leaves
    the limits (one polynomial through at most three samples, whose P'' would jump at a new knot): its samples are
    then joined by straight pieces, which stay within. The end coefficients stay the end samples: pieces still
    meet.
    """
    if position is None:
        return spline
    lower = np.minimum(position[0], q.min(axis=0))
    upper = np.maximum(position[1], q.max(axis=0))
    outside = (spline.c < lower) | (spline.c > upper)
    if not outside.any():
        return spline
    if spline.k < 3:  # a new knot would leave a quadratic's P'' to jump there
        return None
    joints = np.flatnonzero(outside.any(axis=0))

    def bounded(spline: BSpline) -> BSpline:
        c = spline.c.copy()
        for joint in joints:
            c[:, joint] = _bounded_fit(spline, s, q[:, joint], lower[joint], upper[joint])
        return BSpline(spline.t, c, spline.k)

    spline = _insert_knots(spline, np.flatnonzero(outside.any(axis=1)))
    fitted = bounded(spline)
    for _ in range(CLIP_REFINEMENTS):
        missed = np.flatnonzero(np.abs(fitted(s) - q).max(axis=1) > FIT_RAD)
        if not len(missed):
            break
        span = np.searchsorted(spline.t, s[missed], side="right") - 1  # sample i is in [t[span], t[span + 1])
        spline = _insert_knots(spline, np.unique((span[:, None] - np.arange(spline.k + 1)).ravel()))
        fitted = bounded(spline)
    return fitted


def _insert_knots(spline: BSpline, coefficients: np.ndarray) -> BSpline:
    """``spline`` with a knot amid every nonempty knot interval the ``coefficients``' B-splines span."""
    t, k = spline.t, spline.k
    spans = np.unique((np.clip(coefficients, 0, len(spline.c) - 1)[:, None] + np.arange(k + 1)).ravel())
    middles = (t[spans] + t[spans + 1]) / 2  # coefficient i's B-spline spans t[i .. i+k+1]
    for x in np.unique(middles[t[spans + 1] > t[spans]]):
        spline = spline.insert_knot(x)
    return spline


def _bounded_fit(spline: BSpline, s: np.ndarray, y: np.ndarray, lower: float, upper: float) -> np.ndarray:
    """One joint's coefficients (N,): least squares to ``y`` (m,) [rad] at ``s`` on ``spline``'s knots.

    Each coefficient within [``lower``, ``upper``] [rad], the first and last the end samples (``scipy.optimize``'s
    bounded-variable least squares). Where the knots are denser than the samples, coefficients the samples do not
    determine are held by a small penalty (:data:`BOUNDED_FIT_SMOOTHING`) on their third differences.
    """
    basis = BSpline.design_matrix(s, spline.t, spline.k).toarray()
    c = np.zeros(basis.shape[1])
    c[[0, -1]] = y[[0, -1]]
    smooth = BOUNDED_FIT_SMOOTHING * np.sqrt(len(s) / len(c)) * np.diff(np.eye(len(c)), 3, axis=0)
    matrix = np.vstack([basis, smooth])
    target = np.concatenate([y, np.zeros(len(smooth))]) - matrix[:, [0, -1]] @ c[[0, -1]]
    inner = lsq_linear(matrix[:, 1:-1], target, bounds=(lower, upper), method="bvls", tol=1e-14, lsmr_tol=None).x
    c[1:-1] = np.clip(inner, lower, upper)
    return c


def _dense(path: BSpline, points: int = WORST_CASE_POINTS) -> np.ndarray:
    """Each knot of ``path``, and ``points`` - 1 points evenly between each two [rad]."""
    knots = np.unique(path.t)
    shares = np.arange(points) / points
    return np.append((knots[:-1, None] + shares * np.diff(knots)[:, None]).ravel(), knots[-1])


def _cosines(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cosine of the angle between each row of ``a`` and of ``b`` (M, n).

    1 where one is zero (a chord back to where the path was: the turn is a sharp one between those samples, cut
    there).
    """
    lengths = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    return np.divide(np.einsum("ij,ij->i", a, b), lengths, out=np.ones(len(a)), where=lengths > 0)


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
    """When the piece passes the path parameters ``s`` (M,) [s].

    s does not decrease from node to node: each value's interval by search, then bisection of the interval's cubic.
    """
    i = np.clip(np.searchsorted(piece.s, s, side="left") - 1, 0, len(piece.dt) - 1)
    s0, sd, sdd, sddd = piece.s[i], piece.sd[i], piece.sdd[i], piece.sddd[i]
    lo, hi = np.zeros(len(s)), piece.dt[i].copy()
    for _ in range(60):
        h = 0.5 * (lo + hi)
        before = s0 + sd * h + sdd * h**2 / 2 + sddd * h**3 / 6 < s
        lo, hi = np.where(before, h, lo), np.where(before, hi, h)
    return np.where(s <= piece.s[0], 0.0, piece.stretch * (piece.starts_s[i] + hi))


def _time_piece(
    path: BSpline, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray, samples: tuple[int, int]
) -> PieceTiming:
    """One piece's timing along its curve ``path`` (:func:`pieces`).

    Programs solved on nodes refined where the check finds a limit exceeded, then stretched (module docstring); the
    piece's ``samples`` (first, last) name it in errors. A straight piece or a parabola is Ruckig's (:func:`_bounded`).
    When IPOPT does not solve the first program, the fallbacks of :data:`FALLBACKS`: the program from the first guess
    slowed to :data:`WARM_START_SHARE` of its speed, then :func:`_bounded`, which cannot fail.
    """
    if path.k <= 2:  # a straight piece, or a parabola through three samples: Ruckig's (see the module docstring)
        return _bounded(path, velocity, acceleration, jerk)
    nodes = path.t[-1] * (1 - np.cos(np.linspace(0.0, np.pi, NODES + 1))) / 2  # denser at both rest ends
    fallback = ""
    try:
        piece = _solve(path, nodes, velocity, acceleration, jerk, samples, None)
    except StageError:
        try:
            fallback = FALLBACKS[0]
            piece = _solve(path, nodes, velocity, acceleration, jerk, samples, None, WARM_START_SHARE)
        except StageError:
            return replace(_bounded(path, velocity, acceleration, jerk), fallback=FALLBACKS[1])
    limits = np.ones(len(nodes))  # the share of its limits each node's constraints allow
    excess = piece.excess(velocity, acceleration, jerk, bound=False)
    for _ in range(REFINE_ROUNDS):
        over = excess > 1 + REFINE_ABOVE
        halve = over if over.sum() > TIGHTEN_AT_MOST else excess > 1 + HALVE_ABOVE
        if not over.any() or len(nodes) - 1 + halve.sum() > MAX_NODES:
            break
        tighten = np.flatnonzero(over & ~halve)
        for end in (tighten, tighten + 1):  # the interval's slow-down, at both its nodes
            np.minimum.at(limits, end, limits[end] / excess[tighten])
        middles = (nodes[:-1] + nodes[1:])[halve] / 2
        order = np.argsort(np.concatenate([nodes, middles]), kind="stable")
        nodes = np.concatenate([nodes, middles])[order]
        limits = np.concatenate([limits, np.minimum(limits[:-1], limits[1:])[halve]])[order]
        try:
            piece = _solve(path, nodes, velocity, acceleration, jerk, samples, piece, limits=limits)
        except StageError:  # a program IPOPT cannot solve: the last timing, stretched, stands
            break
        excess = piece.excess(velocity, acceleration, jerk, bound=False)
    k = float(piece.excess(velocity, acceleration, jerk).max())
    return replace(piece, stretch=k * (1 + 1e-9) if k > 1 else 1.0, fallback=fallback)


def _bounded(path: BSpline, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray) -> PieceTiming:
    """Ruckig's timing of s, rest to rest, within limits of s that keep every joint within its own.

    With D1, D2, D3 each joint's largest |P'|, |P''|, |P'''| on the piece (at its knots and
    :data:`WORST_CASE_POINTS` points between), and v, a, j its limits times :data:`MARGIN`, the limits of s are
    s' <= min(v / D1, sqrt(a / (2 D2)), cbrt(j / (3 D3))), then s'' <= min((a - D2 s'^2) / D1, j / (9 D2 s')),
    then s''' <= (j - D3 s'^3 - 3 D2 s' s'') / D1, which is at least j / (3 D1): so |q'| <= v,
    |q''| = |P'' s'^2 + P' s''| <= a and |q'''| = |P''' s'^3 + 3 P'' s' s'' + P' s'''| <= j wherever s is. Feasible
    by construction, and exact and time-optimal for a straight piece (D2 = D3 = 0). For a curve, the check
    stretches what the points between miss.
    """
    x = _dense(path)
    d1, d2, d3 = (np.abs(path(x, m)).max(axis=0) if m <= path.k else np.zeros(path.c.shape[-1]) for m in (1, 2, 3))
    v, a, j = (MARGIN * limit for limit in (velocity, acceleration, jerk))
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = np.nanmin(np.concatenate([v / d1, np.sqrt(a / (2 * d2)), np.cbrt(j / (3 * d3))]))
        sdd = np.nanmin(np.concatenate([(a - d2 * sd**2) / d1, j / (9 * d2 * sd)]))
        sddd = np.nanmin((j - d3 * sd**3 - 3 * d2 * sd * sdd) / d1)
    profile = rest_to_rest(0.0, path.t[-1], sd, sdd, sddd).profiles[0][0]
    used = np.flatnonzero(np.asarray(profile.t) > 0)  # Ruckig's seven phases, without those of no duration
    piece = _exact(path, np.asarray(profile.j)[used], np.asarray(profile.t)[used])
    if path.k == 1:  # P' constant: the limits of s hold the joints' exactly, no check needed
        return piece
    k = float(piece.excess(velocity, acceleration, jerk).max())
    return replace(piece, stretch=k * (1 + 1e-9) if k > 1 else 1.0)


def rest_to_rest(start: float, goal: float, velocity: float, acceleration: float, jerk: float) -> Trajectory:
    """Ruckig's time-optimal one-DOF move from ``start`` to ``goal``, at rest at both, within the limits.

    Positions [rad], limits [rad/s, rad/s^2, rad/s^3], finite and positive: within Ruckig's domain.
    """
    inp = InputParameter(1)
    inp.current_position, inp.target_position = [float(start)], [float(goal)]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [float(velocity)], [float(acceleration)], [float(jerk)]
    move = Trajectory(1)
    Ruckig(1).calculate(inp, move)
    return move


def _bound_s(path: BSpline, velocity: np.ndarray, acceleration: np.ndarray) -> float:
    """A piece's duration within the velocity and acceleration limits alone, jerk unlimited [s].

    The backward-forward integration of :func:`_first_guess` at the full limits on :data:`MAX_NODES` intervals.
    """
    nodes = np.linspace(0.0, path.t[-1], MAX_NODES + 1)
    d1, d2 = path(nodes, 1), path(nodes, 2)
    cap = np.min(velocity / np.maximum(np.abs(d1), 1e-12), axis=1)
    sd = _first_guess(nodes, d1, d2, cap, acceleration, share=1.0)
    return float(np.sum(2 * np.diff(nodes) / np.maximum(sd[:-1] + sd[1:], 1e-12)))


def _exact(path: BSpline, sddd: np.ndarray, dt: np.ndarray) -> PieceTiming:
    """The timing that starts at rest at s = 0 and applies the path jerks ``sddd`` for ``dt``, made exact.

    ``sddd`` (K,) [rad/s^3], ``dt`` (K,) [s].

    The solver meets its constraints to its tolerance (~1e-8); integrated as they are, the jerks
    would end the piece with s' and s'' of that order. So they are first changed by the least
    (in the least-squares sense) that ends the piece at rest exactly, then integrated exactly (so
    s(t) is twice continuously differentiable), and s is scaled to end exactly at the piece's
    length (a relative change of the solver's tolerance); the joints then meet the next piece's at
    rest, exactly.
    """
    sddd, dt = np.asarray(sddd, dtype=float), np.asarray(dt, dtype=float)
    remaining = dt.sum() - np.cumsum(dt)  # from each interval's end to the piece's end [s]
    effect = np.stack([dt * (dt / 2 + remaining), dt])  # d(s', s'' at the end) / d(each jerk)
    sddd = sddd - effect.T @ np.linalg.solve(effect @ effect.T, effect @ sddd)
    s, sd, sdd = np.zeros(len(dt) + 1), np.zeros(len(dt) + 1), np.zeros(len(dt) + 1)
    for i, (j, h) in enumerate(zip(sddd, dt, strict=True)):
        s[i + 1] = s[i] + sd[i] * h + sdd[i] * h**2 / 2 + j * h**3 / 6
        sd[i + 1] = sd[i] + sdd[i] * h + j * h**2 / 2
        sdd[i + 1] = sdd[i] + j * h
    scale = path.t[-1] / s[-1]
    return PieceTiming(path, scale * s, scale * sd, scale * sdd, scale * sddd, dt)


def _solve(
    path: BSpline,
    nodes: np.ndarray,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    samples: tuple[int, int],
    start: PieceTiming | None,
    share: float = 0.9,
    limits: np.ndarray | None = None,
) -> PieceTiming:
    """The program on ``nodes`` (K + 1,) [rad] along ``path`` solved (:func:`_program`), unstretched.

    From the timing ``start`` on the same or coarser nodes (or from :func:`_first_guess` at ``share`` of its speed).
    At each node, the acceleration and jerk of the :data:`LOADED` joints nearest their limits in that first guess are
    constrained (:func:`_loaded`), every joint's velocity: to :data:`MARGIN` times the node's ``limits`` (K + 1,) share
    of each (1 where None; the velocity times it, the acceleration times its square, the jerk its cube: the ratios of
    a slow-down by it). StageError naming the piece's ``samples`` if IPOPT fails.

    The program has K intervals rounded up to a multiple of :data:`PROGRAM_STEP`, those after the K null (no length,
    every unknown fixed at 0): the same timing, from a program built once per size rather than per refinement.
    """
    K = len(nodes) - 1
    limits = np.ones(K + 1) if limits is None else limits
    d1, d2, d3 = (path(nodes, m) for m in (1, 2, 3))
    cap = MARGIN * limits * np.min(velocity / np.maximum(np.abs(d1), 1e-12), axis=1)  # s' within the velocity limits
    if start is None:
        bends = (
            np.min(np.cbrt(jerk / np.maximum(np.abs(d3), 1e-12)), axis=1) / 2
        )  # s' where the path's third derivative alone asks 8 times the jerk limit
        sd0 = _first_guess(nodes, d1, d2, np.minimum(cap, bends), MARGIN * acceleration, share)
        dt0 = 2 * np.diff(nodes) / np.maximum(sd0[:-1] + sd0[1:], 1e-6)
        sdd0 = np.append(np.diff(sd0) / dt0, 0.0)
    else:
        passes = _passing(start, nodes)
        _, sd0, sdd0, _ = start.path_state(passes)
        # slowed down uniformly to within the velocity caps, which it may pass between its own nodes: clipping s'
        # instead would break the triple integrator there (by up to 6 % of the speed on the circle)
        k = max(1.0, float(np.max(sd0 / np.maximum(cap, 1e-300))))
        sd0, sdd0, dt0 = sd0 / k, sdd0 / k**2, np.maximum(np.diff(passes), 1e-5) * k
    sddd0 = np.diff(sdd0) / dt0
    slots = _loaded(d1, d2, d3, sd0, sdd0, sddd0, acceleration, jerk)
    size = PROGRAM_STEP * -(-K // PROGRAM_STEP)  # the program's intervals: the K nodes', then null ones
    solver, lbg, ubg = _program(slots.shape[1], size, warm=start is not None)
    lbg, ubg, null = lbg.copy(), ubg.copy(), np.zeros(size - K)
    for block in range(3):  # a null interval's integrator: free (its unknowns are all fixed at 0, and its ds is 0)
        lbg[block * size + K : (block + 1) * size], ubg[block * size + K : (block + 1) * size] = -np.inf, np.inf
    # The program runs in sigma = s / L and tau = t / T (the piece's length, the first guess's duration), where its
    # unknowns are of order one whatever the limits (a Panda's jerk limits are 5000 rad/s^3): the same program, with
    # P's derivatives times L, L^2, L^3 and the limits times T, T^2, T^3.
    L, T = float(nodes[-1]), float(dt0.sum())
    speed = L / T

    def padded(*blocks: np.ndarray) -> np.ndarray:  # the blocks of the K nodes or intervals, each then 0 for the null
        return np.concatenate([np.append(block, null) for block in blocks])

    def columns(values: np.ndarray) -> np.ndarray:  # (K + 1, m) at the nodes, 0 at the null ones, column-major
        return np.vstack([values, np.zeros((size - K, values.shape[1]))]).T.ravel()

    lbx = padded(np.zeros(K + 1), np.full(K + 1, -np.inf), np.full(K, -np.inf), np.full(K, 1e-5 / T))
    ubx = padded(cap / speed, np.full(K + 1, np.inf), np.full(K, np.inf), np.full(K, np.inf))
    for end in (0, K):  # rest at both ends
        ubx[end] = lbx[size + 1 + end] = ubx[size + 1 + end] = 0.0
    node = np.arange(K + 1)[:, None]
    parameters = np.concatenate(
        [
            padded(np.diff(nodes) / L),
            *(columns(d[node, slots] * L**m) for m, d in ((1, d1), (2, d2), (3, d3))),
            columns(1 / (acceleration[slots] * (limits[:, None] * T) ** 2)),
            columns(1 / (jerk[slots] * (limits[:, None] * T) ** 3)),
        ]
    )
    x0 = padded(sd0 / speed, sdd0 * T / speed, sddd0 * T**2 / speed, dt0 / T)
    result = solver(x0=x0, p=parameters, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    status = solver.stats()["return_status"]
    if status not in SOLVED:
        raise StageError(
            f"{STAGE}: jerk-limited: IPOPT did not time the piece from sample {samples[0]} to {samples[1]} ({status})",
            stage=STAGE,
            sample=samples[0],
        )
    x = np.asarray(result["x"]).ravel()
    return _exact(path, x[2 * size + 2 : 2 * size + 2 + K] * speed / T**2, x[3 * size + 2 : 3 * size + 2 + K] * T)


def _loaded(
    d1: np.ndarray,
    d2: np.ndarray,
    d3: np.ndarray,
    sd: np.ndarray,
    sdd: np.ndarray,
    sddd: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
) -> np.ndarray:
    """At each node, the :data:`LOADED` joints nearest their acceleration or jerk limit (K + 1, LOADED).

    P's derivatives ``d1``, ``d2``, ``d3`` at the nodes (K + 1, n); the path velocity ``sd`` and acceleration ``sdd``
    there (K + 1,) and the path jerk ``sddd`` on each interval (K,). A joint's load is max(sqrt(acceleration ratio),
    cbrt(jerk ratio)), the jerk with the interval after the node and with the one before: the slow-down it would ask
    (as :meth:`PieceTiming.excess`). Joint indices, ascending per node; all joints when there are at most
    :data:`LOADED`.
    """
    n = d1.shape[1]
    if n <= LOADED:
        return np.tile(np.arange(n), (len(sd), 1))
    base = d3 * sd[:, None] ** 3 + 3 * d2 * (sd * sdd)[:, None]
    load = np.sqrt(np.abs(d2 * sd[:, None] ** 2 + d1 * sdd[:, None]) / acceleration)
    load[:-1] = np.maximum(load[:-1], np.cbrt(np.abs(base[:-1] + d1[:-1] * sddd[:, None]) / jerk))
    load[1:] = np.maximum(load[1:], np.cbrt(np.abs(base[1:] + d1[1:] * sddd[:, None]) / jerk))
    return np.sort(np.argsort(-load, axis=1, kind="stable")[:, :LOADED], axis=1)


@functools.cache
def _program(m: int, K: int, warm: bool = False) -> tuple[cs.Function, np.ndarray, np.ndarray]:
    """A piece's program on ``K`` intervals, ``m`` joints constrained at each node (module docstring).

    The IPOPT solver (with :data:`IPOPT_WARM` when ``warm``) and the bounds of its constraints.

    Variables: s' (K + 1), s'' (K + 1), s''' (K), dt (K). Parameters: the nodes' spacing (K); P', P'', P''' of each
    node's constrained joints, 1 / their acceleration and 1 / their jerk limits ((K + 1) x m each, column-major).
    """
    sd, sdd, sddd, dt = cs.SX.sym("sd", K + 1), cs.SX.sym("sdd", K + 1), cs.SX.sym("sddd", K), cs.SX.sym("dt", K)
    ds = cs.SX.sym("ds", K)
    d1, d2, d3, inverse_a, inverse_j = (cs.SX.sym(name, K + 1, m) for name in ("d1", "d2", "d3", "ia", "ij"))

    def columns(x: cs.SX) -> cs.SX:  # a value per node, for every constrained joint
        return cs.repmat(x, 1, m)

    triple = [  # the exact triple integrator over each interval
        sd[:-1] * dt + sdd[:-1] * dt**2 / 2 + sddd * dt**3 / 6 - ds,
        sd[:-1] + sdd[:-1] * dt + sddd * dt**2 / 2 - sd[1:],
        sdd[:-1] + sddd * dt - sdd[1:],
    ]
    acc = (d2 * columns(sd**2) + d1 * columns(sdd)) * inverse_a
    base = d3 * columns(sd**3) + 3 * d2 * columns(sd * sdd)
    jerks = [
        (base[at, :] + d1[at, :] * columns(sddd)) * inverse_j[at, :] for at in (slice(0, K), slice(1, K + 1))
    ]  # each node with the jerk after it, and before it
    g = cs.vertcat(*triple, cs.vec(acc), *(cs.vec(j) for j in jerks))
    bound = np.concatenate([np.zeros(3 * K), np.full((K + 1) * m + 2 * K * m, MARGIN)])
    lower = np.concatenate([np.zeros(3 * K), -bound[3 * K :]])
    problem = {
        "x": cs.vertcat(sd, sdd, sddd, dt),
        "p": cs.vertcat(ds, *(cs.vec(x) for x in (d1, d2, d3, inverse_a, inverse_j))),
        "f": cs.sum1(dt),
        "g": g,
    }
    solver = cs.nlpsol(
        "jerk_limited",
        "ipopt",
        problem,
        {"print_time": False, **{f"ipopt.{k}": v for k, v in {**IPOPT, **(IPOPT_WARM if warm else {})}.items()}},
    )
    return solver, lower, bound


def _first_guess(
    s: np.ndarray, d1: np.ndarray, d2: np.ndarray, cap: np.ndarray, acceleration: np.ndarray, share: float = 0.9
) -> np.ndarray:
    """A starting s' (K + 1,) [rad/s] for the program.

    Constant path acceleration between nodes within the velocity cap and the acceleration limits, backward then
    forward (numerical integration, as TOPP's), at ``share`` of the speed.
    """
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
    return share * np.sqrt(np.maximum(forward, 0.0))

"""An "ikfast-style" analytic IK baseline for 7-DOF S-R-S arms: a free joint, discretised.

IKFast (Diankov, OpenRAVE) 7-DOF handling: free joint discretised. IKFast solves only 6-DOF
problems in closed form; for a 7-DOF arm one joint is declared *free*, the generated solver takes
its value as an input, and the caller sweeps that value over its range at a fixed increment and
keeps the solution it likes best (here: the one nearest the previous configuration). The
MC-Inverse paper (Zou, Min, Xu, *MC-Inverse: An Analytical Method for Consistent Motion of
Anthropomorphic Dual-arm Robot*) compares against exactly this scheme as its baseline "ikfast".

The free joint is the third one (index 2, the upper-arm roll), the usual IKFast choice for
KUKA-iiwa-like arms. With theta_3 fixed the other six joints are solved in closed form, in the
product-of-exponentials form of :mod:`dualarm.ik.analytic.mc_inverse` (k_i the joint axes at the zero
configuration in the chain base frame, shoulder axes through S):

- elbow theta_4 from |W - S| (MC-Inverse eqs 2-4, law of cosines): two roots, elbow = +-1;
- shoulder theta_1, theta_2 from exp(k1 t1) exp(k2 t2) v = W - S with
  v = exp(k3 t3) (E0 - S + exp(k4 t4) (W0 - E0)): Paden-Kahan sub-problem 2 (two rotations about
  intersecting axes), two roots +-gamma, none when gamma^2 < 0 (this free value cannot reach W);
- wrist theta_5..7 from the remaining rotation, exactly as MC-Inverse's sub-problem 3: two roots.

That is 2 x 2 x 2 = 8 candidates per (pose, theta_3), with the reason codes of
:data:`dualarm.ik.analytic.mc_inverse.REASONS`. Everything is one CasADi Function
``(T (4x4), theta3) -> (Q (7x8), reason (1x8))``; :meth:`IkfastStyle.nearest` evaluates it at every
free value for one pose in one mapped call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache, cached_property

import casadi as cs
import numpy as np

from dualarm.ik.analytic.mc_inverse import (
    CANDIDATES,
    OUT_OF_REACH,
    OUTSIDE_LIMITS,
    REASONS,
    SINGULAR,
    SINGULAR_SINE,
    VALID,
    McInverse,
    McSolution,
)
from dualarm.ik.analytic.subproblems import (
    REACH_SLACK,
    elbow,
    euler,
    into_limits,
    rotate,
    rotation,
    subproblem2,
    zero_axes,
)
from dualarm.model.robot import Chain
from dualarm.model.srs import SrsKinematics
from dualarm.numerics.batched import BatchedCandidates
from dualarm.numerics.compiled import compiled

__all__ = ["FREE_JOINT", "IkfastResult", "IkfastStyle", "CANDIDATES", "REASONS"]

#: Index of the free (discretised) joint: theta_3, the upper-arm roll.
FREE_JOINT = 2
#: Default discretisation step of the free joint [rad] (IKFast's usual free increment).
DEFAULT_RESOLUTION_RAD = 0.01


def _free_grid(lower: float, upper: float, resolution: float) -> np.ndarray:
    """Values of the free joint from ``lower`` to ``upper`` [rad], both included.

    Evenly spaced at most ``resolution`` [rad] apart (+-pi for an unlimited joint).
    """
    lo = lower if np.isfinite(lower) else -np.pi
    hi = upper if np.isfinite(upper) else np.pi
    if hi <= lo:
        return np.array([lo])
    return np.linspace(lo, hi, int(math.ceil((hi - lo) / resolution - 1e-9)) + 1)


def _candidates(
    kin: SrsKinematics, k: list[np.ndarray], tip0: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> cs.Function:
    """The CasADi Function ``(T (4x4) [m], theta3 [rad]) -> (Q (7x8) [rad], reason (1x8))``."""
    S, E0, W0 = (np.asarray(x).ravel() for x in kin.points(np.zeros(7)))

    T, theta3 = cs.SX.sym("T", 4, 4), cs.SX.sym("theta3")
    R = T[:3, :3]
    a3, a4 = k[2], k[3]
    # sub-problem 1 (MC-Inverse eqs 2-4): the wrist centre and the elbow from |SW|, independent of the free joint
    W, sw, d, out_of_reach_elbow, beta, elbows = elbow(kin.geometry, S, E0, W0, a4, T)
    singular_elbow = cs.sin(beta) < SINGULAR_SINE  # straight or folded elbow
    c3, s3 = cs.cos(theta3), cs.sin(theta3)

    columns, reasons = [], []
    for theta4 in elbows:
        c4, s4 = cs.cos(theta4), cs.sin(theta4)
        # S -> W with the shoulder at zero and theta3, theta4 applied
        v = rotate(a3, c3, s3, cs.SX(E0 - S) + rotate(a4, c4, s4, cs.SX(W0 - E0)))
        # Paden-Kahan sub-problem 2: exp(k1 t1) exp(k2 t2) v = W - S
        shoulders, gamma2, s_gamma = subproblem2(k[0], k[1], v, sw)
        out_of_reach = cs.logic_or(out_of_reach_elbow, gamma2 < -REACH_SLACK)
        # t1 undefined with W on axis 1, t2 with v on axis 2; the two roots merge at gamma = 0
        s_axes = cs.fmin(cs.norm_2(cs.cross(k[0], sw)) / d, cs.norm_2(cs.cross(k[1], v)) / cs.norm_2(v))
        singular_shoulder = cs.fmin(s_axes, s_gamma) < SINGULAR_SINE
        forearm = rotation(a3, c3, s3) @ rotation(a4, c4, s4)
        for t1, t2 in shoulders:
            arm = rotation(k[0], cs.cos(t1), cs.sin(t1)) @ rotation(k[1], cs.cos(t2), cs.sin(t2)) @ forearm
            wrists, s_wrist = euler(arm.T @ R @ tip0.T, k[4], k[5], k[6])  # sub-problem 3 (MC-Inverse)
            singular = cs.logic_or(cs.logic_or(singular_elbow, singular_shoulder), s_wrist < SINGULAR_SINE)
            for t5, t6, t7 in wrists:
                solved = (t1, t2, theta3, theta4, t5, t6, t7)
                q = cs.vertcat(
                    *[
                        a if i == FREE_JOINT else into_limits(a, lo, hi)
                        for i, (a, lo, hi) in enumerate(zip(solved, lower, upper, strict=True))
                    ]
                )
                outside = cs.logic_or(cs.mmax(q - upper) > 0, cs.mmax(lower - q) > 0)
                reasons.append(
                    cs.if_else(
                        out_of_reach,
                        OUT_OF_REACH,
                        cs.if_else(singular, SINGULAR, cs.if_else(outside, OUTSIDE_LIMITS, VALID)),
                    )
                )
                columns.append(q)
    return compiled(
        cs.Function(
            "ikfast_style",
            [T, theta3],
            [cs.horzcat(*columns), cs.horzcat(*reasons)],
            ["T", "theta3"],
            ["Q", "reason"],
            {"cse": True},
        )
    )


@dataclass(frozen=True)
class IkfastStyle:
    """The ikfast-style solver of one S-R-S arm chain: theta_3 free, the rest in closed form.

    Attributes:
        kinematics: S, E, W of the chain (shared with :class:`McInverse`).
        lower, upper: joint limits [rad], (7,).
        free_values: the grid of theta_3 values [rad], (F,), from its lower to its upper limit,
            both included, evenly spaced at most the resolution apart.
        candidates: Function ``(T (4x4) hand pose in the chain base frame [m], theta3 [rad]) ->
            (Q (7x8) [rad], reason (1x8))``; column j is the candidate with index
            4 * elbow + 2 * shoulder + wrist (each 0 for the first root), reason one of
            :data:`REASONS`; row 2 of Q is theta3 as given.
    """

    kinematics: SrsKinematics
    lower: np.ndarray
    upper: np.ndarray
    free_values: np.ndarray
    candidates: cs.Function

    @property
    def chain(self) -> Chain:
        """The arm chain."""
        return self.kinematics.geometry.chain

    @property
    def resolution_rad(self) -> float:
        """Spacing of :attr:`free_values` [rad]."""
        return float(self.free_values[1] - self.free_values[0]) if len(self.free_values) > 1 else 0.0

    @classmethod
    def of(cls, chain: Chain, resolution_rad: float = DEFAULT_RESOLUTION_RAD) -> IkfastStyle:
        """The solver for ``chain`` with theta_3 discretised at ``resolution_rad`` [rad].

        Derived once per chain and resolution in a process, then kept.

        Raises:
            NotSRSError: the chain is not S-R-S, or consecutive shoulder or wrist axes are not
                perpendicular (the checks of :meth:`McInverse.of`).
        """
        if not resolution_rad > 0:
            raise ValueError(f"resolution_rad must be positive, got {resolution_rad}")
        return _solver(chain, float(resolution_rad))

    @classmethod
    def _derive(cls, chain: Chain, resolution_rad: float) -> IkfastStyle:
        """Derive the solver (see :meth:`of`)."""
        mc = McInverse.of(chain)  # validates the chain
        k, tip0 = zero_axes(chain)
        return cls(
            kinematics=mc.kinematics,
            lower=mc.lower,
            upper=mc.upper,
            free_values=_free_grid(mc.lower[FREE_JOINT], mc.upper[FREE_JOINT], resolution_rad),
            candidates=_candidates(mc.kinematics, k, tip0, mc.lower, mc.upper),
        )

    def solve(self, pose: np.ndarray, theta3: float) -> McSolution:
        """All 8 candidates for one hand pose (4x4, chain base frame) [m] at ``theta3`` [rad]."""
        Q, reason = self.candidates(np.asarray(pose, dtype=float), float(theta3))
        return McSolution(q=np.asarray(Q).T.copy(), reason=np.asarray(reason).ravel().astype(int))

    def solve_many(self, poses: np.ndarray, theta3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates for N poses (N, 4, 4) [m] at free values theta3 (N,) [rad], in mapped calls.

        Returns:
            q (N, 8, 7) [rad] and reason codes (N, 8).
        """
        return self._batched.candidates(poses, theta3)

    def valid_candidates(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The valid candidates of one hand pose (4x4, chain base frame) [m] over all free values.

        In one mapped call over the F x 8 candidates.

        Returns:
            q (M, 7) [rad], in the order of the free values, then of the candidates, and the free
            value each was solved at (M,) [rad].
        """
        F = len(self.free_values)
        q, reason = self._batched.candidates(
            np.broadcast_to(np.asarray(pose, dtype=float), (F, 4, 4)), self.free_values
        )
        valid = (reason == VALID).ravel()
        return q.reshape(-1, 7)[valid], np.repeat(self.free_values, CANDIDATES)[valid]

    def nearest(
        self, pose: np.ndarray, previous: np.ndarray, candidates: tuple[np.ndarray, np.ndarray] | None = None
    ) -> IkfastResult:
        """The valid candidate over all free values nearest ``previous`` (7,) [rad] for one hand pose.

        Nearest by Euclidean joint distance, the first of equals; the hand pose is 4x4, chain base frame [m].

        ``candidates``: the pose's :meth:`valid_candidates`, if known (they do not depend on ``previous``).
        """
        previous = np.asarray(previous, dtype=float)
        q, free = self.valid_candidates(pose) if candidates is None else candidates
        if not len(q):
            return IkfastResult(q=previous.copy(), ok=False, free_value=float("nan"))
        best = int(np.argmin(np.einsum("ij,ij->i", q - previous, q - previous)))
        return IkfastResult(q=q[best].copy(), ok=True, free_value=float(free[best]))

    @cached_property
    def _batched(self) -> BatchedCandidates:
        return BatchedCandidates(self.candidates, chunk=len(self.free_values))


@dataclass(frozen=True)
class IkfastResult:
    """Result of :meth:`IkfastStyle.nearest`.

    Attributes:
        q: the chosen joint values [rad], (7,); ``previous`` when nothing is valid.
        ok: a valid candidate was found at some free value.
        free_value: the theta_3 grid value [rad] the candidate was solved at (NaN when not ok).
    """

    q: np.ndarray
    ok: bool
    free_value: float


@cache
def _solver(chain: Chain, resolution_rad: float) -> IkfastStyle:
    return IkfastStyle._derive(chain, resolution_rad)

"""MC-Inverse: closed-form inverse kinematics of an S-R-S arm at a given arm angle.

Zou, Min, Xu, *MC-Inverse: An Analytical Method for Consistent Motion of Anthropomorphic Dual-arm
Robot*, section III.B. For a hand pose (p, R) and an arm angle psi the arm has 8 joint solutions:
two elbow angles (sub-problem 1, eqs 2-4), and for each two shoulder (sub-problem 2, eqs 5-10) and
two wrist (sub-problem 3) triples.

The paper writes sub-problems 2 and 3 for its HR2 arm, whose shoulder and wrist are ZYZ Euler
joints. Here they are written for any S-R-S chain read from a URDF. The forward kinematics is a
product of exponentials: the rotation of the frame after joint i is
exp(k_1 theta_1) ... exp(k_i theta_i) R_i(0), where k_i is joint i's axis at the zero configuration
in the chain base frame. Sub-problems 2 and 3 then become "Euler angles about three arbitrary
axes":

    Q = exp(k_a theta_a) exp(k_b theta_b) exp(k_c theta_c).

The middle angle solves k_a . exp(k_b theta_b) k_c = k_a . Q k_c, which has two roots; for the
ZYZ axes these are eqs (9) and (10). The outer angles are rotations of one known vector onto
another about a known axis. Each joint's sign and offset against the canonical model are absorbed
by the zero-configuration axes k_i and the elbow's zero angle. These are derived from the chain
when it is loaded, and the solver is checked against the chain's own forward kinematics.

The solver requires consecutive shoulder axes and consecutive wrist axes to be perpendicular, as
in every S-R-S arm of the papers. A chain that is not S-R-S is refused with the axes at fault
named.

Everything is one CasADi Function, ``(T (4x4), psi) -> (Q (7x8), reason (1x8))``, which can be
mapped over a whole path in one call.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property

import casadi as cs
import numpy as np

from pipeline.errors import NotSRSError
from pipeline.model.kinematics import chain_frames
from pipeline.model.robot import Chain
from pipeline.model.srs import SrsKinematics

#: Candidate order: index = 4 * elbow + 2 * shoulder + wrist, each 0 (the first root: theta_4 =
#: beta - phi_0, or the middle Euler angle with sine >= 0 from its singular position) or 1.
CANDIDATES = 8

#: Validity codes of a candidate, in order of precedence.
VALID, OUT_OF_REACH, SINGULAR, OUTSIDE_LIMITS = 0, 1, 2, 3
#: SINGULAR: the elbow is straight, the shoulder-wrist line is vertical (no reference plane), or a
#: shoulder or wrist middle joint aligns the outer two axes; the solution is not isolated there.
REASONS = {VALID: "valid", OUT_OF_REACH: "out of reach", SINGULAR: "singular", OUTSIDE_LIMITS: "outside limits"}

#: Sine below which an elbow, shoulder or wrist counts as singular (the solution is not isolated).
SINGULAR_SINE = 1e-7
#: Relative slack on the law-of-cosines argument before a wrist centre counts as out of reach.
REACH_SLACK = 1e-12
#: Largest cosine between two axes that count as perpendicular.
PERPENDICULAR_COSINE = 1e-9
#: Poses per mapped call in :meth:`McInverse.solve_many` (building a map costs time in its size,
#: so one map of this size is built per solver and reused).
MAP_CHUNK = 4096
#: Threads that share a mapped call (one per core).
MAP_THREADS = os.cpu_count() or 1


def _hat(k: np.ndarray) -> np.ndarray:
    return np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])


def _rotation(k: np.ndarray, c, s) -> cs.SX:
    """exp([k] angle) for a constant unit axis ``k``, given c = cos and s = sin of the angle (Rodrigues)."""
    K = _hat(k)
    return cs.SX.eye(3) + s * K + (1 - c) * (K @ K)


def _rotate(k: np.ndarray, c, s, x):
    """exp([k] angle) x for a constant unit axis ``k``, given c = cos and s = sin of the angle (Rodrigues)."""
    return c * x + s * cs.cross(k, x) + (1 - c) * cs.dot(k, x) * k


def _turn(k: np.ndarray, p, q):
    """Angle about unit axis ``k`` that turns vector p onto vector q (Paden-Kahan sub-problem 1)."""
    return cs.atan2(cs.dot(k, cs.cross(p, q)), cs.dot(p, q) - cs.dot(k, p) * cs.dot(k, q))


def _euler(Q, ka: np.ndarray, kb: np.ndarray, kc: np.ndarray):
    """Both solutions of Q = exp(ka ta) exp(kb tb) exp(kc tc) for perpendicular ka, kb and kb, kc
    (eqs 9 and 10 for ZYZ axes): a list of two (ta, tb, tc), and |sin| of the middle angle
    measured from its singular positions (0 where ta and tc are not separable)."""
    phi = float(np.arctan2(ka @ np.cross(kb, kc), ka @ kc))  # ka . exp(kb t) kc = cos(t - phi)
    v = Q @ kc
    s = cs.norm_2(cs.cross(ka, v))  # |sin(tb - phi)|, accurate near 0 and pi
    c = cs.dot(ka, v)
    solutions = []
    for sign in (1.0, -1.0):
        delta = cs.atan2(sign * s, c)  # tb - phi
        cb, sb = cs.cos(delta + phi), cs.sin(delta + phi)
        ta = _turn(ka, _rotate(kb, cb, sb, cs.SX(kc)), v)
        # tc from what is left of Q once ta and tb are undone, so the three reproduce Q to rounding
        # even near the singularity, where ta alone is ill-conditioned
        rest = _rotation(kb, cb, -sb) @ _rotation(ka, cs.cos(ta), -cs.sin(ta)) @ Q
        tc = _turn(kc, cs.SX(kb), rest @ kb)
        solutions.append((ta, cs.atan2(sb, cb), tc))
    return solutions, s


def _into_limits(angle, lower: float, upper: float):
    """An angle in (-pi, pi] moved by 2 pi into [lower, upper] where that helps (only for limits
    that reach beyond +-pi)."""
    if lower < -np.pi:
        angle = cs.if_else(angle > upper, angle - 2 * np.pi, angle)
    if upper > np.pi:
        angle = cs.if_else(angle < lower, angle + 2 * np.pi, angle)
    return angle


@dataclass(frozen=True)
class McInverse:
    """MC-Inverse of one S-R-S arm chain.

    Attributes:
        kinematics: S, E, W and the arm angle psi(q) of eq (1) for the chain.
        lower, upper: joint limits [rad], (7,).
        candidates: Function ``(T (4x4) hand pose in the chain base frame [m], psi [rad]) ->
            (Q (7x8) [rad], reason (1x8))``, column j the candidate with index j (see
            :data:`CANDIDATES`), reason one of :data:`REASONS`.
    """

    kinematics: SrsKinematics
    lower: np.ndarray
    upper: np.ndarray
    candidates: cs.Function

    @property
    def chain(self) -> Chain:
        """The arm chain."""
        return self.kinematics.geometry.chain

    @classmethod
    def of(cls, chain: Chain, vertical: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> "McInverse":
        """Derive the solver for ``chain``; ``vertical`` is V of eq (1) in the chain base frame.

        Raises:
            NotSRSError: the chain is not S-R-S, or consecutive shoulder or wrist axes are not perpendicular.
        """
        kin = SrsKinematics.of(chain, vertical)
        geo = kin.geometry
        movable = [j for j in chain.joints if j.movable]
        frames = chain_frames(chain)
        zero = cs.Function("zero", [frames.q], [*frames.before, frames.after[3], frames.tip])(np.zeros(7))
        zero = [np.asarray(T) for T in zero]
        k = [zero[i][:3, :3] @ np.asarray(j.axis) for i, j in enumerate(movable)]  # axes at q = 0
        for a, b in ((0, 1), (1, 2), (4, 5), (5, 6)):
            if abs(k[a] @ k[b]) > PERPENDICULAR_COSINE:
                raise NotSRSError(f"chain '{chain.name}': the axes of {movable[a].name} and {movable[b].name} are not perpendicular, which MC-Inverse needs")
        S, E0, W0 = (np.asarray(x).ravel() for x in kin.points(np.zeros(7)))
        tip0 = zero[-1][:3, :3]
        lower = np.array([j.lower for j in movable])
        upper = np.array([j.upper for j in movable])

        T, psi = cs.SX.sym("T", 4, 4), cs.SX.sym("psi")
        p, R = T[:3, 3], T[:3, :3]
        L2, L3 = geo.upper_arm, geo.forearm
        W = p - R @ geo.tool_from_wrist  # eq (2): SW = OT - OS - WT
        sw = W - S
        d = cs.norm_2(sw)
        u = sw / d
        cos_beta = (L2**2 + L3**2 - d**2) / (2 * L2 * L3)  # eq (3)
        out_of_reach = cs.fabs(cos_beta) > 1 + REACH_SLACK
        cos_beta = cs.fmin(1, cs.fmax(-1, cos_beta))
        beta = cs.acos(cos_beta)
        # the elbow circle: alpha at S between SW and SE; psi = 0 with the elbow below SW in the
        # vertical plane, psi growing for a turn about -SW (eq 5)
        cos_alpha = cs.fmin(1, cs.fmax(-1, (L2**2 + d**2 - L3**2) / (2 * L2 * d)))
        V = np.asarray(vertical, dtype=float)
        down = -(V - cs.dot(V, u) * u)
        n0 = down / cs.norm_2(down)
        n = cs.cos(psi) * n0 + cs.sin(psi) * cs.cross(-u, n0)
        E = S + L2 * (cos_alpha * u + cs.sqrt(1 - cos_alpha**2) * n)  # eq (5)
        singular_reference = cs.norm_2(cs.cross(u, V)) < SINGULAR_SINE  # SW vertical: no reference plane

        a4 = k[3]
        phi0 = np.arctan2(a4 @ np.cross(S - E0, W0 - E0), (S - E0) @ (W0 - E0))  # elbow's zero angle
        singular_elbow = cs.logic_or(cs.sin(beta) < SINGULAR_SINE, singular_reference)
        columns, reasons = [], []
        for elbow in (1.0, -1.0):
            theta4 = cs.atan2(cs.sin(elbow * beta - phi0), cs.cos(elbow * beta - phi0))  # eq (4), both signs
            c4, s4 = cs.cos(theta4), cs.sin(theta4)
            # sub-problem 2: the shoulder rotation turns SE(0) onto SE and the forearm onto EW (eqs 6-8)
            Q = _triad(E - S, W - E) @ _triad(cs.SX(E0 - S), _rotate(a4, c4, s4, cs.SX(W0 - E0))).T
            shoulders, s_shoulder = _euler(Q, k[0], k[1], k[2])  # eqs (9)-(10)
            arm = Q @ _rotation(a4, c4, s4)  # exp(k1 t1) ... exp(k4 t4): both shoulder triples reproduce Q
            wrists, s_wrist = _euler(arm.T @ R @ tip0.T, k[4], k[5], k[6])  # sub-problem 3
            singular = cs.logic_or(singular_elbow, cs.fmin(s_shoulder, s_wrist) < SINGULAR_SINE)
            for t1, t2, t3 in shoulders:
                for t5, t6, t7 in wrists:
                    q = cs.vertcat(*[_into_limits(a, lo, hi) for a, lo, hi in zip((t1, t2, t3, theta4, t5, t6, t7), lower, upper)])
                    outside = cs.logic_or(cs.mmax(q - upper) > 0, cs.mmax(lower - q) > 0)
                    reasons.append(cs.if_else(out_of_reach, OUT_OF_REACH, cs.if_else(singular, SINGULAR, cs.if_else(outside, OUTSIDE_LIMITS, VALID))))
                    columns.append(q)
        candidates = cs.Function("mc_inverse", [T, psi], [cs.horzcat(*columns), cs.horzcat(*reasons)], ["T", "psi"], ["Q", "reason"], {"cse": True})
        return cls(kinematics=kin, lower=lower, upper=upper, candidates=candidates)

    def solve(self, pose: np.ndarray, psi: float) -> "McSolution":
        """All 8 candidates for one hand pose (4x4, chain base frame) [m] at arm angle ``psi`` [rad]."""
        Q, reason = self.candidates(np.asarray(pose, dtype=float), float(psi))
        return McSolution(q=np.asarray(Q).T.copy(), reason=np.asarray(reason).ravel().astype(int))

    def solve_many(self, poses: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates for N poses (N, 4, 4) [m] at arm angles (N,) [rad], in mapped calls of
        :data:`MAP_CHUNK` poses.

        Returns:
            q (N, 8, 7) [rad] and reason codes (N, 8).
        """
        poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
        psi = np.broadcast_to(np.asarray(psi, dtype=float), poses.shape[:1])
        N = poses.shape[0]
        q, reason = np.empty((N, CANDIDATES, 7)), np.empty((N, CANDIDATES), int)
        evaluate, (T, angle, Q, code) = self._mapped
        for start in range(0, N, MAP_CHUNK):
            n = min(MAP_CHUNK, N - start)
            T.reshape(MAP_CHUNK, 4, 4)[:n] = poses[start : start + n].transpose(0, 2, 1)  # column-major
            angle[:n] = psi[start : start + n]
            evaluate()
            q[start : start + n] = Q.reshape(MAP_CHUNK, CANDIDATES, 7)[:n]
            reason[start : start + n] = code.reshape(MAP_CHUNK, CANDIDATES)[:n]
        return q, reason

    @cached_property
    def _mapped(self):
        """The candidates mapped over :data:`MAP_CHUNK` poses, called through a CasADi
        FunctionBuffer on flat column-major arrays (a plain call spends most of its time
        converting the outputs to numpy): ``(evaluate, (T, psi, Q, reason))``."""
        mapped = self.candidates.map(MAP_CHUNK, "thread", MAP_THREADS)
        buffer, evaluate = mapped.buffer()
        arrays = (np.zeros(16 * MAP_CHUNK), np.zeros(MAP_CHUNK), np.zeros(7 * CANDIDATES * MAP_CHUNK), np.zeros(CANDIDATES * MAP_CHUNK))
        buffer.set_arg(0, memoryview(arrays[0]))
        buffer.set_arg(1, memoryview(arrays[1]))
        buffer.set_res(0, memoryview(arrays[2]))
        buffer.set_res(1, memoryview(arrays[3]))

        def run(_keep=buffer) -> None:
            evaluate()

        return run, arrays


def _triad(x, y):
    """Orthonormal frame [x^, y'^, x^ x y'^] from two non-parallel vectors (Gram-Schmidt)."""
    e1 = x / cs.norm_2(x)
    y = y - cs.dot(y, e1) * e1
    e2 = y / cs.norm_2(y)
    return cs.horzcat(e1, e2, cs.cross(e1, e2))


@dataclass(frozen=True)
class McSolution:
    """The 8 candidates of one pose.

    Attributes:
        q: joint values [rad], (8, 7), row j the candidate with index j.
        reason: validity code per candidate (see :data:`REASONS`), (8,).
    """

    q: np.ndarray
    reason: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """Mask of valid candidates, (8,)."""
        return self.reason == VALID

"""The geometry of a 7R arm for the SEW angle (Elias and Wen).

Which family it is, its axes at q = 0, and S, E, W.

:func:`sew_chain` takes the first family that fits (``R-2R-R-3R``, then ``3R-R-2R-R``); the
solutions at one SEW angle are :mod:`dualarm.ik.analytic.sew`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import TypeVar

import casadi as cs
import numpy as np

from dualarm.errors import NotSRSError
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import Chain
from dualarm.model.rodrigues import rotation
from dualarm.model.srs import INTERSECTION_TOLERANCE_M, _axis_lines, _meeting_point
from dualarm.numerics.batched import Batched
from dualarm.numerics.compiled import compiled

_Built = TypeVar("_Built")


class NotSewError(NotSRSError):
    """A chain is of no family the SEW solver handles (one line naming the chain and the joints)."""


def _rot(k, theta):
    """exp([k] theta) (3x3) for a unit axis k (3,) and an angle theta (Rodrigues)."""
    return rotation(k, cs.cos(theta), cs.sin(theta))


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

    _functions: dict = field(default_factory=dict, repr=False, compare=False)

    def transforms(self, q) -> list[tuple]:
        """(R_0i (3x3), t_0i (3x1) [m]) of T_0i = exp([xi_1] q_1) ... exp([xi_i] q_i), i = 1..7.

        For q (CasADi, 7x1): a point fixed in link i at x (q = 0) is at R_0i x + t_0i.
        """
        R, t, frames = cs.SX.eye(3), cs.SX.zeros(3), []
        for i, (h, p) in enumerate(zip(self.axes, self.axis_points, strict=True)):
            R_i = _rot(h, q[i])
            t = t + R @ (p - R_i @ p)  # exp([xi] q) x = R x + (I - R) p for the line through p
            R = R @ R_i
            frames.append((R, t))
        return frames

    def symbolic(self, q) -> tuple:
        """E, W (3x1) [m] and the tip pose T (4x4) for q (CasADi, 7x1), from one product of exponentials."""
        frames = self.transforms(q)
        (R3, t3), (R6, t6), (R7, t7) = frames[2], frames[5], frames[6]
        T = cs.vertcat(
            cs.horzcat(R7 @ self.tool_rotation, R7 @ (self.wrist + self.tool) + t7), cs.DM([[0.0, 0.0, 0.0, 1.0]])
        )
        return R3 @ self.elbow + t3, R6 @ self.wrist + t6, T

    def cached(self, name: Hashable, build: Callable[[], _Built]) -> _Built:
        """This arm's CasADi Function(s) ``name``, ``build()`` the first time (once per arm and name)."""
        if name not in self._functions:
            self._functions[name] = build()
        return self._functions[name]

    def points_and_poses(self, Q: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """(S, E, W), each (N, 3) [m], and the tip poses (N, 4, 4) at configurations Q (N, 7).

        By :meth:`symbolic`, in mapped calls.
        """

        def build() -> Batched:
            q = cs.SX.sym("q", 7)
            return Batched(compiled(cs.Function("sew_fk", [q], list(self.symbolic(q)), {"cse": True})))

        Q = np.asarray(Q, dtype=float).reshape(-1, 7)
        E, W, T = self.cached("fk", build)(Q)
        return (np.broadcast_to(self.shoulder, E.shape), E, W), T

    def points(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """S, E, W at configurations Q (N, 7), each (N, 3) [m]."""
        return self.points_and_poses(Q)[0]

    def poses(self, Q: np.ndarray) -> np.ndarray:
        """Tip poses (N, 4, 4) at configurations Q (N, 7), by products of exponentials."""
        return self.points_and_poses(Q)[1]


def _foot(point: np.ndarray, line: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    p, d = line
    return p + d * np.dot(point - p, d)


@functools.cache
def sew_chain(chain: Chain) -> SewChain:
    """The geometry of ``chain`` in the first family it belongs to, R-2R-R-3R then 3R-R-2R-R.

    Once per chain.

    Raises:
        NotSewError: one line naming the chain and what it lacks: 7 revolute joints, or the
            meeting axes of either family (with how far they miss).
    """
    movable = [j for j in chain.joints if j.movable]
    names = [j.name for j in movable]
    if len(movable) != 7 or any(j.type == "prismatic" for j in movable):
        raise NotSewError(
            f"chain '{chain.name}' has {len(movable)} movable joints; the SEW solver needs 7 revolute joints",
            chain.name,
        )
    check = _axis_lines(chain, np.random.default_rng(7).uniform(-0.8, 0.8, 7))  # no coincidence of the zero pose
    miss: dict[tuple[int, ...], float] = {
        idx: _meeting_point([check[i] for i in idx])[1] for idx in ((1, 2), (4, 5, 6), (0, 1, 2), (4, 5))
    }
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
            f"chain '{chain.name}' is of no family the SEW solver handles: "
            f"R-2R-R-3R needs the axes of {axes((1, 2))} and of {axes((4, 5, 6))} "
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

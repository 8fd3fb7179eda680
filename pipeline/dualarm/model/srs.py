"""Spherical-Revolute-Spherical arm geometry: shoulder S, elbow E, wrist W and the arm angle.

An S-R-S arm has 7 revolute joints; the axes of joints 1-3 meet at the shoulder centre S, those of
joints 5-7 at the wrist centre W, and joint 4 (the elbow) turns the upper arm S-E against the
forearm E-W (Zou, Min, Xu, *MC-Inverse*, section III.B, Fig. 4). Everything here is derived from
the chain itself, never entered by hand.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as cs
import numpy as np

from dualarm.arrays import frozen
from dualarm.errors import NotSRSError
from dualarm.model.kinematics import chain_frames
from dualarm.model.robot import Chain

#: Largest distance between axes that "intersect" [m]: far below any real offset (millimetres), above the
#: rounding of URDFs that write pi/2 as 1.5708 (an xArm7 misses by 5.4e-7 m).
INTERSECTION_TOLERANCE_M = 1e-5


@dataclass(frozen=True)
class SrsGeometry:
    """Constant S-R-S geometry of an arm chain.

    Attributes:
        chain: the arm chain (7 revolute joints).
        shoulder: S in the chain base frame [m], (3,); joints 1-3 turn about it, so it never moves.
        elbow_local: E in the child frame of joint 3 [m], (3,).
        wrist_local: W in the child frame of joint 4 [m], (3,).
        tool_from_wrist: the tip origin relative to W, in the tip frame [m], (3,): the hand pose
            (p, R) has its wrist centre at ``p - R @ tool_from_wrist`` (MC-Inverse eq 2, W->T).
        upper_arm: |SE| = L2 [m].
        forearm: |EW| = L3 [m].
    """

    chain: Chain
    shoulder: np.ndarray
    elbow_local: np.ndarray
    wrist_local: np.ndarray
    tool_from_wrist: np.ndarray
    upper_arm: float
    forearm: float

    def __post_init__(self) -> None:
        for name in (
            "shoulder",
            "elbow_local",
            "wrist_local",
            "tool_from_wrist",
        ):  # read-only: one geometry is shared per chain
            object.__setattr__(self, name, frozen(getattr(self, name), (3,), name))

    @property
    def reach(self) -> float:
        """Largest shoulder-wrist distance |SW| = L2 + L3 [m]."""
        return self.upper_arm + self.forearm

    @property
    def min_reach(self) -> float:
        """Smallest shoulder-wrist distance |L2 - L3| [m]."""
        return abs(self.upper_arm - self.forearm)

    def wrist_centre(self, position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """W for hand poses: position (..., 3) [m], rotation (..., 3, 3) -> (..., 3) [m]."""
        return np.asarray(position) - np.einsum("...ij,j->...i", rotation, self.tool_from_wrist)


def _axis_lines(chain: Chain, q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(point, unit direction) of each joint axis in the base frame at configuration ``q``."""
    frames = chain_frames(chain)
    f = cs.Function("axes", [frames.q], list(frames.before))
    movable = [j for j in chain.joints if j.movable]
    return [
        (T[:3, 3], T[:3, :3] @ np.asarray(j.axis)) for T, j in zip((np.asarray(M) for M in f(q)), movable, strict=True)
    ]


def _meeting_point(lines: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, float]:
    """Least-squares point closest to all ``lines`` and its largest distance to any of them."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for p, d in lines:
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ p
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    worst = max(np.linalg.norm((np.eye(3) - np.outer(d, d)) @ (x - p)) for p, d in lines)
    return x, float(worst)


@functools.cache
def srs_geometry(chain: Chain, *, seed: int = 7) -> SrsGeometry:
    """Derive the S-R-S geometry of ``chain`` from its joints.

    Once per chain and seed, kept: the task loader, reach tests and solvers all ask for it.

    The axes are taken at a random configuration (fixed ``seed``), so that no coincidence of the
    zero pose hides a missing intersection.

    Raises:
        NotSRSError: the chain does not have 7 revolute joints, or the named axes do not meet.
    """
    movable = [j for j in chain.joints if j.movable]
    if len(movable) != 7 or any(j.type == "prismatic" for j in movable):
        raise NotSRSError(f"chain '{chain.name}' has {len(movable)} movable joints; an S-R-S arm has 7 revolute joints")
    names = [j.name for j in movable]
    q = np.random.default_rng(seed).uniform(-0.8, 0.8, 7)
    lines = _axis_lines(chain, q)
    shoulder, miss_s = _meeting_point(lines[0:3])
    wrist, miss_w = _meeting_point(lines[4:7])
    for miss, idx in ((miss_s, (0, 1, 2)), (miss_w, (4, 5, 6))):
        if miss > INTERSECTION_TOLERANCE_M:
            axes = ", ".join(names[i] for i in idx)
            raise NotSRSError(f"chain '{chain.name}': the axes of {axes} do not meet in one point (miss {miss:.3g} m)")
    p4, d4 = lines[3]
    elbow = p4 + d4 * np.dot(shoulder - p4, d4)  # the point of the elbow axis nearest S
    if abs(np.dot(wrist - elbow, d4)) > INTERSECTION_TOLERANCE_M:
        raise NotSRSError(
            f"chain '{chain.name}': shoulder, elbow axis ({names[3]}) and wrist are not coplanar, "
            "the elbow axis must be normal to S-E-W"
        )

    frames = chain_frames(chain)
    f = cs.Function("frames", [frames.q], [frames.after[2], frames.after[3], frames.tip])
    T3, T4, Ttip = (np.asarray(M) for M in f(q))

    def local(T: np.ndarray, x: np.ndarray) -> np.ndarray:
        return T[:3, :3].T @ (x - T[:3, 3])

    return SrsGeometry(
        chain=chain,
        shoulder=shoulder,
        elbow_local=local(T3, elbow),
        wrist_local=local(T4, wrist),
        tool_from_wrist=-local(Ttip, wrist),
        upper_arm=float(np.linalg.norm(elbow - shoulder)),
        forearm=float(np.linalg.norm(wrist - elbow)),
    )


def arm_angle(S, E, W, vertical=(0.0, 0.0, 1.0)):
    """Arm angle psi of MC-Inverse eq (1) [rad], in (-pi, pi].

    The reference plane holds SW and the vertical vector V, with normal n_ref = SW x V; the arm
    plane holds S, E, W, with normal n_arm = SE x SW (the elbow axis direction of eq 6). With this
    orientation psi = 0 when the elbow lies below SW in the vertical plane ("setting the arm angle
    when the elbow joint is below"), and psi grows as the elbow turns about -SW, the screw axis
    xi_SW of eq (5).

    Works on numpy arrays (3,) and on CasADi expressions alike.

    Args:
        S, E, W: shoulder, elbow and wrist centres [m] in one frame.
        vertical: the vertical vector V in that frame.
    """
    lib = cs if isinstance(S, (cs.SX, cs.MX)) else np
    V = np.asarray(vertical, dtype=float)
    sw = W - S
    se = E - S
    n_ref = lib.cross(sw, V)
    n_ref = n_ref / lib.sqrt(lib.dot(n_ref, n_ref))
    n_arm = lib.cross(se, sw)
    n_arm = n_arm / lib.sqrt(lib.dot(n_arm, n_arm))
    sw_unit = sw / lib.sqrt(lib.dot(sw, sw))
    return lib.arctan2(-lib.dot(lib.cross(n_ref, n_arm), sw_unit), lib.dot(n_ref, n_arm))  # eq (1)


@dataclass(frozen=True)
class SrsKinematics:
    """S, E, W and psi of an S-R-S arm as CasADi Functions.

    Attributes:
        geometry: the constant geometry.
        points: Function ``q (7) -> (S, E, W)``, each (3,) in the chain base frame [m].
        psi: Function ``q (7) -> psi`` [rad], arm angle of eq (1) with the vertical ``vertical``.
        vertical: the reference vertical vector V in the chain base frame.
    """

    geometry: SrsGeometry
    points: cs.Function
    psi: cs.Function
    vertical: tuple[float, float, float]

    @classmethod
    def of(cls, chain: Chain, vertical: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> SrsKinematics:
        """The Functions for ``chain`` (raises NotSRSError if it is not S-R-S).

        Built once per chain and vertical in a process, then kept.
        """
        return _srs_kinematics(chain, (float(vertical[0]), float(vertical[1]), float(vertical[2])))

    @classmethod
    def _build(cls, chain: Chain, vertical: tuple[float, float, float]) -> SrsKinematics:
        geometry = srs_geometry(chain)
        frames = chain_frames(chain)
        S = cs.SX(geometry.shoulder)
        E = frames.after[2][:3, :3] @ geometry.elbow_local + frames.after[2][:3, 3]
        W = frames.after[3][:3, :3] @ geometry.wrist_local + frames.after[3][:3, 3]
        points = cs.Function("srs_points", [frames.q], [S, E, W], ["q"], ["S", "E", "W"])
        psi = cs.Function("arm_angle", [frames.q], [arm_angle(S, E, W, vertical)], ["q"], ["psi"])
        return cls(geometry=geometry, points=points, psi=psi, vertical=vertical)

    def arm_angles(self, Q: np.ndarray) -> np.ndarray:
        """Psi at N configurations (N, 7) [rad] -> (N,) [rad], one mapped call."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        return np.asarray(self.psi.map(Q.shape[0])(Q.T)).ravel()


@functools.cache
def _srs_kinematics(chain: Chain, vertical: tuple[float, float, float]) -> SrsKinematics:
    return SrsKinematics._build(chain, vertical)

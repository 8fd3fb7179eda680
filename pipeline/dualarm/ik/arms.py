"""IK one arm at a time: each hand's targets in its arm's base frame, and the joint path of all arms.

MC-Inverse and the pose-level baselines (TRAC-IK, PyBullet, DLS-SVD, ikfast-style) solve 7-DOF arm
chains. A waist is held at its initial value; each hand's Cartesian reference is expressed in
its arm chain's base frame (the torso) through the reference-frame-to-torso forward kinematics at
the initial configuration. :func:`joint_path` assembles the arms' solutions into the stage's
:class:`~dualarm.contracts.joint_path.JointPath`, measuring each hand's position and orientation errors
with the project's forward kinematics.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference
from dualarm.ik.orientation import orientation_errors
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import invert
from dualarm.model.robot import Chain, Robot


@dataclass(frozen=True)
class ArmProblem:
    """One hand's IK problem along the path.

    Attributes:
        hand: ``left`` or ``right``.
        chain: the arm chain (torso to hand).
        targets: hand poses in the chain's base frame (N, 4, 4) [m].
        q0: the arm's initial configuration (7,) [rad].
    """

    hand: str
    chain: Chain
    targets: np.ndarray
    q0: np.ndarray


@dataclass(frozen=True)
class ArmSolution:
    """One arm's joints along the path.

    Attributes:
        q: joint positions (N, 7) [rad], columns ``chain.joint_names``.
        ok: per-sample success (N,).
        solve_time_s: per-sample solve time (N,) [s].
    """

    q: np.ndarray
    ok: np.ndarray
    solve_time_s: np.ndarray


def arm_problems(robot: Robot, reference: CartesianReference, q0: Mapping[str, float]) -> list[ArmProblem]:
    """Every hand of ``reference`` as an :class:`ArmProblem`.

    Its targets in its arm chain's base frame, the joints between the reference's frame and the arm held at ``q0``
    [rad].
    """
    frame = reference.frame_in(robot)
    problems = []
    for hand in reference.hands:
        chain = robot.hand_chain(hand)
        to_base = robot.chain_between(frame, chain.base)
        base_pose = ChainKinematics.of(to_base).pose(np.array([q0[n] for n in to_base.joint_names]))
        targets = invert(base_pose)[None] @ reference.hands[hand].poses
        problems.append(ArmProblem(hand, chain, targets, np.array([q0[n] for n in chain.joint_names])))
    return problems


def joint_path(
    method: str,
    reference: CartesianReference,
    problems: Sequence[ArmProblem],
    solutions: Sequence[ArmSolution],
    q0: Mapping[str, float],
) -> JointPath:
    """The stage output of per-arm solutions.

    Velocities by central differences [rad/s], status failed where any arm failed, solve times summed over the arms,
    hand position [m] and orientation [rad] errors by the chains' FK, every other joint fixed at ``q0`` [rad].
    """
    q = np.hstack([s.q for s in solutions])
    names = tuple(n for p in problems for n in p.chain.joint_names)
    reached = [ChainKinematics.of(p.chain).poses(s.q) for p, s in zip(problems, solutions, strict=True)]
    errors = [np.linalg.norm(T[:, :3, 3] - p.targets[:, :3, 3], axis=1) for p, T in zip(problems, reached, strict=True)]
    angles = [orientation_errors(p.targets[:, :3, :3], T[:, :3, :3]) for p, T in zip(problems, reached, strict=True)]
    ok = np.logical_and.reduce([s.ok for s in solutions])
    return JointPath(
        method=method,
        joint_names=names,
        t=reference.t,
        rep=reference.rep,
        q=q,
        qd=np.gradient(q, reference.t, axis=0) if len(q) > 1 else np.zeros_like(q),  # a task without moves: one sample
        status=np.where(ok, 0, 1),
        solve_time_s=np.sum([s.solve_time_s for s in solutions], axis=0),
        hand_error_m=np.stack(errors, axis=1),
        hand_orientation_error_rad=np.stack(angles, axis=1),
        hands=tuple(p.hand for p in problems),
        fixed={n: v for n, v in q0.items() if n not in names},
    )

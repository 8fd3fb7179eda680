"""IK one arm at a time: each hand's targets in its arm's base frame, and the joint path of all arms.

MC-Inverse and the pose-level baselines (TRAC-IK, PyBullet, DLS-SVD, ikfast-style) solve 7-DOF arm
chains. A free waist is held at its initial value; each hand's Cartesian reference is expressed in
its arm chain's base frame (the torso) through the root-to-torso forward kinematics at the initial
configuration. :func:`joint_path` assembles the arms' solutions into the stage's
:class:`~pipeline.ik.joint_path.JointPath`, measuring each hand's position error with the project's
forward kinematics.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.ik.joint_path import JointPath
from pipeline.model.kinematics import ChainKinematics
from pipeline.model.poses import invert
from pipeline.model.robot import Chain
from pipeline.tasks import Task


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


def arm_problems(task: Task, reference) -> list[ArmProblem]:
    """Every hand of ``task`` along ``reference`` as an :class:`ArmProblem`."""
    problems = []
    for hand in task.spec.hands:
        chain = task.robot.hand_chain(hand)
        to_base = task.robot.chain_between(reference.frame, chain.base)
        base_pose = ChainKinematics.of(to_base).pose(np.array([task.initial_q[n] for n in to_base.joint_names]))
        targets = invert(base_pose)[None] @ reference.hands[hand].poses
        problems.append(ArmProblem(hand, chain, targets, np.array([task.initial_q[n] for n in chain.joint_names])))
    return problems


def joint_path(method: str, task: Task, reference, problems: Sequence[ArmProblem], solutions: Sequence[ArmSolution]) -> JointPath:
    """The stage output of per-arm solutions: velocities by central differences [rad/s], status
    failed where any arm failed, solve times summed over the arms, hand errors by the chains' FK."""
    q = np.hstack([s.q for s in solutions])
    names = tuple(n for p in problems for n in p.chain.joint_names)
    errors = [np.linalg.norm(ChainKinematics.of(p.chain).poses(s.q)[:, :3, 3] - p.targets[:, :3, 3], axis=1) for p, s in zip(problems, solutions)]
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
        hands=tuple(p.hand for p in problems),
        fixed={n: v for n, v in task.initial_q.items() if n not in names},
    )

"""SEW IK along a Cartesian path (``--ik sew``): the SEW angle per sample, every solution there, one kept, checked steps.

MC-Inverse's consistency argument (:mod:`dualarm.ik.mc_path`) for 7R arms that are not S-R-S: when
the SEW angle is a function of where the hand is on the task and the same solution is followed,
every repetition of a path gives the same joints. At each sample every solution at the SEW angle is
enumerated (:func:`dualarm.ik.sew.solve_many`, all samples at once); the one kept is the one inside
the joint limits nearest the initial configuration at the first sample, then at each sample the one
inside the limits nearest the previous sample's (a SEW solution has no fixed branch label: the
roots of the 1-D search appear and merge along a path, so the branch is followed by continuity).
A sample without such a solution, or a joint step above ``max_joint_step_rad``, fails the stage
naming the sample, the time and the joint; nothing is swapped silently.

The SEW angle is Elias and Wen's stereographic one with e_r the task's ``[arm_angle] vertical`` and
the singular half-line from the shoulder along -e_r (into the base, out of reach). ``[arm_angle]``
modes: ``initial`` (the initial configuration's SEW angle, held), ``constant`` and ``schedule``, as
for MC-Inverse; ``auto`` is MC-Inverse's search over its 8 fixed branches and is refused here.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from dualarm.errors import NoSolutionFound, StageError, TaskFileError
from dualarm.ik import mc_path
from dualarm.ik.arms import ArmSolution, arm_problems, joint_path
from dualarm.ik.joint_path import JointPath
from dualarm.ik.sew import SewAngle, sew_chain, solve_many
from dualarm.model.robot import Robot
from dualarm.paths.reference import CartesianReference
from dualarm.tasks.schema import ArmAngle

if TYPE_CHECKING:
    from dualarm.tasks import Task

__all__ = ["settings_for", "sew_angle_of", "solve_sew"]

#: What a task must say for sew when its [arm_angle] mode is auto (the default).
AUTO_REFUSED = 'mode "auto" is MC-Inverse\'s search over its 8 branches; for sew write [arm_angle] mode = "initial" (or "constant", "schedule")'


def settings_for(task: "Task", **overrides: object) -> ArmAngle:
    """The task's ``[arm_angle]`` table with ``overrides``, refused before anything runs when its mode is ``auto``.

    Raises:
        TaskFileError: ``auto`` mode, one line naming the file and the key.
    """
    spec = mc_path.settings_for(task, **overrides)
    if spec.mode == "auto":
        raise TaskFileError(f"{task.where('arm_angle.mode')}: {AUTO_REFUSED}")
    return spec


def sew_angle_of(spec: ArmAngle) -> SewAngle:
    """The stereographic SEW angle of the ``[arm_angle]`` settings: e_r their vertical, the singular half-line along -e_r."""
    v = np.asarray(spec.vertical, dtype=float) / np.linalg.norm(spec.vertical)
    return SewAngle(reference=(float(v[0]), float(v[1]), float(v[2])), singular=(float(-v[0]), float(-v[1]), float(-v[2])))


def solve_sew(robot: Robot, reference: CartesianReference, q0: Mapping[str, float] | str | None = None, settings: ArmAngle = ArmAngle(mode="initial")) -> JointPath:
    """Joint path of every hand of ``reference`` by SEW IK (module docstring), each arm a 7R chain of the Panda's family.

    Raises:
        NotSewError: an arm is not of that family (one line).
        StageError: ``auto`` mode; a sample without a solution inside the limits, or a joint step
            above ``max_joint_step_rad`` (the error's ``sample``, ``t_s`` and ``joint`` say where).
    """
    spec = settings
    if spec.mode == "auto":  # settings_for refuses it from a task; this is for a direct call
        raise StageError(f"sew: {AUTO_REFUSED}", stage="ik")
    q0 = robot.configuration(q0, "q0")
    sew = sew_angle_of(spec)
    problems = arm_problems(robot, reference, q0)
    solutions = []
    for problem in problems:
        arm = sew_chain(problem.chain)
        psi = mc_path.arm_angles(spec, problem.hand, reference, float(sew.angle(*(x[0] for x in arm.points(problem.q0[None])))))
        start = time.perf_counter()
        found = solve_many(arm, problem.targets, psi, sew)
        elapsed = time.perf_counter() - start
        lower, upper = robot.lower_upper(problem.chain.joint_names)
        q = _followed(problem.hand, problem.chain.joint_names, found, problem.q0, lower, upper, reference, psi, spec.max_joint_step_rad)
        solutions.append(ArmSolution(q=q, ok=np.ones(len(reference), bool), solve_time_s=np.full(len(reference), elapsed / len(reference))))
    return joint_path("sew", reference, problems, solutions, q0)


def _followed(hand, names, found, q0, lower, upper, reference, psi, max_step) -> np.ndarray:
    """The solution inside [lower, upper] nearest ``q0`` at sample 0, then nearest the previous one, at every sample (N, 7) [rad]."""
    q = np.empty((len(found), 7))
    previous = q0
    for k, solutions in enumerate(found):
        where = f"sample {k} (t = {reference.t[k]:.3f} s, rep {reference.rep[k]})"
        if not len(solutions.q):
            raise NoSolutionFound(f"sew, {hand} arm: {where} has no solution at SEW angle {psi[k]:.4f} rad", stage="ik", sample=k, t_s=float(reference.t[k]))
        near = solutions.q + 2 * np.pi * np.round((previous - solutions.q) / (2 * np.pi))  # each joint's turn nearest the previous
        inside = np.all((near >= lower) & (near <= upper), axis=1)
        if not inside.any():
            worst = int(np.argmax(np.maximum(lower - near, near - upper).max(axis=0)))
            raise NoSolutionFound(
                f"sew, {hand} arm: {where}: none of its {len(near)} solutions at SEW angle {psi[k]:.4f} rad is inside the joint limits ({names[worst]} the worst)",
                stage="ik",
                sample=k,
                t_s=float(reference.t[k]),
                joint=names[worst],
            )
        steps = np.where(inside[:, None], np.abs(near - previous), np.inf)
        best = int(np.argmin(steps.max(axis=1)))
        if k and steps[best].max() > max_step:
            j = int(np.argmax(steps[best]))
            raise StageError(
                f"sew, {hand} arm: {names[j]} jumps {steps[best, j]:.3f} rad at {where}, above arm_angle.max_joint_step_rad = {max_step}: the solution followed ends there",
                stage="ik",
                sample=k,
                t_s=float(reference.t[k]),
                joint=names[j],
            )
        q[k] = previous = near[best]
    return q

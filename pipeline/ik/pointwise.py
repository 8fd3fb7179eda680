"""Pose-level IK solvers along a path, sample by sample, each seeded with its previous solution.

This is how a user runs an off-the-shelf IK library on a Cartesian path, and how the MC-Inverse
paper ran its baselines (section V): every sample is solved on its own, starting from the
previous sample's answer (the first from the task's initial configuration), and nothing ties a
repetition to the one before it except that seed. Methods:

- ``trac-ik``: TRAC-IK through ``pytracik`` (:class:`~pipeline.ik.baselines.TracIkSolver`);
- ``pybullet``: ``pybullet.calculateInverseKinematics`` (:class:`~pipeline.ik.baselines.PyBulletIkSolver`);
- ``dls-svd``: Li-Liang's damped least squares through the SVD, eqs (12)-(20)
  (:class:`~pipeline.ik.dls.DlsSolver`);
- ``ikfast-style``: the third joint discretised, the other six in closed form, the candidate
  nearest the previous solution (:class:`~pipeline.ik.ikfast_style.IkfastStyle`).

A sample the solver fails is marked failed in the joint path's status and holds the last
successful joints; the next sample is seeded from them. The stage does not stop: the paper
reports baselines that fail part of a task ("Trac-IK has no data for the fifth time"), and the
consistency report counts the repetitions with a failure.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from pipeline.errors import StageError
from pipeline.ik.arms import ArmProblem, ArmSolution, arm_problems, joint_path
from pipeline.ik.joint_path import JointPath
from pipeline.tasks import Task

#: The methods of this module.
POINTWISE_METHODS = ("trac-ik", "pybullet", "dls-svd", "ikfast-style")

#: A solver of one arm: (target pose in the arm base frame (4, 4) [m], seed (7,) [rad]) -> (q, ok).
ArmSolver = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, bool]]


def pointwise_settings(method: str) -> dict[str, object]:
    """The settings a method runs with (recorded in the run's manifest)."""
    from pipeline.ik.dls import DlsSettings

    if method == "trac-ik":
        return {"timeout_s": 0.005, "epsilon": 1e-5, "solve_type": "Speed"}  # TRAC-IK's own defaults
    if method == "pybullet":
        return {"max_iterations": 100, "residual_threshold_m": 1e-12, "joint_damping": 1e-6, "position_tolerance_m": 1e-9, "orientation_tolerance_rad": 1e-6}
    if method == "dls-svd":
        from dataclasses import asdict

        return asdict(DlsSettings())
    if method == "ikfast-style":
        from pipeline.ik.ikfast_style import DEFAULT_RESOLUTION_RAD, FREE_JOINT

        return {"free_joint_index": FREE_JOINT, "resolution_rad": DEFAULT_RESOLUTION_RAD}
    raise StageError(f"unknown pose-level IK method '{method}' (methods: {', '.join(POINTWISE_METHODS)})")


@contextmanager
def _arm_solver(method: str, task: Task, arm: ArmProblem) -> Iterator[ArmSolver]:
    """The method's solver for one arm, with the settings of :func:`pointwise_settings`."""
    settings = pointwise_settings(method)
    base, tip = arm.chain.base, arm.chain.tip
    if method == "trac-ik":
        from pipeline.ik.baselines import TracIkSolver

        solver = TracIkSolver.of(task.robot, base, tip, **settings)
        yield lambda target, seed: _pair(solver.solve(target, seed))
    elif method == "pybullet":
        from pipeline.ik.baselines import PyBulletIkSolver

        locked = {n: v for n, v in task.initial_q.items() if n not in arm.chain.joint_names}
        with PyBulletIkSolver.of(task.robot, base, tip, locked=locked, **settings) as solver:
            yield lambda target, seed: _pair(solver.solve(target, seed))
    elif method == "dls-svd":
        from pipeline.ik.dls import DlsSolver

        solver = DlsSolver.of(task.robot, base, [tip])

        def solve(target, seed):
            result = solver.solve([target], seed)
            return result.q, result.converged

        yield solve
    else:
        from pipeline.ik.ikfast_style import IkfastStyle

        solver = IkfastStyle.of(arm.chain)

        def solve(target, seed):
            result = solver.nearest(target, seed)
            return result.q, result.ok

        yield solve


def _pair(result) -> tuple[np.ndarray, bool]:
    return result.q, result.ok


def solve_pointwise(method: str, task: Task, reference, progress: Callable[[int, int], None] | None = None) -> JointPath:
    """Joint path of every hand of ``task`` along ``reference`` by ``method``, one sample at a
    time, each seeded with the arm's last successful solution; ``progress(done, total)`` is
    called as samples are solved."""
    pointwise_settings(method)  # unknown methods fail before any solver is built
    problems = arm_problems(task, reference)
    N = len(reference)
    solutions = []
    for a, arm in enumerate(problems):
        q, ok, times = np.empty((N, arm.chain.dof)), np.zeros(N, bool), np.zeros(N)
        seed = arm.q0
        with _arm_solver(method, task, arm) as solve:
            for k in range(N):
                start = time.perf_counter()
                answer, ok[k] = solve(arm.targets[k], seed)
                times[k] = time.perf_counter() - start
                seed = q[k] = answer if ok[k] else seed
                if progress is not None and k % 50 == 0:
                    progress(a * N + k, len(problems) * N)
        solutions.append(ArmSolution(q=q, ok=ok, solve_time_s=times))
    return joint_path(method, task, reference, problems, solutions)

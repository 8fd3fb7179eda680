"""Pose-level IK solvers along a path, sample by sample, each seeded with its previous solution.

This is how a user runs an off-the-shelf IK library on a Cartesian path, and how the MC-Inverse
paper ran its baselines (section V): every sample is solved on its own, starting from the
previous sample's answer (the first from the task's initial configuration), and nothing ties a
repetition to the one before it except that seed. Methods:

- ``trac-ik``: TRAC-IK through ``pytracik`` (:class:`~dualarm.ik.pose_level.baselines.TracIkSolver`);
- ``pybullet``: ``pybullet.calculateInverseKinematics``
  (:class:`~dualarm.ik.pose_level.baselines.PyBulletIkSolver`);
- ``dls-svd``: Li-Liang's damped least squares through the SVD, eqs (12)-(20)
  (:class:`~dualarm.ik.pose_level.dls.DlsSolver`);
- ``ikfast-style``: the third joint discretised, the other six in closed form, the candidate
  nearest the previous solution (:class:`~dualarm.ik.analytic.ikfast_style.IkfastStyle`).

A sample the solver fails is marked failed in the joint path's status and holds the last
successful joints; the next sample is seeded from them. The stage does not stop: the paper
reports baselines that fail part of a task ("Trac-IK has no data for the fifth time"), and the
consistency report counts the repetitions with a failure.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference
from dualarm.errors import InvalidArgumentError
from dualarm.ik.arms import ArmProblem, ArmSolution, arm_problems, joint_path
from dualarm.ik.pose_level.dls import DlsSettings as DlsSettings  # DLS-SVD's settings, with the others here
from dualarm.method import Method
from dualarm.model.robot import Robot
from dualarm.settings import as_record, check_positive

#: The methods of this module.
POINTWISE_METHODS = ("trac-ik", "pybullet", "dls-svd", "ikfast-style")
#: Memory an arm's ikfast-style run may keep poses' candidates in [bytes] (a pose's valid candidates:
#: up to 8 per free value, 4,340 taking 240 kB on the humanoid; a repetition of the triangle task, 600
#: poses).
MEMO_BYTES = 256 * 2**20

#: A solver of one arm: (target pose in the arm base frame (4, 4) [m], seed (7,) [rad]) -> (q, ok).
ArmSolver = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, bool]]


#: TRAC-IK's solve types.
SolveType = Literal["Speed", "Distance", "Manip1", "Manip2"]
SOLVE_TYPES: tuple[str, ...] = get_args(SolveType)


@dataclass(frozen=True)
class TracIkSettings:
    """TRAC-IK's settings (its own defaults).

    Attributes:
        timeout_s: wall-clock budget per solve [s]; TRAC-IK's threads race within it, so its
            answers are not repeatable run to run.
        epsilon: tolerance on each twist error component [m], [rad].
        solve_type: ``Speed``, ``Distance``, ``Manip1`` or ``Manip2``.
    """

    timeout_s: float = 0.005
    epsilon: float = 1e-5
    solve_type: SolveType = "Speed"

    def __post_init__(self) -> None:
        check_positive(self, "timeout_s", "epsilon")
        if self.solve_type not in SOLVE_TYPES:
            raise InvalidArgumentError(
                "solve_type", f"unknown TRAC-IK solve type {self.solve_type!r} (types: {', '.join(SOLVE_TYPES)})"
            )


@dataclass(frozen=True)
class PyBulletIkSettings:
    """``pybullet.calculateInverseKinematics``'s settings.

    See :class:`~dualarm.ik.pose_level.baselines.PyBulletIkSolver`.

    Attributes:
        max_iterations: ``maxNumIterations``.
        residual_threshold_m: ``residualThreshold`` [m].
        joint_damping: damping of every chain joint.
        position_tolerance_m: largest position error of a solve counted as success [m].
        orientation_tolerance_rad: largest orientation error counted as success [rad].
    """

    max_iterations: int = 100
    residual_threshold_m: float = 1e-12
    joint_damping: float = 1e-6
    position_tolerance_m: float = 1e-9
    orientation_tolerance_rad: float = 1e-6

    def __post_init__(self) -> None:
        check_positive(self, "max_iterations", integer=True)
        check_positive(self, "residual_threshold_m", "position_tolerance_m", "orientation_tolerance_rad")
        check_positive(self, "joint_damping", zero=True)


@dataclass(frozen=True)
class IkfastStyleSettings:
    """The ikfast-style solver's settings: theta_3 is discretised, the other six in closed form.

    Attributes:
        resolution_rad: the grid step of theta_3 [rad].
    """

    resolution_rad: float = 0.01

    def __post_init__(self) -> None:
        check_positive(self, "resolution_rad")


def _arm_solver(method: str, robot: Robot, arm: ArmProblem, locked: Mapping[str, float], settings: Any) -> ArmSolver:
    """The method's solver for one arm."""
    base, tip = arm.chain.base, arm.chain.tip
    if method == "trac-ik":
        from dualarm.ik.pose_level.baselines import TracIkSolver

        solver = TracIkSolver.of(robot, base, tip, **as_record(settings))
        return lambda target, seed: _pair(solver.solve(target, seed))
    elif method == "pybullet":
        from dualarm.ik.pose_level.baselines import PyBulletIkSolver

        pb_solver = PyBulletIkSolver.shared(robot, base, tip, locked=locked, **as_record(settings))
        return lambda target, seed: _pair(pb_solver.solve(target, seed))
    elif method == "dls-svd":
        from dualarm.ik.pose_level.dls import DlsSolver

        dls = DlsSolver.of(robot, base, [tip], settings)

        def solve(target: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, bool]:
            result = dls.solve([target], seed)
            return result.q, result.converged

        return solve
    else:
        from dualarm.ik.analytic.ikfast_style import IkfastStyle

        ikfast = IkfastStyle.of(arm.chain, settings.resolution_rad)
        # A pose's candidates do not depend on the seed: a pose met again (each repetition repeats
        # the first's poses bit for bit) reuses them; the oldest are dropped beyond MEMO_BYTES.
        seen: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

        def solve_ikfast(target: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, bool]:
            key = target.tobytes()
            if key not in seen:
                seen[key] = ikfast.valid_candidates(target)
                while sum(q.nbytes for q, _ in seen.values()) > MEMO_BYTES:
                    del seen[next(iter(seen))]
            result = ikfast.nearest(target, seed, seen[key])
            return result.q, result.ok

        return solve_ikfast


def _pair(result: Any) -> tuple[np.ndarray, bool]:
    return result.q, result.ok


#: Each method's settings class.
SETTINGS: Mapping[str, type] = {
    "trac-ik": TracIkSettings,
    "pybullet": PyBulletIkSettings,
    "dls-svd": DlsSettings,
    "ikfast-style": IkfastStyleSettings,
}


def solve_pointwise(
    method: str,
    robot: Robot,
    reference: CartesianReference,
    q0: Mapping[str, float] | str | None = None,
    settings: Any = None,
    progress: Callable[[int, int], None] | None = None,
) -> JointPath:
    """Joint path of every hand of ``reference`` by ``method``, one sample at a time.

    ``method`` is one of :data:`POINTWISE_METHODS`. Each sample is seeded with the arm's last successful
    solution (the first with ``q0``).

    Args:
        method: ``trac-ik``, ``pybullet``, ``dls-svd`` or ``ikfast-style``.
        robot: the robot.
        reference: the hands' poses.
        q0: the initial configuration (a home pose's name or joint -> value [rad], others at 0).
        settings: the method's settings (its class in :data:`SETTINGS`; default its defaults).
        progress: called with (samples done, total) as samples are solved.
    """
    if method not in POINTWISE_METHODS:
        raise InvalidArgumentError(
            "method", f"unknown pose-level IK method '{method}' (methods: {', '.join(POINTWISE_METHODS)})"
        )
    kind = SETTINGS[method]
    settings = kind() if settings is None else settings
    if not isinstance(settings, kind):
        raise InvalidArgumentError("settings", f"{method} takes {kind.__name__}, not {type(settings).__name__}")
    q0 = robot.configuration(q0, "q0")
    problems = arm_problems(robot, reference, q0)
    N = len(reference)
    solutions = []
    for a, arm in enumerate(problems):
        q, ok, times = np.empty((N, arm.chain.dof)), np.zeros(N, bool), np.zeros(N)
        seed = arm.q0
        locked = {n: v for n, v in q0.items() if n not in arm.chain.joint_names}
        solve = _arm_solver(method, robot, arm, locked, settings)
        for k in range(N):
            start = time.perf_counter()
            answer, ok[k] = solve(arm.targets[k], seed)
            times[k] = time.perf_counter() - start
            seed = q[k] = answer if ok[k] else seed
            if progress is not None and k % 50 == 0:
                progress(a * N + k, len(problems) * N)
        solutions.append(ArmSolution(q=q, ok=ok, solve_time_s=times))
    return joint_path(method, reference, problems, solutions, q0)


def _solver_of(method: str) -> Callable[..., JointPath]:
    def solve(
        robot: Robot, reference: CartesianReference, q0: Mapping[str, float] | str | None = None, settings: Any = None
    ) -> JointPath:
        return solve_pointwise(method, robot, reference, q0, settings)

    solve.__name__ = f"solve_{method.replace('-', '_')}"
    solve.__doc__ = (
        f"{method} along a path: :func:`solve_pointwise` with ``method='{method}'`` "
        "(settings: see :data:`dualarm.methods.METHODS`)."
    )
    return solve


#: Each method's solve function ``(robot, reference, q0=None, settings=None) -> JointPath``.
solve_trac_ik = _solver_of("trac-ik")
solve_pybullet = _solver_of("pybullet")
solve_dls_svd = _solver_of("dls-svd")
solve_ikfast_style = _solver_of("ikfast-style")


#: The pose-level methods in the registry (:data:`dualarm.methods.METHODS`).
METHODS: Mapping[str, Method[Any]] = {
    m.name: m
    for m in (
        Method(
            "trac-ik",
            "ik",
            "TRAC-IK (pytracik) pose by pose, seeded with the previous answer",
            solve_trac_ik,
            TracIkSettings,
        ),
        Method(
            "pybullet", "ik", "pybullet.calculateInverseKinematics pose by pose", solve_pybullet, PyBulletIkSettings
        ),
        Method(
            "dls-svd",
            "ik",
            "damped least squares through the SVD, pose by pose (Li, Liang, eqs 12-20)",
            solve_dls_svd,
            DlsSettings,
        ),
        Method(
            "ikfast-style",
            "ik",
            "theta_3 discretised, the other six joints in closed form, nearest candidate",
            solve_ikfast_style,
            IkfastStyleSettings,
            arm="srs",
        ),
    )
}

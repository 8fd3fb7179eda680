"""The pseudoinverse baseline of TV-GDD eqs (2)-(3).

thetadot = J^+(theta) (rdot + K (r - f(theta))) + (I - J^+ J) w with w = 0, the same feedback as
TV-GDD and no limits at all: the scheme the paper shows leaving its bounds. In ``pose`` task space
the orientation rows are stacked under the position rows as in TV-GDD (J_omega, omega_d and
K log(R_d R^T); see :class:`~dualarm.ik.velocity.stack.HandStack`); in ``position`` task space, the
paper's, only the positions.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as cs
import numpy as np

from dualarm.contracts.joint_path import JointPath, TaskSpace, check_task_space
from dualarm.contracts.reference import CartesianReference
from dualarm.ik.velocity.stack import reference_stack, stack_joint_path, stacked_reference, start_configuration
from dualarm.ik.velocity.tvgdd import TvgddSettings, gesture_band, joint_bounds
from dualarm.method import Method
from dualarm.model.robot import Robot
from dualarm.settings import check_positive, with_overrides

if TYPE_CHECKING:
    from dualarm.tasks import Task


@dataclass(frozen=True)
class PinvSettings:
    """Settings of the pseudoinverse baseline. The Euler step is the reference's period.

    Attributes:
        feedback_gain: K [1/s].
        free_waist: move the joints between the reference's frame and the arms too.
        task_space: ``pose`` (the hands' positions and orientations) or ``position`` (positions
            only, as in the paper).
        bands: the TV-GDD settings whose bands (eqs 19-22) are recorded beside the path, for
            comparison with TV-GDD on the same task (the paper's Figs 3-4); they bound nothing.
    """

    feedback_gain: float = 20.0
    free_waist: bool = False
    bands: TvgddSettings = TvgddSettings()
    task_space: TaskSpace = "pose"

    def __post_init__(self) -> None:
        check_task_space(self.task_space)
        check_positive(self, "feedback_gain")


def settings_for(task: Task, **overrides: object) -> PinvSettings:
    """The baseline's settings for a task: TV-GDD's gain, bands and task space.

    They come from the task's ``[gesture]`` and ``[ik]`` tables.
    """
    from dualarm.ik.velocity.tvgdd import settings_for as tvgdd_settings

    bands = tvgdd_settings(task)
    return with_overrides(
        PinvSettings(
            feedback_gain=bands.feedback_gain, free_waist=bands.free_waist, bands=bands, task_space=bands.task_space
        ),
        overrides,
    )


def solve_pinv(
    robot: Robot,
    reference: CartesianReference,
    q0: Mapping[str, float] | str | None = None,
    settings: PinvSettings = PinvSettings(),
) -> JointPath:
    """Follow ``reference`` with the minimum-norm pseudoinverse rate (eqs 2-3, w = 0) and Euler steps.

    The steps are at the reference's period. It follows the hands' positions, and in ``pose`` task
    space their orientations, as TV-GDD.

    Nothing bounds the joints; the path's extras hold the bands TV-GDD would impose
    (:func:`~dualarm.ik.velocity.tvgdd.gesture_band` with ``settings.bands``).

    Args:
        robot: the robot.
        reference: the hands' reference.
        q0: the initial configuration (as :func:`~dualarm.ik.velocity.tvgdd.solve_tvgdd`).
        settings: the gain, the task space and the bands to record.
    """
    stack = reference_stack(robot, reference, q0, settings.free_waist, settings.task_space)
    tau = reference.period_s
    r, rdot = stack.target, cs.SX.sym("rdot", stack.m)
    J = stack.jacobian
    rhs = (
        rdot + settings.feedback_gain * stack.error
    )  # eqs (2)-(3): rdot + K (r - f(theta)), and (pose) omega_d + K log(R_d R^T) under it
    velocity = J.T @ cs.solve(J @ J.T, rhs)  # J^+ rhs for a full-row-rank J, eqs (2)-(3) with w = 0
    step = cs.Function("pinv_step", [stack.theta, r, rdot], [velocity], ["theta", "r", "rdot"], ["thetadot"])
    R, V = stacked_reference(stack, reference)
    N, n = len(reference), stack.n
    q, qd, solve_time = np.empty((N, n)), np.empty((N, n)), np.empty(N)
    theta = start_configuration(stack, reference, *robot.lower_upper(stack.joint_names))
    for k in range(N):
        q[k] = theta
        start = time.perf_counter()
        qd[k] = np.asarray(step(theta, R[k], V[k])).ravel()
        solve_time[k] = time.perf_counter() - start
        theta = theta + tau * qd[k]
    bands = gesture_band(joint_bounds(robot, stack, settings.bands), settings.bands, tau, reference.t, q)
    return stack_joint_path("pinv", stack, reference, q, qd, solve_time, bands)


#: The pseudoinverse baseline in the registry (:data:`dualarm.methods.METHODS`).
METHODS: Mapping[str, Method[PinvSettings]] = {
    "pinv": Method(
        "pinv",
        "ik",
        "pseudoinverse baseline of TV-GDD eqs (2)-(3), no bounds",
        solve_pinv,
        PinvSettings,
        settings_for,
        orientation=False,
    )
}

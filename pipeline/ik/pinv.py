"""The pseudoinverse baseline of TV-GDD eqs (2)-(3).

thetadot = J^+(theta) (rdot + K (r - f(theta))) + (I - J^+ J) w with w = 0, the same position
feedback as TV-GDD and no limits at all: the scheme the paper shows leaving its bounds.
"""

from __future__ import annotations

import time

import casadi as cs
import numpy as np

from pipeline.ik.joint_path import JointPath
from pipeline.ik.stack import hand_stack, stack_joint_path, stacked_reference, start_configuration


def solve_pinv(task, reference, feedback_gain: float, period_s: float | None = None) -> JointPath:
    """Follow ``reference`` with the minimum-norm pseudoinverse rate (eqs 2-3, w = 0) and Euler steps.

    Nothing bounds the joints; for comparison with TV-GDD (the paper's Figs 3-4) the path's extras
    hold the bands TV-GDD would impose on the same task (:func:`~pipeline.ik.tvgdd.gesture_band`).

    Args:
        task: the task (initial configuration, moved onto the path start if it is off it).
        reference: the CartesianReference.
        feedback_gain: K [1/s].
        period_s: Euler step [s] (default: the reference's period).
    """
    from pipeline.ik.tvgdd import gesture_band, joint_bounds, settings_for

    stack = hand_stack(task)
    tau = period_s or reference.period_s
    r, rdot = cs.SX.sym("r", stack.m), cs.SX.sym("rdot", stack.m)
    J = stack.jacobian
    rhs = rdot + feedback_gain * (r - stack.position)
    velocity = J.T @ cs.solve(J @ J.T, rhs)  # J^+ rhs for a full-row-rank J, eqs (2)-(3) with w = 0
    step = cs.Function("pinv_step", [stack.theta, r, rdot], [velocity], ["theta", "r", "rdot"], ["thetadot"])
    R, V = stacked_reference(stack, reference)
    N, n = len(reference), stack.n
    q, qd, solve_time = np.empty((N, n)), np.empty((N, n)), np.empty(N)
    theta = start_configuration(stack, reference, *task.robot.lower_upper(stack.joint_names))
    for k in range(N):
        q[k] = theta
        start = time.perf_counter()
        qd[k] = np.asarray(step(theta, R[k], V[k])).ravel()
        solve_time[k] = time.perf_counter() - start
        theta = theta + tau * qd[k]
    return stack_joint_path("pinv", stack, reference, q, qd, solve_time, gesture_band(joint_bounds(task, stack), settings_for(task), reference.t, q))

"""``ik.*`` metrics of a JointPath (keys of DESIGN.md, units in the suffix)."""

from __future__ import annotations

import numpy as np

from pipeline.ik.joint_path import JointPath

#: Slack allowed before a joint position or velocity counts as a violation [rad] / [rad/s].
VIOLATION_TOLERANCE = 1e-9


def ik_metrics(path: JointPath, task) -> dict[str, float]:
    """Hand position errors (norms over samples and hands), limit violations against the robot's
    position limits and the task's velocity limits, the largest joint step, solve times, failures.

    A violation is one (sample, joint) pair outside its limit by more than
    :data:`VIOLATION_TOLERANCE`.
    """
    limits = task.robot.limits
    names = path.joint_names
    lower = np.array([limits[n].lower for n in names])
    upper = np.array([limits[n].upper for n in names])
    vmax = task.velocity_limits(names)
    error = path.hand_error_m
    steps = np.abs(np.diff(path.q, axis=0))
    return {
        "ik.position_error_max_m": float(error.max()),
        "ik.position_error_mean_m": float(error.mean()),
        "ik.position_error_rmse_m": float(np.sqrt((error**2).mean())),
        "ik.joint_limit_violations": float(((path.q < lower - VIOLATION_TOLERANCE) | (path.q > upper + VIOLATION_TOLERANCE)).sum()),
        "ik.velocity_limit_violations": float((np.abs(path.qd) > vmax + VIOLATION_TOLERANCE).sum()),
        "ik.max_joint_step_rad": float(steps.max()) if len(steps) else 0.0,
        "ik.solve_time_mean_s": float(path.solve_time_s.mean()),
        "ik.solve_time_median_s": float(np.median(path.solve_time_s)),
        "ik.solve_time_total_s": float(path.solve_time_s.sum()),
        "ik.failures": float((path.status != 0).sum()),
    }

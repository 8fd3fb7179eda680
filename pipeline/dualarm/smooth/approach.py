"""The approach: the move from the task's initial configuration to the start of the trajectory.

Jerk-limited, at rest at both ends.

A task starts at its ``initial`` configuration, while the joint path (IK or plan) starts where
its first sample puts the arms; the approach joins them the way the retime stage times a path
(:func:`dualarm.retime.jerk.jerk_limited`): along the straight line in joint space, time-optimal
within each joint's velocity, acceleration and jerk limits (a straight piece: Ruckig on the path
parameter), every joint starting and stopping together, sampled every control period. It is
played before the trajectory, on its own clock (``t`` from 0), and checked like it
(:mod:`dualarm.execute.preflight`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.retime.jerk import jerk_limited

#: The approach's stage name.
STAGE = "approach"


def approach_trajectory(
    names: tuple[str, ...],
    start: np.ndarray,
    goal: np.ndarray,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    period_s: float,
    fixed: dict[str, float] | None = None,
) -> JointTrajectory:
    """The time-optimal jerk-limited straight move from ``start`` to ``goal`` [rad], at rest at both ends.

    Sampled every ``period_s`` [s] (its last sample at the goal).

    Args:
        names: the joints.
        start: the initial configuration (n,) [rad].
        goal: the trajectory's first configuration (n,) [rad].
        velocity: velocity limits (n,) [rad/s].
        acceleration: acceleration limits (n,) [rad/s^2].
        jerk: jerk limits (n,) [rad/s^3].
        period_s: sample period [s].
        fixed: the locked joints' values [rad].
    """
    q = np.stack([np.asarray(start, dtype=float), np.asarray(goal, dtype=float)])
    zeros = np.zeros((2, len(names)))
    line = JointPath(
        method=STAGE,
        joint_names=names,
        t=np.arange(2.0),
        rep=np.zeros(2, dtype=int),
        q=q,
        qd=zeros,
        status=np.zeros(2, dtype=int),
        solve_time_s=np.zeros(2),
        hand_error_m=np.zeros((2, 0)),
        hands=(),
        fixed=fixed or {},
    )
    return replace(jerk_limited(line, velocity, acceleration, jerk).sample(period_s), stage=STAGE)

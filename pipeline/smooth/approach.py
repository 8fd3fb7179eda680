"""The approach: the move from the task's initial configuration to the start of the trajectory, jerk-limited, at rest at both ends.

A task starts at its ``initial`` configuration, while the joint path (IK or plan) starts where
its first sample puts the arms; the approach joins them with one Ruckig trajectory (time-optimal
and time-synchronised over the joints, within each joint's velocity, acceleration and jerk
limits), sampled every control period. It is played before the trajectory, on its own clock
(``t`` from 0), and checked like it (:mod:`dualarm.execute.preflight`).
"""

from __future__ import annotations

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory

from dualarm.errors import StageError
from dualarm.retime.trajectory import JointTrajectory

#: The approach's stage name.
STAGE = "approach"


def approach_trajectory(
    names: tuple[str, ...], start: np.ndarray, goal: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray, period_s: float, fixed: dict[str, float] | None = None
) -> JointTrajectory:
    """The time-optimal jerk-limited move from ``start`` to ``goal`` [rad], at rest at both ends, sampled every ``period_s`` [s] (its last sample at the goal).

    Args:
        names: the joints.
        start: the initial configuration (n,) [rad].
        goal: the trajectory's first configuration (n,) [rad].
        velocity: velocity limits (n,) [rad/s].
        acceleration: acceleration limits (n,) [rad/s^2].
        jerk: jerk limits (n,) [rad/s^3].
        period_s: sample period [s].
        fixed: the locked joints' values [rad].

    Raises:
        StageError: Ruckig cannot compute the move (naming its result).
    """
    n = len(names)
    inp = InputParameter(n)
    inp.current_position, inp.target_position = np.asarray(start, float).tolist(), np.asarray(goal, float).tolist()
    inp.current_velocity = inp.current_acceleration = inp.target_velocity = inp.target_acceleration = [0.0] * n
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = (np.asarray(x, float).tolist() for x in (velocity, acceleration, jerk))
    plan = Trajectory(n)
    result = Ruckig(n).calculate(inp, plan)
    if result not in (Result.Working, Result.Finished):
        raise StageError(f"approach: Ruckig cannot move from the initial configuration to the trajectory's start ({result.name})", stage=STAGE)
    t = np.arange(int(np.ceil(plan.duration / period_s - 1e-9)) + 1) * period_s
    samples = [plan.at_time(min(float(s), plan.duration)) for s in t]
    q, qd, qdd = (np.array([sample[i] for sample in samples], dtype=float).reshape(len(t), n) for i in range(3))
    return JointTrajectory(stage=STAGE, joint_names=names, t=t, q=q, qd=qd, qdd=qdd, rep=np.zeros(len(t), dtype=int), fixed=fixed or {})

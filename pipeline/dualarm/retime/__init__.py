"""The retime stage: a joint path -> a timed joint trajectory, on the path.

Within velocity, acceleration and jerk limits, on the path (TOPP-RA kept for comparison).

Modules:

- :mod:`dualarm.retime.stage`: :func:`retime_path`, :class:`Retimed`, :func:`~dualarm.retime.stage.plan`
  and the checks of the limits and the path.
- :mod:`dualarm.retime.topp`: the time-optimal timing by TOPP-RA (chord-length path, gridpoints, refinement).
- :mod:`dualarm.retime.jerk`: the jerk-limited timing on the path (the default,
  ``[retime] timing = "jerk-limited"``; one CasADi/IPOPT program per rest-to-rest piece).
- :mod:`dualarm.retime.timing`: :class:`~dualarm.retime.timing.Timing`, the continuous trajectory before
  sampling, its sampling, and the task's own timing (``keep_timing``).
- :mod:`dualarm.contracts.trajectory`: :class:`JointTrajectory`, the sampled trajectory.
"""

from dualarm.contracts.trajectory import JointTrajectory
from dualarm.retime.stage import Retimed, retime_path

__all__ = ["JointTrajectory", "Retimed", "retime_path"]

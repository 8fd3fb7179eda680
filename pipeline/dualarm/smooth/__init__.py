"""The smooth stage: a timed joint trajectory -> a jerk-limited one at the control period (Ruckig).

Modules:

- :mod:`dualarm.smooth.stage`: :func:`smooth_trajectory` and :class:`Smoothed`.
- :mod:`dualarm.smooth.targets`: the reference resampled at the control times and clamped into the limits.
- :mod:`dualarm.smooth.tracker`: the control loop, one Ruckig per joint with an adaptive look-ahead.
"""

from dualarm.smooth.stage import Smoothed, smooth_trajectory

__all__ = ["Smoothed", "smooth_trajectory"]

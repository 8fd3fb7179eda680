"""The targets the smooth stage's tracker steers to.

The reference resampled at the control times, clamped into the limits.

Resampling. The reference is resampled at the control times ``t_k = k * period_s`` (linear
interpolation of q, qd and qdd between its samples) and held at its final position, at rest,
after it ends (:class:`Targets`).

Clamping. Ruckig refuses (``RuckigError``) a target whose velocity or acceleration exceeds the
limits, or from which the velocity limit is inevitably crossed. Each target is therefore clamped:
``|qd| <= v``, ``|qdd| <= a * (1 - 1e-9)`` (see :data:`TARGET_INSET`) and
``qdd^2 / (2 j) + |qdd| * period_s <= v - |qd|``, which keeps the velocity within its limit while
the acceleration is brought back to zero, before or after the target, even if Ruckig holds the
target's acceleration for up to one period. A jerk-feasible reference is not changed by the first
two and barely by the third; the target positions are never changed.

Units: positions [rad], velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3], times [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm.contracts.trajectory import JointTrajectory

#: Relative distance by which target accelerations are kept inside their limits: Ruckig
#: 0.19's community solver can crash (segmentation fault) with the current and target
#: accelerations both exactly at the limit and the positions equal.
TARGET_INSET = 1e-9

#: Relative slack when comparing a duration with the time available (here: the reference's
#: duration with the control periods; in the tracker: a time-optimal duration with the look-ahead).
DURATION_SLACK = 1e-9


@dataclass(frozen=True)
class Targets:
    """The reference resampled at the control times, with the targets clamped into the limits.

    Row k (k < ``end``) is the reference at t = k * dt; row ``end`` (and any later index) is its
    final position at rest, the reference's end lying in ((end - 1) * dt, end * dt].

    Attributes:
        p, v, a: (end + 1, n) target positions [rad], velocities [rad/s], accelerations [rad/s^2].
        end: index of the final-rest row.
    """

    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    end: int

    @classmethod
    def of(cls, ref: JointTrajectory, dt: float, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray) -> Targets:
        """Resample ``ref`` every ``dt`` [s] and clamp the targets into the limits (module docstring).

        Args:
            ref: the reference trajectory, not empty.
            dt: the control period [s].
            vmax, amax, jmax: velocity [rad/s], acceleration [rad/s^2] and jerk [rad/s^3] limits per joint (n,).
        """
        n = len(ref.joint_names)
        end = max(0, math.ceil(ref.duration_s / dt * (1 - DURATION_SLACK)))
        t = np.arange(end) * dt
        p, v, acc = (np.zeros((end + 1, n)) for _ in range(3))
        p[:end], v[:end], acc[:end], _ = ref.interpolate(t)
        p[end] = ref.q[-1]
        v = np.clip(v, -vmax, vmax)
        headroom = np.maximum(vmax - np.abs(v), 0.0)
        cap = jmax * (np.sqrt(dt**2 + 2 * headroom / jmax) - dt)  # a^2 / (2 j) + a dt = headroom
        acc = np.sign(acc) * np.minimum(np.abs(acc), np.minimum(amax * (1 - TARGET_INSET), cap))
        return cls(p, v, acc, end)

    def rows(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position [rad], velocity [rad/s] and acceleration [rad/s^2] targets (n,).

        Joint i's from row ``index[i]`` (clipped to ``end``).
        """
        rows = np.minimum(index, self.end)
        cols = np.arange(self.p.shape[1])
        return self.p[rows, cols], self.v[rows, cols], self.a[rows, cols]

    def joint(self, index: int, i: int) -> tuple[float, float, float]:
        """Position [rad], velocity [rad/s] and acceleration [rad/s^2] target of joint ``i`` at row ``index``.

        ``index`` clipped to ``end``.
        """
        r = min(int(index), self.end)
        return self.p[r, i], self.v[r, i], self.a[r, i]

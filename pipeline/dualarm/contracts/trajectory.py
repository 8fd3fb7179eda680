"""``JointTrajectory``: joints over time, the output of the retime and smooth stages."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from dualarm.arrays import frozen


@dataclass(frozen=True)
class JointTrajectory:
    """Joint positions, velocities and accelerations sampled over time.

    Attributes:
        stage: the stage that made it (``retime`` or ``smooth``).
        joint_names: the active joints, the columns of ``q``.
        t: sample times (M,) [s], increasing, t[0] = 0.
        q: joint positions (M, n) [rad].
        qd: joint velocities (M, n) [rad/s].
        qdd: joint accelerations (M, n) [rad/s^2].
        rep: repetition index of each sample (M,) (that of the joint-path sample it came from).
        fixed: values of the robot's locked joints [rad].
        approach: the move from the task's initial configuration to ``q[0]``, played before this
            trajectory on its own clock (:mod:`dualarm.smooth.approach`); None when there is none.
    """

    stage: str
    joint_names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    rep: np.ndarray
    fixed: Mapping[str, float] = field(default_factory=dict)
    approach: JointTrajectory | None = None

    def __post_init__(self) -> None:
        M, n = len(self.t), len(self.joint_names)
        for name, shape, dtype in (
            ("t", (M,), float),
            ("q", (M, n), float),
            ("qd", (M, n), float),
            ("qdd", (M, n), float),
            ("rep", (M,), int),
        ):
            object.__setattr__(self, name, frozen(getattr(self, name), shape, name, dtype))
        if M and (self.t[0] != 0 or (np.diff(self.t) <= 0).any()):
            raise ValueError("t: must start at 0 and increase")
        object.__setattr__(self, "fixed", MappingProxyType(dict(self.fixed)))

    def __len__(self) -> int:
        return len(self.t)

    def mean_jerk(self) -> np.ndarray:
        """The mean jerk over each sample period, diff(qdd) / diff(t), (M, n) [rad/s^3].

        At the period's end (0 at the first sample).
        """
        jerk = np.zeros_like(self.qdd)
        if len(self) > 1:
            jerk[1:] = np.diff(self.qdd, axis=0) / np.diff(self.t)[:, None]
        return jerk

    def interpolate(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """q, qd, qdd (K, n) linearly interpolated at ``times`` (K,) [s] (held at the ends).

        And the repetition index of the last sample at or before each time (K,).
        """
        times = np.asarray(times, dtype=float)
        q, qd, qdd = (
            np.stack([np.interp(times, self.t, x[:, j]) for j in range(x.shape[1])], axis=1).reshape(
                len(times), x.shape[1]
            )
            for x in (self.q, self.qd, self.qdd)
        )
        rep = self.rep[np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self) - 1)]
        return q, qd, qdd, rep

    @property
    def duration_s(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t[-1])

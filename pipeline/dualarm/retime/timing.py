"""``Timing``: a continuous joint trajectory along a joint path, before sampling, and its sampling.

A timing is what the retime stage plans before it samples: q(t), qd(t), qdd(t) as a function of
time, and the time at which the trajectory passes each IK sample. Three kinds are made:

- ``jerk-limited`` (:func:`dualarm.retime.jerk.jerk_limited`): near time-optimal within velocity,
  acceleration and jerk limits, on the path.
- ``topp-ra`` (:func:`dualarm.retime.topp.time_optimal`): the time-optimal trajectory along the path.
- ``keep_timing`` (:func:`task_timing`): the task's own timing, a clamped cubic spline of q over
  the path's t (rest at both ends), which :func:`dualarm.retime.stage.retime_path` then checks against
  the limits on the sampled trajectory.

Sampling (:meth:`Timing.sample`, :func:`sample_grid`) is every period from 0, the last step between
half and one and a half periods, so the trajectory's final time is always a sample. A uniform
slow-down t -> k t (:meth:`Timing.slowed`) scales qd by 1/k and qdd by 1/k^2.

Units: joint positions [rad], velocities [rad/s], accelerations [rad/s^2], times [s].
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np
from scipy.interpolate import CubicSpline

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import StageError

#: The stage name, in messages and in :attr:`JointTrajectory.stage`.
STAGE = "retime"

#: (t [s]) -> (q [rad], qd [rad/s], qdd [rad/s^2]), each (len(t), n).
Evaluator = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Fallback:
    """A piece of a jerk-limited timing that its time-optimal program did not time from its first guess.

    Attributes:
        first_sample, last_sample: the joint-path samples the piece runs between.
        how: ``warm start`` (the program from a slower first guess) or ``worst-case limits`` (Ruckig on the path
            parameter within limits that hold wherever on the piece).
        duration_s: the piece's duration as timed [s].
        bound_s: its duration within the velocity and acceleration limits alone, jerk unlimited [s]; what the
            fallback cost is at most ``duration_s - bound_s``.
    """

    first_sample: int
    last_sample: int
    how: str
    duration_s: float
    bound_s: float


@dataclass(frozen=True)
class Timing:
    """A continuous joint trajectory along a joint path, before sampling.

    Attributes:
        method: ``jerk-limited``, ``topp-ra`` (time-optimal) or ``keep_timing`` (the task's own timing).
        joint_names: the active joints, the columns of q.
        duration_s: the trajectory's duration [s]; 0 for a path that does not move.
        sample_times_s: the time at which the trajectory passes each joint-path sample (N,) [s],
            non-decreasing (dropped duplicates share the time of the sample they repeat).
        rep: repetition index of each joint-path sample (N,).
        evaluate: (t (M,) [s], within [0, duration_s]) -> (q [rad], qd [rad/s], qdd [rad/s^2]),
            each (M, n).
        stretch: the uniform slow-down applied after TOPP-RA to meet the limits between its
            gridpoints (>= 1; 1 for ``keep_timing`` and for a path that does not move).
        fixed: values of the robot's locked joints [rad].
        fallbacks: the pieces of a ``jerk-limited`` timing timed by a fallback, in order.
    """

    method: str
    joint_names: tuple[str, ...]
    duration_s: float
    sample_times_s: np.ndarray
    rep: np.ndarray
    evaluate: Evaluator
    stretch: float = 1.0
    fixed: Mapping[str, float] = field(default_factory=dict)
    fallbacks: tuple[Fallback, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "fixed", MappingProxyType(dict(self.fixed)))

    def sample(self, period_s: float) -> JointTrajectory:
        """The trajectory sampled every ``period_s`` [s], plus its final time (stage ``retime``).

        The last step lies between half and one and a half periods (a sample closer than half a
        period to the end is replaced by the end). Each sample's ``rep`` is that of the last
        joint-path sample the trajectory has passed (``sample_times_s`` <= t).
        """
        t = sample_grid(self.duration_s, period_s)
        q, qd, qdd = self.evaluate(t)
        passed = np.clip(np.searchsorted(self.sample_times_s, t, side="right") - 1, 0, len(self.rep) - 1)
        if len(t) == 1:
            passed = np.array([len(self.rep) - 1])
        return JointTrajectory(
            stage=STAGE, joint_names=self.joint_names, t=t, q=q, qd=qd, qdd=qdd, rep=self.rep[passed], fixed=self.fixed
        )

    def slowed(self, k: float) -> Timing:
        """The same motion ``k`` (>= 1) times slower: q(t / k), qd / k, qdd / k^2."""
        return replace(
            self,
            duration_s=k * self.duration_s,
            sample_times_s=k * self.sample_times_s,
            evaluate=_Slowed(self.evaluate, k),
            stretch=k * self.stretch,
        )


@dataclass(frozen=True)
class _Slowed:
    """An evaluator run ``k`` times slower.

    Attributes:
        evaluate: the evaluator at its own speed.
        k: the slow-down factor (>= 1).
    """

    evaluate: Evaluator
    k: float

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Q [rad], qd [rad/s], qdd [rad/s^2] at times ``t`` [s] of the slowed motion."""
        q, qd, qdd = self.evaluate(np.asarray(t, dtype=float) / self.k)
        return q, qd / self.k, qdd / self.k**2


def sample_grid(duration_s: float, period_s: float) -> np.ndarray:
    """Sample times every ``period_s`` from 0 to ``duration_s`` included [s].

    The last step is in [period/2, 3 period/2), unless the whole duration is shorter than that;
    a duration of 0 gives the single time 0.
    """
    if duration_s <= 0:
        return np.zeros(1)
    t = np.arange(1, int(np.floor(duration_s / period_s)) + 1) * period_s
    return np.concatenate([[0.0], t[t < duration_s - 0.5 * period_s], [duration_s]])


def task_timing(path: JointPath) -> Timing:
    """The path's own timing: a clamped cubic spline of q over ``path.t - path.t[0]`` (rest at both ends).

    The spline passes through every sample at its own time. Its velocity is forced to 0 at both
    ends, so a path that does not start or end at rest gets a short acceleration spike there
    (which the limit check of :func:`dualarm.retime.stage.retime_path` reports).

    Args:
        path: the IK output, finite and not empty.

    Raises:
        StageError: the path's times do not strictly increase.
    """
    if len(path) == 1:
        return still(path, method="keep_timing")
    t = path.t - path.t[0]
    if not np.isfinite(t).all() or (np.diff(t) <= 0).any():
        k = int(np.argmax(~np.isfinite(t[1:]) | (np.diff(t) <= 0)))
        t_s = float(path.t[k + 1])
        raise StageError(
            f"{STAGE}: keep_timing needs increasing sample times, "
            f"but sample {k + 1} (t = {t_s:.6g} s) does not come after sample {k}",
            stage=STAGE,
            sample=k + 1,
            t_s=t_s,
        )
    spline = CubicSpline(t, path.q, bc_type="clamped")
    d1, d2 = spline.derivative(1), spline.derivative(2)

    def evaluate(ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ts = np.clip(np.asarray(ts, dtype=float), 0.0, t[-1])
        return spline(ts), d1(ts), d2(ts)

    return Timing(
        method="keep_timing",
        joint_names=path.joint_names,
        duration_s=float(t[-1]),
        sample_times_s=t,
        rep=path.rep,
        evaluate=evaluate,
        fixed=path.fixed,
    )


def still(path: JointPath, method: str = "topp-ra") -> Timing:
    """A trajectory that holds the path's first configuration (a path that does not move).

    Its duration is 0: sampled, it is one sample at rest, with the repetition index of the
    path's last sample.

    Args:
        path: the IK output, not empty.
        method: the :attr:`Timing.method` to record.
    """
    q0 = np.asarray(path.q[0], dtype=float)

    def evaluate(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m = len(np.atleast_1d(t))
        return np.tile(q0, (m, 1)), np.zeros((m, len(q0))), np.zeros((m, len(q0)))

    return Timing(
        method=method,
        joint_names=path.joint_names,
        duration_s=0.0,
        sample_times_s=np.zeros(len(path)),
        rep=path.rep,
        evaluate=evaluate,
        fixed=path.fixed,
    )


def path_deviation_max_rad(timing: Timing, path: JointPath) -> float:
    """The largest joint difference between the trajectory at the joint-path samples and the samples [rad].

    The trajectory is evaluated at :attr:`Timing.sample_times_s` (the times it passes the
    samples' path parameters) and compared with ``path.q``. The spline passes through the
    samples, so this is ~1e-12 rad (up to :data:`dualarm.retime.topp.DUPLICATE_CHORD_RAD` for
    dropped duplicates).
    """
    q, _, _ = timing.evaluate(timing.sample_times_s)
    return float(np.abs(q - path.q).max())

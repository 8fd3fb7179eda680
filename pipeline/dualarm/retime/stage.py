"""Retime a joint path: a timed, sampled trajectory within joint velocity and acceleration limits.

The IK stage gives joint positions sample by sample (a :class:`JointPath`). This stage turns them
into a trajectory over time, q(t), qd(t), qdd(t), sampled at a fixed period, that passes through
every IK sample and keeps every joint within its velocity and acceleration limits:

1. :func:`plan` validates the limits (:func:`dualarm.limits.per_joint`) and the path
   (:func:`check_path`; :func:`check_jumps` but for the task's own timing), and times the path:
   time-optimally by TOPP-RA (:func:`dualarm.retime.topp.time_optimal`, which explains the method),
   or with the task's own timing (``keep_timing``, :func:`dualarm.retime.timing.task_timing`), or
   jerk-limited within velocity, acceleration and jerk limits (``jerk``,
   :func:`dualarm.retime.jerk.jerk_limited`).
2. :func:`retime_path` samples the timing (:meth:`dualarm.retime.timing.Timing.sample`). A time-optimal
   trajectory is then checked on its samples (:func:`dualarm.limits.limit_ratios`) and slowed down
   uniformly by k = max(velocity ratio, sqrt(acceleration ratio)) should a sample still exceed a
   limit (rounding; not seen in the tests), at most :data:`SAFEGUARD_PASSES` times. A
   ``keep_timing`` trajectory is not slowed down but checked (:func:`check_limits`, its mean jerk
   per sample period too when jerk limits are given): a StageError names the joint, the time and
   the ratio if the task's timing is too fast.

Units: joint positions [rad], velocities [rad/s], accelerations [rad/s^2], times [s].
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import StageError
from dualarm.limits import LimitRatio, limit_ratios, per_joint
from dualarm.retime.timing import STAGE, Fallback, Timing, task_timing
from dualarm.retime.topp import time_optimal

#: At most this many uniform slow-downs after sampling, should a sample still exceed a limit.
SAFEGUARD_PASSES = 3
#: A joint step between samples beyond this many times what the joint's velocity limit covers in their interval, and
#: beyond JUMP_MIN_RAD, is a jump (:func:`check_jumps`).
JUMP_FACTOR = 10.0
JUMP_MIN_RAD = 1e-3


@dataclass(frozen=True)
class Retimed:
    """The retime stage's product.

    Attributes:
        trajectory: the sampled trajectory (stage ``retime``).
        stretch: the uniform slow-down applied to meet the limits between gridpoints and at the
            samples (>= 1).
        path_deviation_max_rad: largest joint difference between the trajectory at the times it
            passes the joint-path samples (:attr:`Timing.sample_times_s`) and the samples [rad].
        at_samples: the trajectory's joints at those times, (N, n) [rad].
        fallbacks: the pieces the jerk-limited timing timed by a fallback (:attr:`Timing.fallbacks`).
    """

    trajectory: JointTrajectory
    stretch: float
    path_deviation_max_rad: float
    at_samples: np.ndarray
    fallbacks: tuple[Fallback, ...] = ()


def retime_path(
    path: JointPath,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    *,
    sample_period_s: float = 0.001,
    keep_timing: bool = False,
    jerk: np.ndarray | None = None,
    position: tuple[np.ndarray, np.ndarray] | None = None,
    assumed: Callable[[str], str] = lambda kind: "",
) -> Retimed:
    """Time a joint path within joint limits and sample it.

    Args:
        path: the IK output.
        velocity: velocity limit per active joint (n,) [rad/s], positive; symmetric (+-v). A
            number applies to every joint.
        acceleration: acceleration limit per active joint (n,) [rad/s^2], positive; symmetric.
        sample_period_s: sample period of the output [s].
        keep_timing: keep the path's own timing instead of the time-optimal one, and check it
            (against ``jerk`` too, when given).
        jerk: jerk limit per active joint (n,) [rad/s^3] (or one for all): given, the timing is
            jerk-limited (:mod:`dualarm.retime.jerk`) instead of TOPP-RA's, or the task's own
            timing is checked against it.
        position: the lower and upper position limits per joint (n,) each [rad]: the jerk-limited curve stays
            within them wherever the samples do (:func:`dualarm.retime.jerk.within`).
        assumed: what a ``keep_timing`` refusal adds about a limit of a kind
            (:meth:`dualarm.model.robot.Robot.assumed`: that it was assumed).

    Returns:
        The trajectory, rest to rest, sampled every ``sample_period_s`` plus its final time, with
        when it passes the samples and how closely.

    Raises:
        StageError: a limit is not a positive finite number, the path has non-finite joints,
            TOPP-RA finds no parameterisation, the path jumps (:func:`check_jumps`; ``keep_timing`` checks the
            limits instead), or (``keep_timing``) the task's timing exceeds a limit.
    """
    if not (np.isfinite(sample_period_s) and sample_period_s > 0):
        raise StageError(
            f"{STAGE}: the sample period must be a positive number of seconds, got {sample_period_s!r}", stage=STAGE
        )
    timing = plan(path, velocity, acceleration, keep_timing=keep_timing, jerk=jerk, position=position)
    traj = timing.sample(sample_period_s)
    if keep_timing:
        check_limits(traj, velocity, acceleration, jerk, assumed)
    else:
        timing, traj = _within_limits(timing, traj, velocity, acceleration, sample_period_s)
    at_samples = timing.evaluate(timing.sample_times_s)[0]
    return Retimed(traj, timing.stretch, float(np.abs(at_samples - path.q).max()), at_samples, timing.fallbacks)


def plan(
    path: JointPath,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    *,
    keep_timing: bool = False,
    jerk: np.ndarray | None = None,
    position: tuple[np.ndarray, np.ndarray] | None = None,
) -> Timing:
    """The continuous trajectory :func:`retime_path` samples (checks the limits and the path first).

    Args:
        path: the IK output.
        velocity: velocity limit per active joint (n,) [rad/s] (or one for all).
        acceleration: acceleration limit per active joint (n,) [rad/s^2] (or one for all).
        keep_timing: the path's own timing instead of the time-optimal one.
        jerk: jerk limit per joint (n,) [rad/s^3] (or one for all): the jerk-limited timing.
        position: the lower and upper position limits per joint (n,) each [rad], for the jerk-limited timing.

    Raises:
        StageError: as :func:`retime_path`, except the ``keep_timing`` limit check, which needs samples.
    """
    v = per_joint(velocity, path.joint_names, "velocity", STAGE)
    a = per_joint(acceleration, path.joint_names, "acceleration", STAGE)
    check_path(path)
    if keep_timing:
        return task_timing(path)
    check_jumps(path, v)
    if jerk is not None:
        from dualarm.retime.jerk import jerk_limited

        return jerk_limited(path, v, a, per_joint(jerk, path.joint_names, "jerk", STAGE), position)
    return time_optimal(path, v, a)


def _within_limits(
    timing: Timing, traj: JointTrajectory, velocity: np.ndarray, acceleration: np.ndarray, period_s: float
) -> tuple[Timing, JointTrajectory]:
    """Slow ``timing`` down until its samples ``traj`` are within the limits (rarely needed).

    Each pass slows the whole trajectory down by k = max(velocity ratio, sqrt(acceleration
    ratio)) (times a relative 1e-12, against rounding) and samples it again every ``period_s`` [s];
    at most :data:`SAFEGUARD_PASSES` passes.

    Returns:
        The timing and its samples.
    """
    for _ in range(SAFEGUARD_PASSES):
        ratios = _sample_ratios(traj, velocity, acceleration)
        k = max(ratios["velocity"].ratio, np.sqrt(ratios["acceleration"].ratio))
        if k <= 1:
            break
        timing = timing.slowed(k * (1 + 1e-12))
        traj = timing.sample(period_s)
    return timing, traj


def check_limits(
    traj: JointTrajectory,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray | None = None,
    assumed: Callable[[str], str] = lambda kind: "",
) -> None:
    """Raise a StageError naming the joint, time and ratio if ``traj`` exceeds a limit.

    The ``keep_timing`` check: a limit exceeded by more than :data:`dualarm.limits.LIMIT_TOLERANCE`.

    Args:
        traj: the sampled trajectory (its ``qd`` [rad/s], ``qdd`` [rad/s^2] and mean jerk per sample period [rad/s^3]).
        velocity: velocity limit per joint (n,) [rad/s] (or one for all).
        acceleration: acceleration limit per joint (n,) [rad/s^2] (or one for all).
        jerk: jerk limit per joint (n,) [rad/s^3] (or one for all), or None: not checked.
        assumed: what the message adds about a limit of this kind (:meth:`dualarm.model.robot.Robot.assumed`).
    """
    ratios = _sample_ratios(traj, velocity, acceleration)
    if jerk is not None:
        ratios |= limit_ratios(traj.t, traj.joint_names, {"jerk": traj.mean_jerk()}, {"jerk": jerk}, STAGE)
    worst = max(ratios.values(), key=lambda r: (r.ratio, r.kind, r.joint, r.t_s))
    if worst.exceeded:
        raise StageError(
            f"{STAGE}: keep_timing: {worst.joint} reaches {worst.ratio:.3g}x its {worst.kind} limit "
            f"at t = {worst.t_s:.3f} s (the task's timing is too fast for the joint limits){assumed(worst.kind)}",
            stage=STAGE,
            t_s=worst.t_s,
            joint=worst.joint,
        )


def check_jumps(path: JointPath, velocity: np.ndarray) -> None:
    """Refuse a path that jumps: a joint step between samples no motion of the joint makes in their time.

    A step of more than :data:`JUMP_FACTOR` times what the joint's velocity limit (n,) [rad/s] covers in the
    samples' interval is not a motion the task asked for but the IK changing branch (or a path joined from two);
    no timing follows it *as a path* (any would draw a line the IK never solved through). The StageError names
    the samples, the joint and the step.
    """
    if len(path) < 2:
        return
    steps = np.abs(np.diff(path.q, axis=0))
    allowed = JUMP_FACTOR * np.maximum(np.diff(path.t), 0.0)[:, None] * velocity[None, :]
    jumps = np.argwhere((steps > allowed) & (steps > JUMP_MIN_RAD))
    if len(jumps):
        k, j = (int(x) for x in jumps[0])
        joint, t_s = path.joint_names[j], float(path.t[k + 1])
        raise StageError(
            f"{STAGE}: the joint path jumps: {joint} moves {steps[k, j]:.4g} rad between samples {k} and {k + 1} "
            f"(t = {t_s:.3f} s), more than {JUMP_FACTOR:g} times its velocity limit allows in "
            f"{float(path.t[k + 1] - path.t[k]):.4g} s; the IK left its solution there, no timing follows a jump",
            stage=STAGE,
            sample=k + 1,
            t_s=t_s,
            joint=joint,
        )


def check_path(path: JointPath) -> None:
    """Raise a StageError naming the first non-finite joint value of ``path``, or an empty path."""
    if len(path) == 0:
        raise StageError(f"{STAGE}: the joint path has no samples", stage=STAGE)
    bad = np.argwhere(~np.isfinite(path.q))
    if len(bad):
        k, j = (int(x) for x in bad[0])
        joint, t_s = path.joint_names[j], float(path.t[k])
        raise StageError(
            f"{STAGE}: the joint path's {joint} is {float(path.q[k, j])!r} at sample {k} (t = {t_s:.3f} s)",
            stage=STAGE,
            sample=k,
            t_s=t_s,
            joint=joint,
        )


def _sample_ratios(
    traj: JointTrajectory, velocity: np.ndarray | Sequence[float], acceleration: np.ndarray | Sequence[float]
) -> dict[str, LimitRatio]:
    """The largest velocity and acceleration limit ratios over the samples of ``traj``.

    kind -> :class:`dualarm.limits.LimitRatio`.
    """
    return limit_ratios(
        traj.t,
        traj.joint_names,
        {"velocity": traj.qd, "acceleration": traj.qdd},
        {"velocity": velocity, "acceleration": acceleration},
        STAGE,
    )

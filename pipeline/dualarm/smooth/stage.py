"""Jerk-limited smoothing of a retimed trajectory by online tracking with Ruckig.

The retime stage limits velocity and acceleration but not jerk: its accelerations may jump. This
stage turns its :class:`JointTrajectory` into one sampled at the control period whose velocity,
acceleration and jerk stay within given limits, starting and ending at rest.

Method. Ruckig could pass through the reference's samples as intermediate waypoints, but that
needs Ruckig Pro (the community version asks a cloud service, unreachable here). So the reference
is *tracked online*: it is resampled at the control times and clamped into the limits
(:mod:`dualarm.smooth.targets`), and every control cycle each joint's Ruckig plans a jerk-limited
motion from its current state to a target ahead on the reference and advances one period along
it (:mod:`dualarm.smooth.tracker`, which explains the adaptive look-ahead and the fallbacks).
Consequence: where the reference itself breaks the limits (a jump of acceleration is an infinite
jerk) the output cannot follow it and lags behind it; that deviation,
``|q_smooth(t) - q_reference(t)|`` per joint, is computed and returned, never hidden, as is the
look-ahead used per sample and joint (``lookahead_s``).

Guarantees. Ruckig's outputs are exact samples of the executed motion: a continuous,
twice-differentiable concatenation of the per-cycle plans, with piecewise-constant jerk. Every
plan is checked against the limits before it is used (see :mod:`dualarm.smooth.tracker`). Hence
the sampled velocity and acceleration, the mean velocity ``diff(q) / period_s`` and mean
acceleration ``diff(qd) / period_s`` over each period, and the mean jerk ``diff(qdd) / period_s``
over each period (the returned ``jerk``) all stay within the limits, up to rounding. The
binding's ``new_jerk`` is not returned: it is the plan's jerk at the sample instant, 0 whenever
the plan ends within the period (every cycle on track), not the jerk applied over the period.

Units: positions [rad], velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3], times [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from dualarm.arrays import frozen
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import StageError
from dualarm.limits import per_joint
from dualarm.smooth.targets import Targets
from dualarm.smooth.tracker import STAGE, Tracker


@dataclass(frozen=True)
class Smoothed:
    """A jerk-limited trajectory tracking a retimed reference, and how far it departs from it.

    Attributes:
        trajectory: the smoothed trajectory (stage ``smooth``), sampled every ``period_s`` from 0,
            at rest at the reference's first position at t = 0 and at its last position at the
            end; ``rep`` is the reference's at the same time (that of its last sample at or before
            it), ``fixed`` copied from the reference.
        jerk: (M, n) [rad/s^3] mean jerk over the period ending at each sample,
            ``(qdd[k] - qdd[k-1]) / period_s`` (0 at k = 0), exact for the executed motion.
        deviation_rad: (M, n) [rad] ``|q_smooth(t) - q_reference(t)|`` per joint, the reference
            linearly interpolated at t and held at its final position after it ends.
        lookahead_s: (M, n) [s] how far past each sample's time lay the reference sample the
            joint steered to when the sample was made (0: on track).
        fallbacks: number of joint-cycles that needed a fallback plan of
            :data:`dualarm.smooth.tracker.RETRIES` because Ruckig failed or its plan left the limits.
    """

    trajectory: JointTrajectory
    jerk: np.ndarray
    deviation_rad: np.ndarray
    lookahead_s: np.ndarray
    fallbacks: int = 0

    @classmethod
    def unchanged(cls, reference: JointTrajectory) -> Smoothed:
        """``reference`` passed through as it is (stage ``smooth``).

        For a timing already within the jerk limits: its mean jerk, no deviation, no look-ahead.
        """
        traj = replace(reference, stage=STAGE)
        jerk, zeros = traj.mean_jerk(), np.zeros(traj.q.shape)
        return cls(
            traj,
            frozen(jerk, jerk.shape, "jerk"),
            frozen(zeros, zeros.shape, "deviation_rad"),
            frozen(zeros, zeros.shape, "lookahead_s"),
        )

    @property
    def path_deviation_max_rad(self) -> float:
        """Largest deviation from the reference over all samples and joints [rad]."""
        return float(self.deviation_rad.max()) if self.deviation_rad.size else 0.0


def smooth_trajectory(
    reference: JointTrajectory,
    velocity: ArrayLike,
    acceleration: ArrayLike,
    jerk: ArrayLike,
    *,
    period_s: float = 0.001,
) -> Smoothed:
    """Track ``reference`` with a jerk-limited motion sampled every ``period_s``, rest to rest.

    Args:
        reference: the retimed trajectory to follow (its own jerk may exceed ``jerk``).
        velocity: velocity limit [rad/s], one for all joints or one per joint.
        acceleration: acceleration limit [rad/s^2], one for all joints or one per joint.
        jerk: jerk limit [rad/s^3], one for all joints or one per joint.
        period_s: control period [s].

    Returns:
        The smoothed trajectory, its jerk, its deviation from the reference and the look-ahead
        used (see the module docstring for the method).

    Raises:
        StageError: a limit is not finite and positive (naming the joint), the period is not, the
            reference is empty or not finite, or Ruckig fails (naming the joint and the time).
    """
    names = reference.joint_names
    v = per_joint(velocity, names, "velocity", STAGE)
    a = per_joint(acceleration, names, "acceleration", STAGE)
    j = per_joint(jerk, names, "jerk", STAGE)
    dt = _period(period_s)
    _check_reference(reference)

    tracker = Tracker(names, Targets.of(reference, dt, v, a, j), v, a, j, dt)
    q_out, qd_out, qdd_out, ahead = tracker.run()

    t = np.arange(len(q_out)) * dt
    q_ref, _, _, rep = reference.interpolate(t)
    traj = JointTrajectory(
        stage=STAGE, joint_names=names, t=t, q=q_out, qd=qd_out, qdd=qdd_out, rep=rep, fixed=dict(reference.fixed)
    )
    jerk_out = traj.mean_jerk()
    deviation = np.abs(q_out - q_ref)
    lookahead = ahead * dt
    return Smoothed(
        trajectory=traj,
        jerk=frozen(jerk_out, jerk_out.shape, "jerk"),
        deviation_rad=frozen(deviation, deviation.shape, "deviation_rad"),
        lookahead_s=frozen(lookahead, lookahead.shape, "lookahead_s"),
        fallbacks=tracker.fallbacks,
    )


def _check_reference(reference: JointTrajectory) -> None:
    """StageError if ``reference`` has no samples, or a non-finite position, velocity or acceleration.

    The error names the joint.
    """
    names = reference.joint_names
    if len(reference) == 0:
        raise StageError(f"{STAGE}: the reference trajectory has no samples", stage=STAGE)
    for label, arr in (("position", reference.q), ("velocity", reference.qd), ("acceleration", reference.qdd)):
        bad = ~np.isfinite(arr).all(axis=0)
        if bad.any():
            joint = names[int(np.argmax(bad))]
            raise StageError(
                f"{STAGE}: the reference {label} of joint '{joint}' is not finite", stage=STAGE, joint=joint
            )


def _period(period_s: float) -> float:
    """``period_s`` [s] as a float; StageError if it is not finite and positive."""
    try:
        dt = float(period_s)
    except (TypeError, ValueError):
        raise StageError(
            f"{STAGE}: the control period must be a number of seconds, got {period_s!r}", stage=STAGE
        ) from None
    if not (math.isfinite(dt) and dt > 0):
        raise StageError(f"{STAGE}: the control period is {dt} s; it must be finite and positive", stage=STAGE)
    return dt

"""Jerk-limited smoothing of a retimed trajectory by online tracking with Ruckig.

The retime stage limits velocity and acceleration but not jerk: its accelerations may jump. This
stage turns its :class:`JointTrajectory` into one sampled at the control period whose velocity,
acceleration and jerk stay within given limits, starting and ending at rest.

Method. Ruckig could pass through the reference's samples as intermediate waypoints, but that
needs Ruckig Pro (the community version asks a cloud service, unreachable here). So the reference
is *tracked online*: every control cycle, Ruckig's ``update()`` plans a jerk-limited motion from
the current state to a target state taken from the reference and advances one period along it;
``pass_to_input()`` makes the state reached the start of the next cycle. Consequence: where the
reference itself breaks the limits (a jump of acceleration is an infinite jerk) the output cannot
follow it and lags behind it; that deviation, ``|q_smooth(t) - q_reference(t)|`` per joint, is
computed and returned, never hidden.

Targets. The reference is resampled at the control times ``t_k = k * period_s`` (linear
interpolation of q, qd and qdd between its samples) and held at its final position, at rest,
after it ends. Each joint has its own one-DOF Ruckig: the joints are coordinated by the shared
reference clock rather than by Ruckig's time synchronisation, and each joint may aim at a
different reference time. In the cycle from t_k, joint i aims at the reference sample at
``t_(k+m)``, ``m >= 1``, and is asked to arrive exactly then (``minimum_duration = m * period_s``):

* On track, ``m = 1``: the sample one period ahead is reachable within the period, and the output
  reproduces a jerk-feasible reference at the samples (deviation at rounding level).
* Behind, ``m`` is the earliest sample the joint can still reach in time (Ruckig's time-optimal
  duration to it is at most ``m * period_s``), found by marching ahead in doubling steps and
  bisecting, and kept from cycle to cycle (``m - 1`` next time) while it stays reachable: the
  joint cuts the reference's corner time-optimally and rejoins it. This adaptive look-ahead is
  what makes the tracking sound. Ruckig plans as if the target stood still; aimed at the
  reference's *current* state, which moves at full speed a few millimetres ahead, it plans an
  overshoot and reversal every cycle, drives the joint backwards and falls far behind: measured
  0.42 rad behind a trapezoidal-velocity reference at v = 1 rad/s, a = 3 rad/s^2, j = 30 rad/s^3,
  against 0.05 rad with interception, the S-curve's own lag ``v * a / (2 j)``.

The look-ahead used is returned per sample and joint (``lookahead_s``).

Clamping. Ruckig refuses (``RuckigError``) a target whose velocity or acceleration exceeds the
limits, or from which the velocity limit is inevitably crossed. Each target is therefore clamped:
``|qd| <= v``, ``|qdd| <= a * (1 - 1e-9)`` (see :data:`TARGET_INSET`) and ``qdd^2 / (2 j) + |qdd| * period_s <= v - |qd|``, which keeps the
velocity within its limit while the acceleration is brought back to zero, before or after the
target, even if Ruckig holds the target's acceleration for up to one period. A jerk-feasible
reference is not changed by the first two and barely by the third; the target positions are
never changed.

Guarantees. Ruckig's outputs are exact samples of the executed motion: a continuous,
twice-differentiable concatenation of the per-cycle plans, with piecewise-constant jerk. Every
plan is checked against the limits before it is used (see Robustness). Hence the sampled
velocity and acceleration, the mean velocity ``diff(q) / period_s`` and mean acceleration
``diff(qd) / period_s`` over each period, and the mean jerk ``diff(qdd) / period_s`` over each
period (the returned ``jerk``) all stay within the limits, up to rounding. The binding's
``new_jerk`` is not returned: it is the plan's jerk at the sample instant, 0 whenever the plan
ends within the period (every cycle on track), not the jerk applied over the period.

Robustness. Ruckig's community solver has numerical failures: it can raise with the current or
target acceleration at its limit or the state on the edge of the velocity limit, return a plan
slower than optimal, and, when stretching a profile to a given duration, return a plan that
leaves the limits. A failed or invalid plan is replaced by the next of :data:`RETRIES`
(time-optimal, then toward a target shrunk by up to 1e-3, then from the current acceleration
shrunk toward zero by 1e-12 or 1e-10: a jerk error of at most ``1e-10 * a / period_s``); the
joint-cycles that needed one are counted in ``fallbacks``. If none works, or Ruckig reports an
error, a :class:`StageError` names the joint, the time and Ruckig's message.

Units: positions [rad], velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3], times [s].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import ruckig

from pipeline.errors import StageError
from pipeline.retime.trajectory import JointTrajectory

#: Name of the stage, as recorded in the output trajectory.
STAGE = "smooth"

#: Relative distance by which target accelerations are kept inside their limits: Ruckig
#: 0.19's community solver can crash (segmentation fault) with the current and target
#: accelerations both exactly at the limit and the positions equal.
TARGET_INSET = 1e-9

#: Relative slack when checking a plan of Ruckig against the limits (rounding).
LIMIT_SLACK = 1e-9

#: Plans tried in turn for a joint in a cycle until one is found within the limits: (arrive
#: exactly when aimed, relative shrinking of the target's velocity and acceleration, relative
#: shrinking of the current acceleration toward zero). The first is the plan; the others work
#: around numerical failures of Ruckig's community solver (see ``_Tracker._step``).
RETRIES = (
    (True, 0.0, 0.0),
    (False, 0.0, 0.0),
    (False, 1e-9, 0.0),
    (False, 1e-6, 0.0),
    (False, 0.0, 1e-12),
    (False, 1e-6, 1e-12),
    (False, 1e-3, 1e-10),
)

#: Relative slack when comparing a time-optimal duration with the time available.
DURATION_SLACK = 1e-9

#: Bound on the time the tracker may take after the reference ends, in traverses of the
#: reference's span at full speed (with full stops), plus :data:`REST_MARGIN_S` [s].
TAIL_FACTOR = 10.0
REST_MARGIN_S = 1.0

_OK = (ruckig.Result.Working, ruckig.Result.Finished)


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
        fallbacks: number of joint-cycles that needed a fallback plan of :data:`RETRIES` because
            Ruckig failed or its plan left the limits.
    """

    trajectory: JointTrajectory
    jerk: np.ndarray
    deviation_rad: np.ndarray
    lookahead_s: np.ndarray
    fallbacks: int = 0

    @property
    def path_deviation_max_rad(self) -> float:
        """Largest deviation from the reference over all samples and joints [rad]."""
        return float(self.deviation_rad.max()) if self.deviation_rad.size else 0.0


def limit_ratios(
    traj: JointTrajectory,
    jerk: np.ndarray,
    velocity: float | Sequence[float],
    acceleration: float | Sequence[float],
    jerk_limit: float | Sequence[float],
) -> dict[str, float]:
    """Largest ratio of |velocity|, |acceleration| and |jerk| to their limits over the samples.

    Args:
        traj: the trajectory (its ``qd`` [rad/s] and ``qdd`` [rad/s^2]).
        jerk: (M, n) jerk samples [rad/s^3], e.g. :attr:`Smoothed.jerk`.
        velocity, acceleration, jerk_limit: limits [rad/s, rad/s^2, rad/s^3], one for all joints
            or one per joint.

    Returns:
        ``velocity_ratio_max``, ``acceleration_ratio_max`` and ``jerk_ratio_max`` (1 = at a limit;
        0 for an empty trajectory).

    Raises:
        StageError: a limit is not finite and positive, or there is not one per joint.
    """
    names = traj.joint_names
    jerk = np.asarray(jerk, dtype=float)
    if jerk.shape != traj.q.shape:
        raise StageError(f"{STAGE}: jerk: expected shape {traj.q.shape}, got {jerk.shape}")
    ratios = {}
    for key, samples, limit, kind in (
        ("velocity_ratio_max", traj.qd, velocity, "velocity"),
        ("acceleration_ratio_max", traj.qdd, acceleration, "acceleration"),
        ("jerk_ratio_max", jerk, jerk_limit, "jerk"),
    ):
        lim = _limits(kind, limit, names)
        ratios[key] = float((np.abs(samples) / lim).max()) if samples.size else 0.0
    return ratios


def smooth(
    reference: JointTrajectory,
    velocity: float | Sequence[float],
    acceleration: float | Sequence[float],
    jerk: float | Sequence[float],
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
    v = _limits("velocity", velocity, names)
    a = _limits("acceleration", acceleration, names)
    j = _limits("jerk", jerk, names)
    dt = _period(period_s)
    if len(reference) == 0:
        raise StageError(f"{STAGE}: the reference trajectory has no samples")
    for label, arr in (("position", reference.q), ("velocity", reference.qd), ("acceleration", reference.qdd)):
        bad = ~np.isfinite(arr).all(axis=0)
        if bad.any():
            raise StageError(f"{STAGE}: the reference {label} of joint '{names[int(np.argmax(bad))]}' is not finite")

    targets = _Targets.of(reference, dt, v, a, j)
    tracker = _Tracker(names, targets, v, a, j, dt)
    q_out, qd_out, qdd_out, ahead = tracker.run()

    t = np.arange(len(q_out)) * dt
    jerk_out = np.zeros_like(qdd_out)
    jerk_out[1:] = np.diff(qdd_out, axis=0) / dt
    q_ref, _, _, rep = reference.interpolate(t)
    traj = JointTrajectory(
        stage=STAGE,
        joint_names=names,
        t=t,
        q=q_out,
        qd=qd_out,
        qdd=qdd_out,
        rep=rep,
        fixed=dict(reference.fixed),
    )
    return Smoothed(
        trajectory=traj,
        jerk=_frozen(jerk_out),
        deviation_rad=_frozen(np.abs(q_out - q_ref)),
        lookahead_s=_frozen(ahead * dt),
        fallbacks=tracker.fallbacks,
    )


@dataclass(frozen=True)
class _Targets:
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
    def of(cls, ref: JointTrajectory, dt: float, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray) -> "_Targets":
        """Resample ``ref`` every ``dt`` [s] and clamp the targets into the limits (module docstring)."""
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

    def at(self, index: np.ndarray, i: int | None = None):
        """Position, velocity and acceleration targets of the rows ``index`` (clipped to ``end``),
        one per joint, or of joint ``i`` at row ``index``."""
        if i is not None:
            r = min(int(index), self.end)
            return self.p[r, i], self.v[r, i], self.a[r, i]
        rows = np.minimum(index, self.end)
        cols = np.arange(self.p.shape[1])
        return self.p[rows, cols], self.v[rows, cols], self.a[rows, cols]


class _Tracker:
    """The control loop: one one-DOF Ruckig per joint, and a multi-DOF one to probe durations."""

    def __init__(self, names: tuple[str, ...], targets: _Targets, v: np.ndarray, a: np.ndarray, j: np.ndarray, dt: float):
        n = len(names)
        self.names, self.targets, self.dt, self.n = names, targets, dt, n
        self.bounds = [(float(x) * (1 + LIMIT_SLACK), float(y) * (1 + LIMIT_SLACK), float(z) * (1 + LIMIT_SLACK)) for x, y, z in zip(v, a, j)]
        self.fallbacks = 0
        self.otgs = [ruckig.Ruckig(1, dt) for _ in range(n)]
        self.inps = [ruckig.InputParameter(1) for _ in range(n)]
        self.outs = [ruckig.OutputParameter(1) for _ in range(n)]
        for i, inp in enumerate(self.inps):
            inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v[i]], [a[i]], [j[i]]
            inp.current_position, inp.current_velocity, inp.current_acceleration = [targets.p[0, i]], [0.0], [0.0]
        self.probe = ruckig.Ruckig(n)
        self.probe_inp = ruckig.InputParameter(n)
        self.probe_traj = ruckig.Trajectory(n)
        self.probe_inp.max_velocity, self.probe_inp.max_acceleration, self.probe_inp.max_jerk = list(v), list(a), list(j)
        self.probe_inp.synchronization = ruckig.Synchronization.No
        # a bound against endless loops only: the reference, then TAIL_FACTOR times a traverse of
        # its span and full stops (Ruckig's community solver can find plans slower than optimal)
        span = np.ptp(targets.p, axis=0)
        tail = TAIL_FACTOR * float(np.max(span / v + v / a + a / j)) + REST_MARGIN_S
        self.max_cycles = targets.end + math.ceil(tail / dt) + 2

    def run(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cycle until every joint rests at the reference's final position.

        Returns:
            q, qd, qdd (M, n) and the look-ahead of each sample in periods (M, n), 0 at k = 0.
        """
        n, end = self.n, self.targets.end
        q = [self.targets.p[0].copy()]
        qd = [np.zeros(n)]
        qdd = [np.zeros(n)]
        ahead = [np.zeros(n, dtype=int)]
        state = np.stack([q[0], qd[0], qdd[0]])
        m = np.ones(n, dtype=int)
        for k in range(self.max_cycles):
            m = self._leads(k, state, m)
            finished = True
            for i in range(n):
                result = self._step(i, k, int(m[i]))
                out = self.outs[i]
                state[:, i] = out.new_position[0], out.new_velocity[0], out.new_acceleration[0]
                out.pass_to_input(self.inps[i])
                finished = finished and result == ruckig.Result.Finished
            q.append(state[0].copy())
            qd.append(state[1].copy())
            qdd.append(state[2].copy())
            ahead.append(m - 1)
            if finished and (k + m >= end).all():
                return np.array(q), np.array(qd), np.array(qdd), np.array(ahead)
        raise StageError(f"{STAGE}: the tracker did not come to rest at the reference's final position within {self.max_cycles * self.dt:.3f} s")

    def _step(self, i: int, k: int, m: int) -> ruckig.Result:
        """Plan joint i from t_k to the target row k + m, arriving in m periods; advance one period.

        Ruckig's community solver occasionally fails (near the acceleration limit, or with the
        state on the edge of the velocity limit), or, stretching a profile to a given duration,
        returns a plan that leaves the limits. Each plan is therefore checked, and a failed or
        invalid one is replaced by the next of :data:`RETRIES`: time-optimal plans to the target,
        then to the target with its velocity and acceleration shrunk, then from the current
        acceleration shrunk toward zero by a relative 1e-12 or 1e-10 (a jerk error of at most
        ``1e-10 * a / period_s`` in the samples).
        """
        inp, otg, out = self.inps[i], self.otgs[i], self.outs[i]
        p, v, a = self.targets.at(k + m, i)
        a0 = inp.current_acceleration[0]
        inp.target_position = [p]
        failure = ""
        for attempt, (stretch, target_shrink, state_shrink) in enumerate(RETRIES):
            inp.target_velocity, inp.target_acceleration = [v * (1 - target_shrink)], [a * (1 - target_shrink)]
            inp.current_acceleration = [a0 * (1 - state_shrink)]
            inp.minimum_duration = m * self.dt if stretch else None
            if attempt:
                otg.reset()  # Ruckig compares inputs without their minimum duration: force a new plan
            try:
                result = otg.update(inp, out)
            except ruckig.RuckigError as e:
                failure = (str(e).strip().splitlines() or ["RuckigError"])[0].strip()
                continue
            if result not in _OK:
                failure = f"Ruckig returned {result.name}"
                continue
            failure = self._outside(i, out.trajectory.profiles[0][0])
            if not failure:
                self.fallbacks += attempt > 0
                return result
        raise StageError(f"{STAGE}: no motion within the limits for joint '{self.names[i]}' at t = {k * self.dt:.4f} s: {failure}")

    def _outside(self, i: int, profile) -> str:
        """Why the plan ``profile`` of joint i (with its braking pre-phases) leaves a limit, or ''."""
        vmax, amax, jmax = self.bounds[i]
        brake = profile.brake
        phases = [(brake.t, brake.j, brake.a, brake.v)] if brake.duration > 0 else []
        for t, j, a, v in (*phases, (profile.t, profile.j, profile.a, profile.v)):
            for h in range(len(t)):
                if t[h] <= 0:
                    continue
                if abs(j[h]) > jmax:
                    return f"the plan's jerk {j[h]:.6g} rad/s^3 exceeds the limit"
                if abs(a[h]) > amax:
                    return f"the plan's acceleration {a[h]:.6g} rad/s^2 exceeds the limit"
                peak = abs(v[h])
                a_end = a[h] + j[h] * t[h]
                if a[h] * a_end < 0:  # the velocity turns inside the phase
                    peak = max(peak, abs(v[h] - a[h] ** 2 / (2 * j[h])))
                if peak > vmax:
                    return f"the plan's velocity {peak:.6g} rad/s exceeds the limit"
                if abs(a_end) > amax:
                    return f"the plan's acceleration {a_end:.6g} rad/s^2 exceeds the limit"
        return ""

    def _durations(self, state: np.ndarray, rows: np.ndarray) -> np.ndarray | None:
        """Time-optimal duration [s] of each joint from ``state`` to its target row, or None if
        Ruckig fails."""
        inp = self.probe_inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = list(state[0]), list(state[1]), list(state[2])
        p, v, a = self.targets.at(rows)
        inp.target_position, inp.target_velocity, inp.target_acceleration = list(p), list(v), list(a)
        try:
            result = self.probe.calculate(inp, self.probe_traj)
        except ruckig.RuckigError:
            return None
        if result not in _OK:
            return None
        return np.array(self.probe_traj.independent_min_durations)

    def _leads(self, k: int, state: np.ndarray, m_prev: np.ndarray) -> np.ndarray:
        """Periods ahead (>= 1) each joint aims at in the cycle from t_k: ``m_prev - 1`` while it is
        still reachable in time, else the earliest reachable sample (marching ahead in doubling
        steps, then bisecting). A probe that Ruckig fails on leaves the current choice."""
        dt, end = self.dt, self.targets.end
        m = np.maximum(1, m_prev - 1)
        durations = self._durations(state, k + m)
        if durations is None:
            return m
        ok = durations <= m * dt * (1 + DURATION_SLACK)
        if ok.all():
            return m
        # from the final-rest row on, the target stands still: reachable once the time suffices
        rest = self._durations(state, np.full(self.n, end))
        if rest is None:
            return m
        lo = m  # for the joints not ok: not reachable in time
        hi = np.where(ok, m, np.maximum(np.maximum(end - k, 1) + np.ceil(rest / dt * (1 + DURATION_SLACK)).astype(int), m + 1))
        # march ahead in doubling steps to the first reachable sample, then bisect: the earliest
        # meeting, where reachability may come and go, not merely some meeting
        step = np.ones(self.n, dtype=int)
        while (~ok & (lo + step < hi)).any():
            mid = np.where(~ok & (lo + step < hi), lo + step, m)
            durations = self._durations(state, k + mid)
            if durations is None:
                break
            probed = mid != m
            reach = probed & (durations <= mid * dt * (1 + DURATION_SLACK))
            hi = np.where(reach, mid, hi)
            lo = np.where(probed & ~reach, mid, lo)
            step = np.where(reach, hi - lo, 2 * step)
        while (hi - lo > 1).any():
            mid = np.where(ok, m, (lo + hi) // 2)
            durations = self._durations(state, k + mid)
            if durations is None:
                break
            reach = durations <= mid * dt * (1 + DURATION_SLACK)
            hi = np.where(~ok & reach, mid, hi)
            lo = np.where(~ok & ~reach, mid, lo)
        return np.where(ok, m, hi)


def _limits(kind: str, value, names: tuple[str, ...]) -> np.ndarray:
    """One ``kind`` limit per joint, as an array; StageError naming the joint if one is not
    finite and positive."""
    unit = {"velocity": "rad/s", "acceleration": "rad/s^2", "jerk": "rad/s^3"}[kind]
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise StageError(f"{STAGE}: the {kind} limit must be a number or one number per joint, got {value!r}") from None
    if arr.ndim == 0:
        arr = np.full(len(names), float(arr))
    if arr.shape != (len(names),):
        raise StageError(f"{STAGE}: expected one {kind} limit or {len(names)} (one per joint), got {arr.size}")
    for name, x in zip(names, arr):
        if not (math.isfinite(x) and x > 0):
            raise StageError(f"{STAGE}: the {kind} limit of joint '{name}' is {x} {unit}; it must be finite and positive")
    return arr


def _period(period_s: float) -> float:
    """``period_s`` as a float; StageError if it is not finite and positive."""
    try:
        dt = float(period_s)
    except (TypeError, ValueError):
        raise StageError(f"{STAGE}: the control period must be a number of seconds, got {period_s!r}") from None
    if not (math.isfinite(dt) and dt > 0):
        raise StageError(f"{STAGE}: the control period is {dt} s; it must be finite and positive")
    return dt


def _frozen(a: np.ndarray) -> np.ndarray:
    """A read-only float copy of ``a``."""
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a

"""The smooth stage's control loop: online tracking of the targets with Ruckig, one joint at a time.

Tracking. Every control cycle, Ruckig's ``update()`` plans a jerk-limited motion from the current
state to a target state taken from the reference (:class:`~dualarm.smooth.targets.Targets`) and
advances one period along it; ``pass_to_input()`` makes the state reached the start of the next
cycle.

Look-ahead. Each joint has its own one-DOF Ruckig: the joints are coordinated by the shared
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

The durations are probed by a multi-DOF Ruckig without synchronisation (each joint's
time-optimal duration). The look-ahead used is returned per sample and joint.

Robustness. Ruckig's community solver has numerical failures: it can raise with the current or
target acceleration at its limit or the state on the edge of the velocity limit, return a plan
slower than optimal, and, when stretching a profile to a given duration, return a plan that
leaves the limits. Every plan is checked against the limits before it is used; a failed or
invalid plan is replaced by the next of :data:`RETRIES` (time-optimal, then toward a target
shrunk by up to 1e-3, then from the current acceleration shrunk toward zero by 1e-12 or 1e-10: a
jerk error of at most ``1e-10 * a / period_s``); the joint-cycles that needed one are counted in
:attr:`Tracker.fallbacks`. If none works, or Ruckig reports an error, a :class:`StageError` names
the joint, the time and Ruckig's message.

Units: positions [rad], velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3], times [s].
"""

from __future__ import annotations

import math

import numpy as np
import ruckig

from dualarm.errors import StageError
from dualarm.smooth.targets import DURATION_SLACK, Targets

#: Name of the stage, as recorded in the output trajectory and in messages.
STAGE = "smooth"

#: Relative slack when checking a plan of Ruckig against the limits (rounding).
LIMIT_SLACK = 1e-9

#: Plans tried in turn for a joint in a cycle until one is found within the limits: (arrive
#: exactly when aimed, relative shrinking of the target's velocity and acceleration, relative
#: shrinking of the current acceleration toward zero). The first is the plan; the others work
#: around numerical failures of Ruckig's community solver (see ``Tracker._step``).
RETRIES = (
    (True, 0.0, 0.0),
    (False, 0.0, 0.0),
    (False, 1e-9, 0.0),
    (False, 1e-6, 0.0),
    (False, 0.0, 1e-12),
    (False, 1e-6, 1e-12),
    (False, 1e-3, 1e-10),
)

#: Bound on the time the tracker may take after the reference ends, in traverses of the
#: reference's span at full speed (with full stops), plus :data:`REST_MARGIN_S` [s].
TAIL_FACTOR = 10.0
REST_MARGIN_S = 1.0

_OK = (ruckig.Result.Working, ruckig.Result.Finished)


class Tracker:
    """The control loop: one one-DOF Ruckig per joint, and a multi-DOF one to probe durations.

    Attributes:
        names: the joints.
        targets: the targets steered to.
        dt: the control period [s].
        n: the number of joints.
        bounds: per joint, the velocity [rad/s], acceleration [rad/s^2] and jerk [rad/s^3] limits
            a plan is checked against (the limits plus :data:`LIMIT_SLACK`).
        fallbacks: number of joint-cycles so far that needed a fallback plan of :data:`RETRIES`.
        max_cycles: the most control cycles :meth:`run` takes before giving up.
    """

    def __init__(
        self, names: tuple[str, ...], targets: Targets, v: np.ndarray, a: np.ndarray, j: np.ndarray, dt: float
    ):
        """Set up the Ruckig instances, at rest at the first target.

        Args:
            names: the joints.
            targets: the targets (:meth:`Targets.of` with the same limits and period).
            v, a, j: velocity [rad/s], acceleration [rad/s^2] and jerk [rad/s^3] limits per joint (n,).
            dt: the control period [s].
        """
        n = len(names)
        self.names, self.targets, self.dt, self.n = names, targets, dt, n
        self.bounds = [
            (float(x) * (1 + LIMIT_SLACK), float(y) * (1 + LIMIT_SLACK), float(z) * (1 + LIMIT_SLACK))
            for x, y, z in zip(v, a, j, strict=True)
        ]
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
        self.probe_inp.max_velocity, self.probe_inp.max_acceleration, self.probe_inp.max_jerk = (
            list(v),
            list(a),
            list(j),
        )
        self.probe_inp.synchronization = ruckig.Synchronization.No
        # a bound against endless loops only: the reference, then TAIL_FACTOR times a traverse of
        # its span and full stops (Ruckig's community solver can find plans slower than optimal)
        span = np.ptp(targets.p, axis=0)
        tail = TAIL_FACTOR * float(np.max(span / v + v / a + a / j)) + REST_MARGIN_S
        self.max_cycles = targets.end + math.ceil(tail / dt) + 2

    def run(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cycle until every joint rests at the reference's final position.

        Returns:
            q [rad], qd [rad/s], qdd [rad/s^2] (M, n) and the look-ahead of each sample in periods
            (M, n), 0 at k = 0.

        Raises:
            StageError: no plan within the limits for a joint, or no rest within :attr:`max_cycles`.
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
        raise StageError(
            f"{STAGE}: the tracker did not come to rest at the reference's final position "
            f"within {self.max_cycles * self.dt:.3f} s",
            stage=STAGE,
        )

    def _step(self, i: int, k: int, m: int) -> ruckig.Result:
        """Plan joint i from t_k to the target row k + m, arriving in m periods; advance one period.

        Ruckig's community solver occasionally fails (near the acceleration limit, or with the
        state on the edge of the velocity limit), or, stretching a profile to a given duration,
        returns a plan that leaves the limits. Each plan is therefore checked, and a failed or
        invalid one is replaced by the next of :data:`RETRIES`: time-optimal plans to the target,
        then to the target with its velocity and acceleration shrunk, then from the current
        acceleration shrunk toward zero by a relative 1e-12 or 1e-10 (a jerk error of at most
        ``1e-10 * a / period_s`` in the samples).

        Raises:
            StageError: no plan of :data:`RETRIES` works (naming the joint, the time and why).
        """
        inp, otg, out = self.inps[i], self.otgs[i], self.outs[i]
        p, v, a = self.targets.joint(k + m, i)
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
        joint, t_s = self.names[i], k * self.dt
        raise StageError(
            f"{STAGE}: no motion within the limits for joint '{joint}' at t = {t_s:.4f} s: {failure}",
            stage=STAGE,
            sample=k,
            t_s=t_s,
            joint=joint,
        )

    def _outside(self, i: int, profile: ruckig.Profile) -> str:
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
        """Time-optimal duration [s] of each joint from ``state`` (3, n) to its target row ``rows`` (n,).

        None if Ruckig fails.
        """
        inp = self.probe_inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = (
            list(state[0]),
            list(state[1]),
            list(state[2]),
        )
        p, v, a = self.targets.rows(rows)
        inp.target_position, inp.target_velocity, inp.target_acceleration = list(p), list(v), list(a)
        try:
            result = self.probe.calculate(inp, self.probe_traj)
        except ruckig.RuckigError:
            return None
        if result not in _OK:
            return None
        return np.array(self.probe_traj.independent_min_durations)

    def _leads(self, k: int, state: np.ndarray, m_prev: np.ndarray) -> np.ndarray:
        """Periods ahead (>= 1) each joint aims at in the cycle from t_k.

        ``m_prev - 1`` while it is still reachable in time, else the earliest reachable sample (marching ahead in
        doubling steps, then bisecting).

        A probe that Ruckig fails on leaves the current choice.
        """
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
        hi = np.where(
            ok, m, np.maximum(np.maximum(end - k, 1) + np.ceil(rest / dt * (1 + DURATION_SLACK)).astype(int), m + 1)
        )
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

"""Retime a joint path: time-optimal within joint velocity and acceleration limits (TOPP-RA).

The IK stage gives joint positions sample by sample (a :class:`JointPath`). This stage turns them
into a trajectory over time, q(t), qd(t), qdd(t), sampled at a fixed period, that passes through
every IK sample and keeps every joint within its velocity and acceleration limits.

The geometric path. All active joints (both arms) form ONE path, so the arms stay synchronised.
Its parameter s is the cumulative joint-space chord length [rad], the Euclidean norm of the
differences of consecutive samples. Consecutive samples closer than :data:`DUPLICATE_CHORD_RAD`
(holds: the IK repeats a configuration) are dropped first; they would give zero-length spline
intervals. ``toppra.SplineInterpolator(s, q)`` (a not-a-knot cubic spline per joint) passes
through the kept samples exactly at their s. A path whose samples are all equal (length ~0) gives
a trajectory of a single sample at rest (duration 0).

The time parameterisation. ``toppra.algorithm.TOPPRA`` with ``JointVelocityConstraint`` and
``JointAccelerationConstraint`` (symmetric limits), rest to rest (``compute_trajectory(0, 0)``),
and these settings:

- ``parametrizer="ParametrizeConstAccel"``: the path acceleration s'' is constant between
  gridpoints, which is exactly what TOPP-RA optimised. The default ``ParametrizeSpline`` refits a
  cubic spline through the gridpoint times and overshoots the acceleration limits.
- gridpoints: the IK samples' s values, every interval split into at least
  :data:`GRID_SUBDIVISIONS` equal stages and into stages no longer than
  :data:`MAX_GRID_STEP_RAD`, with at least :data:`MIN_GRIDPOINTS` points. Containing the IK
  samples gives the time at which the trajectory passes each of them exactly
  (:attr:`Timing.sample_times_s`).
- TOPP-RA enforces the limits at the gridpoints only (the velocity at each gridpoint, the
  acceleration at both ends of each stage: toppra's interpolation discretisation). Between
  gridpoints q'(s) and q''(s) vary along the spline, so the limits can be exceeded there: by about
  1e-4 (relative) on a smooth path, by much more where the path turns sharply (a reversal of all
  joints, where the chord-length spline has a large q''). So the stage evaluates the limit ratios
  at :data:`CHECK_POINTS_PER_STAGE` + 1 points of every stage, splits the stages exceeding
  1 + :data:`REFINE_TOLERANCE` in two and runs TOPP-RA again (at most :data:`MAX_REFINEMENTS`
  runs), then slows the whole trajectory down uniformly by the remaining ratio
  k = max(velocity ratio, sqrt(acceleration ratio)) >= 1 (t -> k t scales qd by 1/k and qdd by
  1/k^2), recorded as :attr:`Timing.stretch`. Last, :func:`retime` checks the output samples and
  slows down again should one still exceed a limit (rounding; not seen in the tests).

s(t) is evaluated in closed form from TOPP-RA's gridpoints and path velocities, the same formula
as ``ParametrizeConstAccel`` (vectorised): on stage i, s = s_i + s'_i dt + u_i dt^2 / 2 with
u_i = (s'_{i+1}^2 - s'_i^2) / (2 (s_{i+1} - s_i)), and q = P(s), qd = P'(s) s', qdd = P''(s) s'^2 +
P'(s) u_i. Knowing s(t) gives the repetition index of each sample (that of the last IK sample
passed) and the time of each IK sample.

``keep_timing=True`` keeps the task's own timing instead: a clamped cubic spline of q over the
path's t (rest at both ends), checked against the limits on the sampled trajectory; a StageError
names the joint, the time and the ratio if it is too fast.

Units: joint positions [rad], velocities [rad/s], accelerations [rad/s^2], times [s]. The path
parameter s is in [rad] (a joint-space length), its derivatives in [rad/s] and [rad/s^2].
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint
from scipy.interpolate import CubicSpline

from pipeline.errors import StageError
from pipeline.ik.joint_path import JointPath
from pipeline.retime.trajectory import JointTrajectory

#: The stage name, in messages and in :attr:`JointTrajectory.stage`.
STAGE = "retime"
#: Consecutive samples closer than this (Euclidean, over all active joints) are one sample [rad].
DUPLICATE_CHORD_RAD = 1e-9
#: Each interval between IK samples is split into at least this many TOPP-RA stages.
GRID_SUBDIVISIONS = 2
#: Longest TOPP-RA stage [rad of path length].
MAX_GRID_STEP_RAD = 0.01
#: Fewest TOPP-RA gridpoints (toppra's own default minimum).
MIN_GRIDPOINTS = 100
#: The limit check after TOPP-RA evaluates each stage at this many + 1 evenly spaced points.
CHECK_POINTS_PER_STAGE = 8
#: A stage whose limit ratio exceeds 1 by more than this is split in two and TOPP-RA run again.
REFINE_TOLERANCE = 1e-3
#: At most this many TOPP-RA runs (the first one and its refinements).
MAX_REFINEMENTS = 8
#: At most this many uniform slow-downs after sampling, should a sample still exceed a limit.
SAFEGUARD_PASSES = 3
#: Relative excess over a limit that ``keep_timing`` tolerates.
LIMIT_TOLERANCE = 1e-6

#: (t [s]) -> (q [rad], qd [rad/s], qdd [rad/s^2]), each (len(t), n).
Evaluator = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Timing:
    """A continuous joint trajectory along a joint path, before sampling.

    Attributes:
        method: ``topp-ra`` (time-optimal) or ``keep_timing`` (the task's own timing).
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
    """

    method: str
    joint_names: tuple[str, ...]
    duration_s: float
    sample_times_s: np.ndarray
    rep: np.ndarray
    evaluate: Evaluator
    stretch: float = 1.0
    fixed: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "fixed", MappingProxyType(dict(self.fixed)))

    def sample(self, period_s: float) -> JointTrajectory:
        """The trajectory sampled every ``period_s`` [s], plus its final time.

        The last step lies between half and one and a half periods (a sample closer than half a
        period to the end is replaced by the end). Each sample's ``rep`` is that of the last
        joint-path sample the trajectory has passed (``sample_times_s`` <= t).
        """
        t = sample_grid(self.duration_s, period_s)
        q, qd, qdd = self.evaluate(t)
        passed = np.clip(np.searchsorted(self.sample_times_s, t, side="right") - 1, 0, len(self.rep) - 1)
        if len(t) == 1:
            passed = np.array([len(self.rep) - 1])
        return JointTrajectory(stage=STAGE, joint_names=self.joint_names, t=t, q=q, qd=qd, qdd=qdd, rep=self.rep[passed], fixed=self.fixed)

    def slowed(self, k: float) -> "Timing":
        """The same motion ``k`` (>= 1) times slower: q(t / k), qd / k, qdd / k^2."""
        return replace(self, duration_s=k * self.duration_s, sample_times_s=k * self.sample_times_s, evaluate=_Slowed(self.evaluate, k), stretch=k * self.stretch)


@dataclass(frozen=True)
class _Slowed:
    """An evaluator run ``k`` times slower."""

    evaluate: Evaluator
    k: float

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q, qd, qdd = self.evaluate(np.asarray(t, dtype=float) / self.k)
        return q, qd / self.k, qdd / self.k**2


@dataclass(frozen=True)
class LimitRatios:
    """The largest |qd| / velocity limit and |qdd| / acceleration limit over a trajectory's samples.

    Attributes:
        velocity_ratio_max: largest |qd_j| / v_j over samples and joints (1 = at the limit).
        acceleration_ratio_max: largest |qdd_j| / a_j over samples and joints.
        velocity_joint, acceleration_joint: the joint where each maximum occurs.
        velocity_time_s, acceleration_time_s: the time of each maximum [s].
    """

    velocity_ratio_max: float
    acceleration_ratio_max: float
    velocity_joint: str
    acceleration_joint: str
    velocity_time_s: float
    acceleration_time_s: float


@dataclass(frozen=True)
class Retimed:
    """The retime stage's product.

    Attributes:
        trajectory: the sampled trajectory (stage ``retime``).
        stretch: the uniform slow-down applied to meet the limits between gridpoints and at the
            samples (>= 1).
        path_deviation_max_rad: largest joint difference between the trajectory at the times it
            passes the joint-path samples (:attr:`Timing.sample_times_s`) and the samples [rad].
    """

    trajectory: JointTrajectory
    stretch: float
    path_deviation_max_rad: float


def retime(path: JointPath, velocity: np.ndarray, acceleration: np.ndarray, *, sample_period_s: float = 0.001, keep_timing: bool = False) -> Retimed:
    """Time a joint path within joint limits and sample it.

    Args:
        path: the IK output.
        velocity: velocity limit per active joint (n,) [rad/s], positive; symmetric (+-v).
        acceleration: acceleration limit per active joint (n,) [rad/s^2], positive; symmetric.
        sample_period_s: sample period of the output [s].
        keep_timing: keep the path's own timing instead of the time-optimal one, and check it.

    Returns:
        The trajectory, rest to rest, sampled every ``sample_period_s`` plus its final time, with
        when it passes the samples and how closely.

    Raises:
        StageError: a limit is not a positive finite number, the path has non-finite joints,
            TOPP-RA finds no parameterisation, or (``keep_timing``) the task's timing exceeds a limit.
    """
    if not (np.isfinite(sample_period_s) and sample_period_s > 0):
        raise StageError(f"{STAGE}: the sample period must be a positive number of seconds, got {sample_period_s!r}")
    timing = plan(path, velocity, acceleration, keep_timing=keep_timing)
    traj = timing.sample(sample_period_s)
    if keep_timing:
        check_limits(traj, velocity, acceleration)
    else:
        for _ in range(SAFEGUARD_PASSES):  # the samples themselves within the limits (rarely needed)
            r = limit_ratios(traj, velocity, acceleration)
            k = max(r.velocity_ratio_max, np.sqrt(r.acceleration_ratio_max))
            if k <= 1:
                break
            timing = timing.slowed(k * (1 + 1e-12))
            traj = timing.sample(sample_period_s)
    return Retimed(traj, timing.stretch, path_deviation_max_rad(timing, path))


def plan(path: JointPath, velocity: np.ndarray, acceleration: np.ndarray, *, keep_timing: bool = False) -> Timing:
    """The continuous trajectory :func:`retime` samples (checks the limits and the path first).

    Raises:
        StageError: as :func:`retime`, except the ``keep_timing`` limit check, which needs samples.
    """
    v = joint_limits(velocity, path.joint_names, "velocity", "rad/s")
    a = joint_limits(acceleration, path.joint_names, "acceleration", "rad/s^2")
    check_path(path)
    return task_timing(path) if keep_timing else time_optimal(path, v, a)


def time_optimal(path: JointPath, velocity: np.ndarray, acceleration: np.ndarray) -> Timing:
    """The time-optimal rest-to-rest trajectory along ``path`` by TOPP-RA (see the module docstring).

    Args:
        path: the IK output, finite.
        velocity, acceleration: validated limits per joint (n,) [rad/s], [rad/s^2].

    Raises:
        StageError: TOPP-RA finds no feasible parameterisation.
    """
    s, kept, of_sample = chord_parameter(path.q)
    if len(kept) == 1:
        return _still(path)
    spline = toppra.SplineInterpolator(s, path.q[kept])
    grid, _ = gridpoints(s)
    for _ in range(MAX_REFINEMENTS):
        profile = _topp_ra(spline, grid, velocity, acceleration, path.joint_names)
        excess = profile.stage_ratios(velocity, acceleration) > 1 + REFINE_TOLERANCE
        if not excess.any():
            break
        grid = np.sort(np.concatenate([grid, grid[:-1][excess] + 0.5 * np.diff(grid)[excess]]))
    profile = profile.stretched(max(1.0, float(profile.stage_ratios(velocity, acceleration).max())))
    knots = np.searchsorted(profile.s_grid, s)  # the knots are gridpoints, exactly
    return Timing(
        method="topp-ra",
        joint_names=path.joint_names,
        duration_s=profile.duration_s,
        sample_times_s=profile.stretch * profile.t_grid[knots][of_sample],
        rep=path.rep,
        evaluate=profile,
        stretch=profile.stretch,
        fixed=path.fixed,
    )


def _topp_ra(spline: toppra.SplineInterpolator, grid: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, joint_names: Sequence[str]) -> "ConstAccelProfile":
    """TOPP-RA, rest to rest, on ``grid`` (see the module docstring).

    Raises:
        StageError: TOPP-RA finds no feasible parameterisation (``compute_trajectory`` gives None).
    """
    instance = toppra.algorithm.TOPPRA(
        [toppra.constraint.JointVelocityConstraint(np.vstack([-velocity, velocity]).T), toppra.constraint.JointAccelerationConstraint(np.vstack([-acceleration, acceleration]).T)],
        spline,
        gridpoints=grid,
        parametrizer="ParametrizeConstAccel",
    )
    result = instance.compute_trajectory(0, 0)
    sd = None if result is None else np.asarray(instance.problem_data.sd_vec, dtype=float)
    if sd is None or sd.shape != grid.shape or not np.isfinite(sd).all() or (sd[:-1] + sd[1:] <= 0).any():
        code = instance.problem_data.return_code
        raise StageError(
            f"{STAGE}: TOPP-RA found no feasible time parameterisation ({code}) of the {len(joint_names)}-joint path "
            f"(length {grid[-1]:.4g} rad, {len(spline.ss_waypoints)} distinct samples, {len(grid)} gridpoints; joint limits: velocity "
            f"{_listing(velocity)} rad/s, acceleration {_listing(acceleration)} rad/s^2)"
        )
    return ConstAccelProfile.of(spline, grid, np.maximum(sd, 0.0))


def task_timing(path: JointPath) -> Timing:
    """The path's own timing: a clamped cubic spline of q over ``path.t - path.t[0]`` (rest at both ends).

    The spline passes through every sample at its own time. Its velocity is forced to 0 at both
    ends, so a path that does not start or end at rest gets a short acceleration spike there
    (which the limit check of :func:`retime` reports).

    Raises:
        StageError: the path's times do not strictly increase.
    """
    if len(path) == 1:
        return _still(path, method="keep_timing")
    t = path.t - path.t[0]
    if not np.isfinite(t).all() or (np.diff(t) <= 0).any():
        k = int(np.argmax(~np.isfinite(t[1:]) | (np.diff(t) <= 0)))
        raise StageError(f"{STAGE}: keep_timing needs increasing sample times, but sample {k + 1} (t = {path.t[k + 1]:.6g} s) does not come after sample {k}")
    spline = CubicSpline(t, path.q, bc_type="clamped")
    d1, d2 = spline.derivative(1), spline.derivative(2)

    def evaluate(ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ts = np.clip(np.asarray(ts, dtype=float), 0.0, t[-1])
        return spline(ts), d1(ts), d2(ts)

    return Timing(method="keep_timing", joint_names=path.joint_names, duration_s=float(t[-1]), sample_times_s=t, rep=path.rep, evaluate=evaluate, fixed=path.fixed)


@dataclass(frozen=True)
class ConstAccelProfile:
    """The TOPP-RA result along the path: piecewise-constant path acceleration between gridpoints.

    Attributes:
        path: the geometric path P(s) [rad].
        s_grid: gridpoints (G,) [rad].
        sd_grid: path velocity at the gridpoints (G,) [rad/s], 0 at both ends.
        t_grid: time of each gridpoint before stretching (G,) [s].
        u: path acceleration on each stage (G-1,) [rad/s^2].
        stretch: time scale factor k: the trajectory at time t is the profile at t / k.
    """

    path: toppra.SplineInterpolator
    s_grid: np.ndarray
    sd_grid: np.ndarray
    t_grid: np.ndarray
    u: np.ndarray
    stretch: float = 1.0

    @classmethod
    def of(cls, path: toppra.SplineInterpolator, s_grid: np.ndarray, sd_grid: np.ndarray) -> "ConstAccelProfile":
        """The profile of TOPP-RA's path velocities ``sd_grid`` at ``s_grid`` (as ``ParametrizeConstAccel``)."""
        ds = np.diff(s_grid)
        t_grid = np.concatenate([[0.0], np.cumsum(2 * ds / (sd_grid[:-1] + sd_grid[1:]))])
        u = (sd_grid[1:] ** 2 - sd_grid[:-1] ** 2) / (2 * ds)
        return cls(path=path, s_grid=s_grid, sd_grid=sd_grid, t_grid=t_grid, u=u)

    @property
    def duration_s(self) -> float:
        """Duration after stretching [s]."""
        return float(self.stretch * self.t_grid[-1])

    def stretched(self, k: float) -> "ConstAccelProfile":
        """The same profile slowed down by the factor ``k`` (>= 1)."""
        return ConstAccelProfile(self.path, self.s_grid, self.sd_grid, self.t_grid, self.u, self.stretch * k)

    def path_state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """s [rad], s' [rad/s] and s'' [rad/s^2] at times ``t`` [s] (stretch included)."""
        tau = np.clip(np.asarray(t, dtype=float) / self.stretch, 0.0, self.t_grid[-1])
        i = np.clip(np.searchsorted(self.t_grid, tau, side="right") - 1, 0, len(self.u) - 1)
        dt = tau - self.t_grid[i]
        s = np.clip(self.s_grid[i] + self.sd_grid[i] * dt + 0.5 * self.u[i] * dt**2, self.s_grid[i], self.s_grid[i + 1])
        sd = np.maximum(self.sd_grid[i] + self.u[i] * dt, 0.0)
        return s, sd / self.stretch, self.u[i] / self.stretch**2

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q [rad], qd [rad/s], qdd [rad/s^2] at times ``t`` [s], each (len(t), n)."""
        s, sd, sdd = self.path_state(t)
        dq = self.path(s, 1)
        return self.path(s, 0), dq * sd[:, None], self.path(s, 2) * sd[:, None] ** 2 + dq * sdd[:, None]

    def stage_ratios(self, velocity: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
        """Per stage, the largest of |qd| / v and sqrt(|qdd| / a) over joints (G-1,).

        Each stage is evaluated at ``CHECK_POINTS_PER_STAGE`` + 1 evenly spaced path positions,
        both ends included, with its own path acceleration (so the one-sided accelerations at the
        gridpoints are covered). A ratio r means the stage meets the limits once slowed down by r.
        """
        fraction = np.linspace(0.0, 1.0, CHECK_POINTS_PER_STAGE + 1)
        lo, ds = self.s_grid[:-1, None], np.diff(self.s_grid)[:, None]
        s = (lo + ds * fraction).ravel()
        u = np.repeat(self.u, len(fraction)) / self.stretch**2
        x = np.maximum((self.sd_grid[:-1, None] ** 2 + 2 * self.u[:, None] * ds * fraction).ravel(), 0.0) / self.stretch**2
        dq, ddq = self.path(s, 1), self.path(s, 2)
        rv = (np.abs(dq) * np.sqrt(x)[:, None] / velocity).max(axis=1)
        ra = (np.abs(ddq * x[:, None] + dq * u[:, None]) / acceleration).max(axis=1)
        return np.maximum(rv, np.sqrt(ra)).reshape(-1, len(fraction)).max(axis=1)


def chord_parameter(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cumulative chord-length parameter of the distinct samples of ``q`` (N, n) [rad].

    A sample within :data:`DUPLICATE_CHORD_RAD` of the last kept sample is dropped (so a slow
    creep is not lost: distances are taken to the last kept sample, not to the previous one).

    Returns:
        s (K,) [rad] of the kept samples, increasing from 0; the kept sample indices (K,); and,
        for every sample (N,), the position in the kept list of the sample it equals or follows.
    """
    q = np.asarray(q, dtype=float)
    chord = np.linalg.norm(np.diff(q, axis=0), axis=1)
    if (chord > DUPLICATE_CHORD_RAD).all():
        kept = np.arange(len(q))
    else:
        keep = [0]
        for k in range(1, len(q)):
            if np.linalg.norm(q[k] - q[keep[-1]]) > DUPLICATE_CHORD_RAD:
                keep.append(k)
        kept = np.array(keep)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q[kept], axis=0), axis=1))])
    of_sample = np.searchsorted(kept, np.arange(len(q)), side="right") - 1
    return s, kept, of_sample


def gridpoints(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """TOPP-RA gridpoints containing the knots ``s`` (K,) [rad] (see the module docstring).

    Returns:
        The gridpoints (G,) [rad], increasing, and the index of each knot among them (K,).
    """
    ds = np.diff(s)
    parts = np.maximum(GRID_SUBDIVISIONS, np.ceil(ds / MAX_GRID_STEP_RAD).astype(int))
    parts = np.maximum(parts, int(np.ceil((MIN_GRIDPOINTS - 1) / len(ds))))
    knots = np.concatenate([[0], np.cumsum(parts)])
    interval = np.repeat(np.arange(len(ds)), parts)
    step = np.arange(knots[-1]) - knots[interval]
    grid = np.concatenate([s[interval] + ds[interval] * step / parts[interval], [s[-1]]])
    return grid, knots


def sample_grid(duration_s: float, period_s: float) -> np.ndarray:
    """Sample times every ``period_s`` from 0 to ``duration_s`` included [s].

    The last step is in [period/2, 3 period/2), unless the whole duration is shorter than that;
    a duration of 0 gives the single time 0.
    """
    if duration_s <= 0:
        return np.zeros(1)
    t = np.arange(1, int(np.floor(duration_s / period_s)) + 1) * period_s
    return np.concatenate([[0.0], t[t < duration_s - 0.5 * period_s], [duration_s]])


def limit_ratios(traj: JointTrajectory, velocity: np.ndarray, acceleration: np.ndarray) -> LimitRatios:
    """The largest velocity and acceleration limit ratios over the samples of ``traj`` (qd, qdd).

    Args:
        traj: a sampled trajectory.
        velocity, acceleration: limits per joint (n,) [rad/s], [rad/s^2], positive.
    """
    v = joint_limits(velocity, traj.joint_names, "velocity", "rad/s")
    a = joint_limits(acceleration, traj.joint_names, "acceleration", "rad/s^2")
    rv, ra = np.abs(traj.qd) / v, np.abs(traj.qdd) / a
    kv, jv = np.unravel_index(np.argmax(rv), rv.shape)
    ka, ja = np.unravel_index(np.argmax(ra), ra.shape)
    return LimitRatios(
        velocity_ratio_max=float(rv[kv, jv]),
        acceleration_ratio_max=float(ra[ka, ja]),
        velocity_joint=traj.joint_names[jv],
        acceleration_joint=traj.joint_names[ja],
        velocity_time_s=float(traj.t[kv]),
        acceleration_time_s=float(traj.t[ka]),
    )


def check_limits(traj: JointTrajectory, velocity: np.ndarray, acceleration: np.ndarray) -> None:
    """Raise a StageError naming the joint, time and ratio if ``traj`` exceeds a limit by more than :data:`LIMIT_TOLERANCE`."""
    r = limit_ratios(traj, velocity, acceleration)
    worst = max(
        (r.velocity_ratio_max, "velocity", r.velocity_joint, r.velocity_time_s),
        (r.acceleration_ratio_max, "acceleration", r.acceleration_joint, r.acceleration_time_s),
    )
    ratio, kind, joint, time = worst
    if ratio > 1 + LIMIT_TOLERANCE:
        raise StageError(f"{STAGE}: keep_timing: {joint} reaches {ratio:.3g}x its {kind} limit at t = {time:.3f} s (the task's timing is too fast for the joint limits)")


def path_deviation_max_rad(timing: Timing, path: JointPath) -> float:
    """The largest joint difference between the trajectory at the joint-path samples and the samples [rad].

    The trajectory is evaluated at :attr:`Timing.sample_times_s` (the times it passes the
    samples' path parameters) and compared with ``path.q``. The spline passes through the
    samples, so this is ~1e-12 rad (up to :data:`DUPLICATE_CHORD_RAD` for dropped duplicates).
    """
    q, _, _ = timing.evaluate(timing.sample_times_s)
    return float(np.abs(q - path.q).max())


def joint_limits(values, joint_names: Sequence[str], kind: str, unit: str) -> np.ndarray:
    """``values`` as one positive finite limit per joint (n,); a scalar applies to every joint.

    Raises:
        StageError: a wrong number of limits, or one that is not a positive finite number.
    """
    try:
        limits = np.broadcast_to(np.asarray(values, dtype=float), (len(joint_names),)).copy()
    except (TypeError, ValueError):
        raise StageError(f"{STAGE}: expected {len(joint_names)} {kind} limits (one per joint: {', '.join(joint_names)}), got {np.shape(values)}") from None
    bad = np.flatnonzero(~(np.isfinite(limits) & (limits > 0)))
    if len(bad):
        j = int(bad[0])
        raise StageError(f"{STAGE}: the {kind} limit of joint {j} ({joint_names[j]}) is {float(limits[j])!r} {unit}; every limit must be a positive finite number")
    return limits


def check_path(path: JointPath) -> None:
    """Raise a StageError naming the first non-finite joint value of ``path``, or an empty path."""
    if len(path) == 0:
        raise StageError(f"{STAGE}: the joint path has no samples")
    bad = np.argwhere(~np.isfinite(path.q))
    if len(bad):
        k, j = (int(x) for x in bad[0])
        raise StageError(f"{STAGE}: the joint path's {path.joint_names[j]} is {float(path.q[k, j])!r} at sample {k} (t = {path.t[k]:.3f} s)")


def _still(path: JointPath, method: str = "topp-ra") -> Timing:
    """A trajectory that holds the path's first configuration (a path that does not move)."""
    q0 = np.asarray(path.q[0], dtype=float)

    def evaluate(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m = len(np.atleast_1d(t))
        return np.tile(q0, (m, 1)), np.zeros((m, len(q0))), np.zeros((m, len(q0)))

    return Timing(method=method, joint_names=path.joint_names, duration_s=0.0, sample_times_s=np.zeros(len(path)), rep=path.rep, evaluate=evaluate, fixed=path.fixed)


def _listing(x: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in x) + "]"

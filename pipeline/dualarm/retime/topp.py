"""Time-optimal timing of a joint path within joint velocity and acceleration limits (TOPP-RA).

The geometric path. All active joints (both arms) form ONE path, so the arms stay synchronised.
Its parameter s is the cumulative joint-space chord length [rad], the Euclidean norm of the
differences of consecutive samples (:func:`chord_parameter`). Consecutive samples closer than
:data:`DUPLICATE_CHORD_RAD` (holds: the IK repeats a configuration) are dropped first; they would
give zero-length spline intervals. ``toppra.SplineInterpolator(s, q)`` (a not-a-knot cubic spline
per joint) passes through the kept samples exactly at their s. A path whose samples are all equal
(length ~0) gives a trajectory of a single sample at rest (duration 0).

The time parameterisation. ``toppra.algorithm.TOPPRA`` with ``JointVelocityConstraint`` and
``JointAccelerationConstraint`` (symmetric limits), rest to rest (``compute_trajectory(0, 0)``),
and these settings:

- ``parametrizer="ParametrizeConstAccel"``: the path acceleration s'' is constant between
  gridpoints, which is exactly what TOPP-RA optimised. The default ``ParametrizeSpline`` refits a
  cubic spline through the gridpoint times and overshoots the acceleration limits.
- gridpoints (:func:`gridpoints`): the IK samples' s values, every interval split into at least
  :data:`GRID_SUBDIVISIONS` equal stages and into stages no longer than
  :data:`MAX_GRID_STEP_RAD`, with at least :data:`MIN_GRIDPOINTS` points. Containing the IK
  samples gives the time at which the trajectory passes each of them exactly
  (:attr:`~dualarm.retime.timing.Timing.sample_times_s`).
- TOPP-RA enforces the limits at the gridpoints only (the velocity at each gridpoint, the
  acceleration at both ends of each stage: toppra's interpolation discretisation). Between
  gridpoints q'(s) and q''(s) vary along the spline, so the limits can be exceeded there: by about
  1e-4 (relative) on a smooth path, by much more where the path turns sharply (a reversal of all
  joints, where the chord-length spline has a large q''). So :func:`time_optimal` evaluates the
  limit ratios at :data:`CHECK_POINTS_PER_STAGE` + 1 points of every stage
  (:meth:`ConstAccelProfile.stage_ratios`), splits the stages exceeding 1 + :data:`REFINE_TOLERANCE`
  in two and runs TOPP-RA again (at most :data:`MAX_REFINEMENTS` runs), then slows the whole
  trajectory down uniformly by the remaining ratio k = max(velocity ratio, sqrt(acceleration
  ratio)) >= 1 (t -> k t scales qd by 1/k and qdd by 1/k^2), recorded as
  :attr:`~dualarm.retime.timing.Timing.stretch`. Last, :func:`dualarm.retime.stage.retime_path`
  checks the output samples and slows down again should one still exceed a limit.

s(t) is evaluated in closed form from TOPP-RA's gridpoints and path velocities, the same formula
as ``ParametrizeConstAccel`` (vectorised, :class:`ConstAccelProfile`): on stage i,
s = s_i + s'_i dt + u_i dt^2 / 2 with u_i = (s'_{i+1}^2 - s'_i^2) / (2 (s_{i+1} - s_i)), and
q = P(s), qd = P'(s) s', qdd = P''(s) s'^2 + P'(s) u_i. Knowing s(t) gives the repetition index of
each sample (that of the last IK sample passed) and the time of each IK sample.

Units: joint positions [rad], velocities [rad/s], accelerations [rad/s^2], times [s]. The path
parameter s is in [rad] (a joint-space length), its derivatives in [rad/s] and [rad/s^2].
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint

from dualarm.contracts.joint_path import JointPath
from dualarm.errors import StageError
from dualarm.retime.timing import STAGE, Timing, still

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


def time_optimal(path: JointPath, velocity: np.ndarray, acceleration: np.ndarray) -> Timing:
    """The time-optimal rest-to-rest trajectory along ``path`` by TOPP-RA (see the module docstring).

    Args:
        path: the IK output, finite.
        velocity: validated velocity limit per joint (n,) [rad/s], symmetric (+-v).
        acceleration: validated acceleration limit per joint (n,) [rad/s^2], symmetric.

    Returns:
        A ``topp-ra`` timing; a path that does not move gives one at rest of duration 0.

    Raises:
        StageError: TOPP-RA finds no feasible parameterisation.
    """
    s, kept, of_sample = chord_parameter(path.q)
    if len(kept) == 1:
        return still(path)
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


def _topp_ra(
    spline: toppra.SplineInterpolator,
    grid: np.ndarray,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    joint_names: Sequence[str],
) -> ConstAccelProfile:
    """TOPP-RA, rest to rest, on ``grid`` (see the module docstring).

    Args:
        spline: the geometric path P(s) [rad].
        grid: the gridpoints (G,) [rad].
        velocity: velocity limit per joint (n,) [rad/s].
        acceleration: acceleration limit per joint (n,) [rad/s^2].
        joint_names: the joints, for the message.

    Raises:
        StageError: TOPP-RA finds no feasible parameterisation (``compute_trajectory`` gives None).
    """
    instance = toppra.algorithm.TOPPRA(
        [
            toppra.constraint.JointVelocityConstraint(np.vstack([-velocity, velocity]).T),
            toppra.constraint.JointAccelerationConstraint(np.vstack([-acceleration, acceleration]).T),
        ],
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
            f"(length {grid[-1]:.4g} rad, {len(spline.ss_waypoints)} distinct samples, {len(grid)} gridpoints; "
            "joint limits: velocity "
            f"{_listing(velocity)} rad/s, acceleration {_listing(acceleration)} rad/s^2)",
            stage=STAGE,
        )
    return ConstAccelProfile.of(spline, grid, np.maximum(sd, 0.0))


@dataclass(frozen=True)
class ConstAccelProfile:
    """The TOPP-RA result along the path: piecewise-constant path acceleration between gridpoints.

    Called with times, it is the :attr:`~dualarm.retime.timing.Timing.evaluate` of a ``topp-ra`` timing.

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
    def of(cls, path: toppra.SplineInterpolator, s_grid: np.ndarray, sd_grid: np.ndarray) -> ConstAccelProfile:
        """The profile of TOPP-RA's path velocities ``sd_grid`` [rad/s] at ``s_grid`` [rad].

        As ``ParametrizeConstAccel``.
        """
        ds = np.diff(s_grid)
        t_grid = np.concatenate([[0.0], np.cumsum(2 * ds / (sd_grid[:-1] + sd_grid[1:]))])
        u = (sd_grid[1:] ** 2 - sd_grid[:-1] ** 2) / (2 * ds)
        return cls(path=path, s_grid=s_grid, sd_grid=sd_grid, t_grid=t_grid, u=u)

    @property
    def duration_s(self) -> float:
        """Duration after stretching [s]."""
        return float(self.stretch * self.t_grid[-1])

    def stretched(self, k: float) -> ConstAccelProfile:
        """The same profile slowed down by the factor ``k`` (>= 1)."""
        return ConstAccelProfile(self.path, self.s_grid, self.sd_grid, self.t_grid, self.u, self.stretch * k)

    def path_state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """S [rad], s' [rad/s] and s'' [rad/s^2] at times ``t`` [s] (stretch included)."""
        tau = np.clip(np.asarray(t, dtype=float) / self.stretch, 0.0, self.t_grid[-1])
        i = np.clip(np.searchsorted(self.t_grid, tau, side="right") - 1, 0, len(self.u) - 1)
        dt = tau - self.t_grid[i]
        s = np.clip(self.s_grid[i] + self.sd_grid[i] * dt + 0.5 * self.u[i] * dt**2, self.s_grid[i], self.s_grid[i + 1])
        sd = np.maximum(self.sd_grid[i] + self.u[i] * dt, 0.0)
        return s, sd / self.stretch, self.u[i] / self.stretch**2

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Q [rad], qd [rad/s], qdd [rad/s^2] at times ``t`` [s], each (len(t), n)."""
        s, sd, sdd = self.path_state(t)
        dq = self.path(s, 1)
        return self.path(s, 0), dq * sd[:, None], self.path(s, 2) * sd[:, None] ** 2 + dq * sdd[:, None]

    def stage_ratios(self, velocity: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
        """Per stage, the largest of |qd| / v and sqrt(|qdd| / a) over joints (G-1,).

        Each stage is evaluated at :data:`CHECK_POINTS_PER_STAGE` + 1 evenly spaced path positions,
        both ends included, with its own path acceleration (so the one-sided accelerations at the
        gridpoints are covered). A ratio r means the stage meets the limits once slowed down by r.

        Args:
            velocity: velocity limit per joint (n,) [rad/s].
            acceleration: acceleration limit per joint (n,) [rad/s^2].
        """
        fraction = np.linspace(0.0, 1.0, CHECK_POINTS_PER_STAGE + 1)
        lo, ds = self.s_grid[:-1, None], np.diff(self.s_grid)[:, None]
        s = (lo + ds * fraction).ravel()
        u = np.repeat(self.u, len(fraction)) / self.stretch**2
        x = (
            np.maximum((self.sd_grid[:-1, None] ** 2 + 2 * self.u[:, None] * ds * fraction).ravel(), 0.0)
            / self.stretch**2
        )
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


def _listing(x: np.ndarray) -> str:
    """``x`` as ``[a, b, ...]`` with 4 significant digits, for messages."""
    return "[" + ", ".join(f"{v:.4g}" for v in x) + "]"

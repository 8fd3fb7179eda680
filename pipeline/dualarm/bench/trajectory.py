"""``dualarm bench trajectory``: the jerk-limited timing against TOPP-RA with Ruckig tracking.

On the same joint paths.

Each task's joint path is made once (its IK method, or its planner), then timed three ways, each
timed on its own call (the motion the robot would execute):

- ``jerk-limited``: :func:`dualarm.retime.jerk.jerk_limited` within the full velocity, acceleration and
  jerk limits; the motion is q(t) = P(s(t)) on the path.
- ``TOPP-RA 0.9/0.3 + tracking`` (today's pipeline): TOPP-RA at 90 % of the velocity and 30 % of the
  acceleration limits, then tracked by Ruckig per joint within the full limits (the smooth stage).
- ``TOPP-RA 1.0/1.0 + tracking``: the same at the full limits.

Per row: the motion's duration, its ratio to TOPP-RA's at the full velocity and acceleration
limits with jerk unlimited, and its ratio to :func:`rest_to_rest_bound_s` (what a jerk-limited motion
resting where the jerk-limited timing rests needs at least); the velocity,
acceleration and jerk limit ratios of the motion by finite differences of its positions sampled
every :data:`STEP_S` (the jerk-limited timing evaluated there, its jerk from its accelerations: :func:`_ratios`; the
tracked motion at its 1 ms control period); its deviation from the path, per joint and at the hands (forward kinematics;
the tracked motion: from the retimed reference at the same time, as the smooth stage reports it;
the jerk-limited motion: from the IK samples at the times it passes them); and the compute time
per second of motion.

Each tracked row runs in a process of its own (:func:`isolated`): a crash of Ruckig's C++ there is that row's
failure, named, and the other rows still run.

Never used by the test suite: wall-clock numbers depend on the machine.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.errors import StageError
from dualarm.isolation import CrashedError, isolated
from dualarm.retime.stage import plan, retime_path
from dualarm.retime.timing import path_deviation_max_rad
from dualarm.run import run_task
from dualarm.tasks import Task, load_task

#: (task file, IK method or planner) of the benchmark.
DEFAULT_RUNS = (
    ("tasks/triangle.toml", "mc-inverse"),
    ("tasks/circle.toml", "mc-inverse"),
    ("tasks/ball_game.toml", "tvgdd"),
    ("tasks/bowl_grasp.toml", "mcikrrt"),
)
#: The methods, in the table's order.
METHODS = ("jerk-limited", "TOPP-RA 0.9/0.3 + tracking", "TOPP-RA 1.0/1.0 + tracking")
#: Finite-difference step of the jerk-limited motion's limit ratios [s].
STEP_S = 2.5e-4
#: Control period of the tracked motions [s].
PERIOD_S = 1e-3


@dataclass(frozen=True)
class TrajectoryRow:
    """One method on one task.

    Attributes:
        task, method: what was timed.
        duration_s: the motion's duration [s].
        optimal_s: TOPP-RA's duration at the full velocity and acceleration limits, jerk unlimited [s].
        ratios: the velocity, acceleration and jerk limit ratios by finite differences.
        deviation_rad: the joint deviation from the path [rad] (module docstring).
        hand_deviation_m: the hands' deviation from the path [m] (module docstring).
        compute_s: wall-clock time of the timing (and tracking) [s].
        failure: why the method gave no motion (its one-line error), else None; the other fields are then NaN.
        bound_s: :func:`rest_to_rest_bound_s` of the task's path [s].
    """

    task: str
    method: str
    duration_s: float
    optimal_s: float
    ratios: tuple[float, float, float]
    deviation_rad: float
    hand_deviation_m: float
    compute_s: float
    failure: str | None = None
    bound_s: float = float("nan")

    @classmethod
    def failed(cls, task: str, method: str, optimal_s: float, failure: str) -> TrajectoryRow:
        """The row of a method that gave no motion: ``failure``, NaN for what it would have measured."""
        return cls(task, method, np.nan, optimal_s, (np.nan,) * 3, np.nan, np.nan, np.nan, failure)


def _ratios(
    q: np.ndarray, step_s: float, limits: Sequence[np.ndarray], qdd: np.ndarray | None = None
) -> tuple[float, float, float]:
    """Velocity, acceleration and jerk ratios of positions ``q`` (M, n) sampled every ``step_s`` [s].

    By first, second and third differences; the jerk by first differences of the accelerations ``qdd`` (M, n) where
    given: at 0.25 ms, the rounding of positions near 2.8 rad makes up to 5e-6 of a 100 rad/s^3 limit in a third
    difference (the property test read 1.0000017 on a motion riding that limit), 64 times less at the 1 ms of the
    tracked motions.
    """
    velocity, acceleration = (
        float((np.abs(np.diff(q, order, axis=0)) / step_s**order / limit).max())
        for order, limit in zip((1, 2), limits[:2], strict=True)
    )
    third = np.diff(q, 3, axis=0) / step_s**3 if qdd is None else np.diff(qdd, axis=0) / step_s
    return velocity, acceleration, float((np.abs(third) / limits[2]).max())


def _hand_distance(
    task: Task, names: tuple[str, ...], q: np.ndarray, reference: np.ndarray, fixed: Mapping[str, float]
) -> float:
    """The largest distance [m] between where the configurations ``q`` and ``reference`` put each hand.

    ``q`` and ``reference`` are (M, n) [rad]; each driven hand, by forward kinematics.
    """
    at, to = (task.hand_poses(names, x, fixed) for x in (q, reference))
    return max(
        (float(np.linalg.norm(at[hand][:, :3, 3] - to[hand][:, :3, 3], axis=1).max()) for hand in at), default=0.0
    )


def bench_trajectory(
    runs: Sequence[tuple[str, str]] = DEFAULT_RUNS, progress: Callable[[str], None] = lambda text: None
) -> list[TrajectoryRow]:
    """Make each task's joint path, then time it by each of :data:`METHODS` (module docstring)."""
    from dualarm.methods import METHODS as REGISTRY

    rows: list[TrajectoryRow] = []
    for task_file, method in runs:
        first = len(rows)
        task = load_task(task_file)
        progress(f"{task.name}: joint path ({method})")
        kind = "plan" if REGISTRY[method].kind == "planner" else "ik"
        path: JointPath = run_task(task, method, stages=("path", kind)).joint_path  # type: ignore[assignment]
        names = path.joint_names
        v, a, j = (task.robot.limit_array(k, names) for k in ("velocity", "acceleration", "jerk"))
        optimal = plan(path, v, a).duration_s
        progress(f"{task.name}: jerk-limited")
        start = time.perf_counter()
        try:
            timing = plan(path, v, a, jerk=j)
        except StageError as error:
            rows.append(TrajectoryRow.failed(task.name, METHODS[0], optimal, str(error)))
        else:
            timing.sample(PERIOD_S)
            compute = time.perf_counter() - start
            q, _, qdd = timing.evaluate(np.arange(0.0, timing.duration_s, STEP_S))
            hands = _hand_distance(task, names, timing.evaluate(timing.sample_times_s)[0], path.q, path.fixed)
            rows.append(
                TrajectoryRow(
                    task.name,
                    METHODS[0],
                    timing.duration_s,
                    optimal,
                    _ratios(q, STEP_S, (v, a, j), qdd),
                    path_deviation_max_rad(timing, path),
                    hands,
                    compute,
                )
            )
        for name, share in zip(METHODS[1:], ((0.9, 0.3), (1.0, 1.0)), strict=True):
            progress(f"{task.name}: {name}")
            fields = (names, path.t, path.q, path.rep, dict(path.fixed))
            try:
                rows.append(isolated(tracked_row, task_file, fields, name, share, optimal))
            except (StageError, CrashedError) as error:
                rows.append(TrajectoryRow.failed(task.name, name, optimal, str(error)))
        bound = rest_to_rest_bound_s(path, v, a, j)
        rows[first:] = [replace(row, bound_s=bound) for row in rows[first:]]
    return rows


def tracked_row(
    task_file: str,
    fields: tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray, dict[str, float]],
    name: str,
    share: tuple[float, float],
    optimal: float,
) -> TrajectoryRow:
    """TOPP-RA at ``share`` of the velocity and acceleration limits, tracked by Ruckig at the full limits.

    The row ``name`` of the joint path ``fields`` (joint names, t, q, rep, locked joints) of ``task_file``.
    """
    from dualarm.smooth import smooth_trajectory

    task = load_task(task_file)
    names, t, q, rep, fixed = fields
    path = JointPath.of_positions("bench", names, t, q, rep, fixed)
    v, a, j = (task.robot.limit_array(k, names) for k in ("velocity", "acceleration", "jerk"))
    start = time.perf_counter()
    retimed = retime_path(path, share[0] * v, share[1] * a, sample_period_s=PERIOD_S).trajectory
    smoothed = smooth_trajectory(retimed, v, a, j, period_s=PERIOD_S)
    compute = time.perf_counter() - start
    motion = smoothed.trajectory.q[:-1]  # every period, without the final sample (the last step may be shorter)
    hands = _hand_distance(task, names, smoothed.trajectory.q, retimed.interpolate(smoothed.trajectory.t)[0], fixed)
    return TrajectoryRow(
        task.name,
        name,
        smoothed.trajectory.duration_s,
        optimal,
        _ratios(motion, PERIOD_S, (v, a, j)),
        smoothed.path_deviation_max_rad,
        hands,
        compute,
    )


def rest_to_rest_bound_s(path: JointPath, velocity: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray) -> float:
    """A lower bound [s] on a jerk-limited timing that rests where the jerk-limited timing rests.

    Summed over its pieces (:func:`dualarm.retime.jerk.pieces`, rest to rest): the larger of TOPP-RA's duration
    along the piece (jerk unlimited) and the longest of the joints' own time-optimal rest-to-rest moves over the
    piece's displacement (Ruckig, one joint, no path to follow), both of which any timing of the piece needs.
    """
    from dualarm.retime.jerk import pieces, rest_to_rest
    from dualarm.retime.topp import chord_parameter

    s, kept, _ = chord_parameter(path.q)
    q = path.q[kept]
    total = 0.0
    for first, last, _ in pieces(q, s):
        samples = q[first : last + 1]
        piece = JointPath.of_positions("bench", path.joint_names, np.arange(len(samples)), samples)
        along = plan(piece, velocity, acceleration)
        moves = [
            rest_to_rest(samples[0, i], samples[-1, i], velocity[i], acceleration[i], jerk[i]).duration
            for i in np.flatnonzero(samples[-1] != samples[0])
        ]
        total += max([along.duration_s, *moves])
    return total

"""The approach: the move from the task's initial configuration to the start of the trajectory.

Jerk-limited, at rest at both ends.

A task starts at its ``initial`` configuration, while the joint path (IK or plan) starts where
its first sample puts the arms; the approach joins them the way the retime stage times a path
(:func:`dualarm.retime.jerk.jerk_limited`): along the straight line in joint space, time-optimal
within each joint's velocity, acceleration and jerk limits (a straight piece: Ruckig on the path
parameter), every joint starting and stopping together, sampled every control period. It is
played before the trajectory, on its own clock (``t`` from 0), and checked like it
(:mod:`dualarm.execute.preflight`).

Where the straight line collides (on a robot the task was not written for, the arms may sweep
through the torso or each other on the way), :func:`approach_waypoints` finds a collision-free
path with the planners' tree search (RRT-Connect: :func:`~dualarm.plan.mcikrrt.mcikrrt` with the
one goal, a fixed seed, and its shortcutting), checked by the execute stage's own checker (no
margin, the task's objects and expected contacts); the approach then goes through its waypoints,
each segment straight and rest to rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.retime.jerk import jerk_limited

if TYPE_CHECKING:
    from dualarm.tasks import Task

#: The approach's stage name.
STAGE = "approach"
#: The tree search of a colliding approach: its seed, its time limit [s], and the checked segments' resolution
#: [rad] (half the execute stage's ``RESOLUTION_RAD``, so it checks more finely than the execute stage does).
PLAN_SEED, PLAN_TIMEOUT_S, PLAN_RESOLUTION_RAD = 0, 10.0, 0.01


def approach_waypoints(
    task: Task, names: tuple[str, ...], start: np.ndarray, goal: np.ndarray, fixed: dict[str, float]
) -> np.ndarray:
    """``start``, the waypoints of a collision-free joint path, and ``goal`` [rad]; (K, n).

    (2, n) when the straight line is free, or when it cannot be helped (``start`` or ``goal`` in
    collision themselves, which the execute stage reports, or no path found within
    :data:`PLAN_TIMEOUT_S`: the straight line is kept and reported the same way). ``names``
    move, the other joints are at ``fixed``.
    """
    from dualarm.plan.collision import CollisionChecker
    from dualarm.plan.mcikrrt import TreeSearchSettings, mcikrrt

    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    line = np.stack([start, goal])
    if not len(names) or np.array_equal(start, goal):
        return line
    spec = task.spec
    with CollisionChecker(
        task.robot,
        names,
        fixed,
        spec.environment,
        spec.expected_contacts,
        margin_m=0.0,
        resolution_rad=PLAN_RESOLUTION_RAD,
    ) as checker:
        if not (checker.free(start) and checker.free(goal)) or checker.segment_free(start, goal):
            return line
        lower, upper = task.robot.lower_upper(names)
        reach = np.minimum(start, goal) - np.pi, np.maximum(start, goal) + np.pi  # continuous joints: a turn about
        planned = mcikrrt(
            start,
            np.maximum(lower, reach[0]),
            np.minimum(upper, reach[1]),
            checker,
            lambda: goal,
            np.random.default_rng(PLAN_SEED),
            TreeSearchSettings(timeout_s=PLAN_TIMEOUT_S),
        )
    return np.asarray(planned.path) if planned.success else line


def approach_trajectory(
    names: tuple[str, ...],
    start: np.ndarray,
    goal: np.ndarray,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    period_s: float,
    fixed: dict[str, float] | None = None,
    via: Sequence[np.ndarray] = (),
) -> JointTrajectory:
    """The time-optimal jerk-limited straight move from ``start`` to ``goal`` [rad], at rest at both ends.

    Through the configurations ``via`` on the way when given, each segment straight and rest to rest.
    Sampled every ``period_s`` [s] within each segment (its last sample at the segment's end).

    Args:
        names: the joints.
        start: the initial configuration (n,) [rad].
        goal: the trajectory's first configuration (n,) [rad].
        velocity: velocity limits (n,) [rad/s].
        acceleration: acceleration limits (n,) [rad/s^2].
        jerk: jerk limits (n,) [rad/s^3].
        period_s: sample period [s].
        fixed: the locked joints' values [rad].
        via: configurations (n,) [rad] to pass through at rest, in order (:func:`approach_waypoints`'s inner rows).
    """

    def straight(a: np.ndarray, b: np.ndarray) -> JointTrajectory:  # one segment, rest to rest
        line = JointPath.of_positions(STAGE, names, np.arange(2.0), np.stack([a, b]), fixed=fixed)
        return replace(jerk_limited(line, velocity, acceleration, jerk).sample(period_s), stage=STAGE)

    points = [np.asarray(p, dtype=float) for p in (start, *via, goal)]
    segments = [straight(a, b) for a, b in zip(points[:-1], points[1:], strict=True)]
    first = segments[0]
    if len(segments) == 1:
        return first
    ends = np.cumsum([0.0] + [s.t[-1] for s in segments[:-1]])  # each segment starts at rest where the last stopped

    def joined(field: str) -> np.ndarray:  # a later segment's first sample is the earlier one's last
        return np.concatenate([getattr(first, field)] + [getattr(s, field)[1:] for s in segments[1:]])

    return replace(
        first,
        t=np.concatenate([first.t] + [s.t[1:] + end for s, end in zip(segments[1:], ends[1:], strict=True)]),
        q=joined("q"),
        qd=joined("qd"),
        qdd=joined("qdd"),
        rep=joined("rep"),
    )

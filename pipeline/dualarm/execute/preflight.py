"""Validation of a trajectory before it is executed.

As MoveIt validates a trajectory before handing it to the controllers.

The trajectory is checked against every joint's position, velocity, acceleration and jerk limits
(:func:`~dualarm.violations.trajectory_violations`) and for collisions with the planners' checker
(:class:`~dualarm.plan.collision.CollisionChecker`, no safety margin, the task's expected contacts
allowed) at configurations no more than ``resolution_rad`` apart in every joint. The execute stage
refuses a trajectory that fails, unless it is told to play it anyway.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import Violation
from dualarm.tasks import Task
from dualarm.violations import trajectory_violations

if TYPE_CHECKING:
    from dualarm.plan.collision import CollisionChecker

#: Largest joint step between the configurations checked for collision [rad] (the planners' default).
RESOLUTION_RAD = 0.02


def checked_samples(q: np.ndarray, resolution_rad: float) -> np.ndarray:
    """Indices of the samples of ``q`` (M, n) to check.

    The first, the last, and the next sample wherever some joint has moved ``resolution_rad`` [rad] since the last
    one kept.

    A trajectory sampled densely (each step below ``resolution_rad``) is so checked at configurations
    no more than ``2 resolution_rad`` apart, each a configuration it passes through.
    """
    if not len(q):
        return np.zeros(0, dtype=int)
    kept, last = [0], q[0]
    for k in range(1, len(q)):
        if np.abs(q[k] - last).max() >= resolution_rad:
            kept.append(k)
            last = q[k]
    if kept[-1] != len(q) - 1:
        kept.append(len(q) - 1)
    return np.array(kept)


def collision_violations(
    checker: CollisionChecker, q: np.ndarray, t: np.ndarray, stage: str, resolution_rad: float = RESOLUTION_RAD
) -> list[Violation]:
    """Each pair of bodies ``checker`` finds in collision along ``q`` (M, n) [rad] at times ``t`` (M,) [s].

    With the first time and the deepest overlap found; ``stage`` names where ``q`` comes from.
    """
    first: dict[tuple[str, str], tuple[float, float, int]] = {}
    for k in checked_samples(q, resolution_rad):
        for c in checker.contacts(q[k]):
            at, depth, count = first.get((c.a, c.b), (float(t[k]), 0.0, 0))
            first[(c.a, c.b)] = (at, max(depth, c.depth_m), count + 1)
    return [
        Violation(
            "contact",
            stage,
            f"{stage}: {a} collides with {b} at t = {at:.3f} s, {depth * 1e3:.3g} mm deep at most, "
            f"at {count} checked configurations",
            at,
        )
        for (a, b), (at, depth, count) in sorted(first.items(), key=lambda item: item[1][0])
    ]


def _checker(
    task: Task, joint_names: tuple[str, ...], fixed: Mapping[str, float], resolution_rad: float
) -> CollisionChecker:
    """The planners' checker without a safety margin, the task's expected contacts allowed."""
    from dualarm.plan.collision import CollisionChecker

    spec = task.spec
    return CollisionChecker(
        task.robot,
        joint_names,
        fixed,
        spec.environment,
        spec.expected_contacts,
        margin_m=0.0,
        resolution_rad=resolution_rad,
    )


#: Most checkers of IK paths a process keeps open, the least recently used closed first: building one (a PyBullet
#: world and a compiled Function, ~50 ms on the humanoid) took longer than a study trial's IK.
KEPT_CHECKERS = 4
_kept: OrderedDict[tuple, CollisionChecker] = OrderedDict()


def path_collision_violations(path: JointPath, task: Task, resolution_rad: float = RESOLUTION_RAD) -> list[Violation]:
    """Each pair of bodies in collision at an IK path's solved samples (checked as :func:`preflight` does).

    The checker is kept for the next path of the same robot, joints and scene (:data:`KEPT_CHECKERS`).
    """
    spec = task.spec
    key = (
        task.robot,
        path.joint_names,
        tuple(sorted(path.fixed.items())),
        spec.environment,
        tuple(map(tuple, spec.expected_contacts)),
        resolution_rad,
    )
    checker = _kept.pop(key, None) or _checker(task, path.joint_names, path.fixed, resolution_rad)
    _kept[key] = checker
    while len(_kept) > KEPT_CHECKERS:
        _kept.popitem(last=False)[1].close()
    ok = path.status == 0
    return collision_violations(checker, path.q[ok], path.t[ok], "ik", resolution_rad)


def preflight(traj: JointTrajectory, task: Task, resolution_rad: float = RESOLUTION_RAD) -> list[Violation]:
    """Every limit (jerk included) and collision (no margin) ``traj`` breaks.

    Its ``approach``'s first when it has one; earliest first within each kind.

    One checker serves both: the approach and the trajectory move the same joints.
    """
    found = []
    with _checker(task, traj.joint_names, traj.fixed, resolution_rad) as checker:
        for played in (traj.approach, traj):
            if played is not None:
                found += trajectory_violations(played, task.robot, jerk=True) + collision_violations(
                    checker, played.q, played.t, played.stage, resolution_rad
                )
    return found

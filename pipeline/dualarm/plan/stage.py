"""The plan stage's product and metrics.

A task with Workspace Target Areas -> a collision-free joint path (the stage itself is
:class:`dualarm.stages.PlanStage`).

The plan's waypoints are joined by straight joint-space segments, each collision-checked at the
checker's resolution; the stage's :class:`~dualarm.contracts.joint_path.JointPath` holds those checked
configurations in order (waypoints included), so the retime stage's spline through them stays
within the resolution of the checked segments. Its sample times are nominal (one
``control_period_s`` apart; the retime stage gives the real timing), its ``hand_error_m`` is each
hand's distance to its nearest WTA in position, eq (26)'s translation rows [m], and it has no
per-sample solve time (the planning time is ``plan.planning_time_s``).
"""

from __future__ import annotations

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.plan.mcikrrt import PlanResult
from dualarm.plan.problem import PlanningProblem
from dualarm.plan.wta import displacement


def plan_metrics(result: PlanResult) -> dict[str, float]:
    """``plan.*`` metrics of one query."""
    return {
        "plan.success": float(result.success),
        "plan.planning_time_s": result.planning_time_s,
        "plan.nodes": float(result.nodes),
        "plan.goals": float(result.goals),
        "plan.collision_checks": float(result.collision_checks),
        "plan.path_length_rad": result.path_length_rad,
        "plan.raw_path_length_rad": result.raw_path_length_rad,
        "plan.waypoints": float(len(result.path)),
    }


def planned_joint_path(problem: PlanningProblem, result: PlanResult, method: str) -> JointPath:
    """``method``'s plan: the checked configurations along the plan's segments as a joint path.

    See the module docstring.
    """
    checker, task = problem.checker, problem.task
    rows = [result.path[0]]
    for a, b in zip(result.path[:-1], result.path[1:], strict=True):
        steps = checker.segment_steps(a, b)
        rows += list(a + np.arange(1, steps + 1)[:, None] / steps * (b - a))
    q = np.array(rows)
    N = len(q)
    poses = task.hand_poses(problem.joint_names, q, problem.fixed)
    hands = tuple(problem.areas)
    error = np.stack(
        [
            np.min(
                [
                    np.linalg.norm(displacement(a.carried_vector(poses[h]), a.bounds)[:, :3], axis=1)
                    for a in problem.areas[h]
                ],
                axis=0,
            )
            for h in hands
        ],
        axis=1,
    )
    return JointPath(
        method=method,
        joint_names=problem.joint_names,
        t=np.arange(N) * task.spec.control_period_s,
        rep=np.zeros(N, dtype=int),
        q=q,
        qd=np.zeros_like(q),
        status=np.zeros(N, dtype=int),
        solve_time_s=np.zeros(N),
        hand_error_m=error,
        hands=hands,
        fixed=problem.fixed,
    )

"""``dualarm bench plan``: MCIKRRT against OMPL's RRTConnect on one planning problem, in one process.

Both planners plan the same trials (seeds ``seed .. seed + trials - 1``) with the same collision
checker and goal sampler (:class:`~dualarm.plan.problem.PlanningProblem`), interleaved trial by
trial so that a slower or busier stretch of the machine falls on both. Besides the planning
times it reports the collision checks and the mean time of one check, so the ratio can be read
as checks times cost.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualarm.methods import PLANNERS
from dualarm.plan.problem import PlanningProblem, PlanningSettings
from dualarm.tasks import load_task


@dataclass(frozen=True)
class PlannerBench:
    """One planner's figures over the trials.

    Attributes:
        planner: the planner.
        success_rate: share of trials that found a path.
        median_s, p95_s, mean_s: planning time statistics over all trials [s].
        checks_median: collision checks per trial, median.
        check_time_s: mean time of one collision check [s].
        path_length_median_rad: smoothed path length of the successful trials, median [rad].
    """

    planner: str
    success_rate: float
    median_s: float
    p95_s: float
    mean_s: float
    checks_median: float
    check_time_s: float
    path_length_median_rad: float


def bench_plan(task_file: str | Path, trials: int, seed: int = 0, progress: Callable[[str], None] = lambda text: None) -> list[PlannerBench]:
    """Plan ``trials`` times with each of :data:`PLANNERS` on ``task_file``."""
    task = load_task(task_file)
    rows: dict[str, list] = {p: [] for p in PLANNERS}
    check_time = {p: [0.0, 0] for p in PLANNERS}
    with PlanningProblem(task, PlanningSettings()) as problem:
        for i in range(trials):
            for planner in PLANNERS:
                progress(f"{planner}, trial {i + 1}/{trials}")
                before_time, before_checks = problem.checker.check_time_s, problem.checker.checks
                rows[planner].append(problem.solve(planner, seed + i))
                check_time[planner][0] += problem.checker.check_time_s - before_time
                check_time[planner][1] += problem.checker.checks - before_checks
    out = []
    for planner, results in rows.items():
        times = np.array([r.planning_time_s for r in results])
        lengths = [r.path_length_rad for r in results if r.success]
        out.append(
            PlannerBench(
                planner=planner,
                success_rate=float(np.mean([r.success for r in results])),
                median_s=float(np.median(times)),
                p95_s=float(np.percentile(times, 95)),
                mean_s=float(times.mean()),
                checks_median=float(np.median([r.collision_checks for r in results])),
                check_time_s=check_time[planner][0] / max(check_time[planner][1], 1),
                path_length_median_rad=float(np.median(lengths)) if lengths else float("nan"),
            )
        )
    return out

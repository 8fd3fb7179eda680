"""``dualarm bench plan``: MCIKRRT against OMPL's RRTConnect on one planning problem, in one process.

Both planners plan the same trials (seeds ``seed .. seed + trials - 1``) with the same collision
checker and goal sampler (:class:`~dualarm.plan.problem.PlanningProblem`), interleaved trial by
trial so that a slower or busier stretch of the machine falls on both. Besides the planning
times it reports the collision checks and the mean time of one check, so the ratio can be read
as checks times cost.

The checkers are then timed on the same configurations: the reference
(:class:`~dualarm.plan.pybullet_checker.PyBulletChecker`, one configuration at a time, as the planners
checked before) and the planners' closed-form checker
(:class:`~dualarm.plan.collision.CollisionChecker`) one at a time, one edge at a time and all at
once. The configurations are those of planner-like edges: from a random configuration within the
limits, one Connect step (``step_rad``) toward another, its end and the configurations along it.
The rounds are interleaved and each row keeps its fastest; the two checkers' verdicts are compared
on every configuration.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualarm.methods import PLANNERS
from dualarm.plan.problem import PlanningProblem, PlanningSettings
from dualarm.plan.pybullet_checker import PyBulletChecker
from dualarm.tasks import load_task

#: Edges whose configurations the checkers are timed on, and the rounds of timing.
CHECKER_EDGES, CHECKER_ROUNDS = 200, 3


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


@dataclass(frozen=True)
class CheckerBench:
    """One checker's time of one collision check, on the configurations every row shares.

    Attributes:
        checker: ``pybullet`` (the reference) or ``closed form`` (the planners' checker).
        batch: how the configurations were given: ``one at a time``, ``one edge at a time`` or ``all at once``.
        batch_size: configurations per call (the median, for edges).
        check_time_s: time of one check, the fastest of the rounds [s].
    """

    checker: str
    batch: str
    batch_size: int
    check_time_s: float


@dataclass(frozen=True)
class PlanBench:
    """What ``dualarm bench plan`` measured.

    Attributes:
        planners: each planner's figures, in :data:`~dualarm.methods.PLANNERS` order.
        checkers: each checker's time per check, the reference first.
        configurations: configurations the checkers were timed on.
        disagreements: configurations on which the two checkers' verdicts differ.
    """

    planners: list[PlannerBench]
    checkers: list[CheckerBench]
    configurations: int
    disagreements: int


def bench_plan(
    task_file: str | Path, trials: int, seed: int = 0, progress: Callable[[str], None] = lambda text: None
) -> PlanBench:
    """Plan ``trials`` times with each of :data:`PLANNERS` on ``task_file``, then time the checkers."""
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
        progress("the checkers")
        checkers, edges, disagreements = bench_checkers(problem, np.random.default_rng(seed))
    planners = []
    for planner, results in rows.items():
        times = np.array([r.planning_time_s for r in results])
        lengths = [r.path_length_rad for r in results if r.success]
        planners.append(
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
    return PlanBench(planners, checkers, sum(len(e) for e in edges), disagreements)


def bench_checkers(
    problem: PlanningProblem, rng: np.random.Generator
) -> tuple[list[CheckerBench], list[np.ndarray], int]:
    """Time the reference and ``problem``'s checker on the same configurations, in interleaved rounds.

    The configurations of :data:`CHECKER_EDGES` planner-like edges (module docstring), over
    :data:`CHECKER_ROUNDS` interleaved rounds.

    Returns:
        the rows, the edges' configurations (each (k, n), its end first), and the configurations on
        which the verdicts differ.
    """
    checker, task, settings = problem.checker, problem.task, problem.settings
    step = settings.planner.step_rad
    edges = []
    for _ in range(CHECKER_EDGES):
        a, target = rng.uniform(problem.lower, problem.upper, (2, len(problem.lower)))
        b = a + (target - a) * min(1.0, step / np.linalg.norm(target - a))
        edges.append(np.vstack([b, checker.segment_configurations(a, b)]))
    Q = np.vstack(edges)
    with PyBulletChecker(
        task.robot,
        problem.joint_names,
        problem.fixed,
        task.spec.environment,
        task.spec.expected_contacts,
        settings.margin_m,
        settings.resolution_rad,
    ) as reference:
        runs: dict[tuple[str, str, int], Callable[[], object]] = {
            ("pybullet", "one at a time", 1): lambda: [reference.free(q) for q in Q],
            ("closed form", "one at a time", 1): lambda: [checker.free(q) for q in Q],
            ("closed form", "one edge at a time", int(np.median([len(e) for e in edges]))): lambda: [
                checker.free_many(e) for e in edges
            ],
            ("closed form", "all at once", len(Q)): lambda: checker.free_many(Q),
        }
        best = dict.fromkeys(runs, np.inf)
        for _ in range(CHECKER_ROUNDS):
            for key, run in runs.items():
                started = time.perf_counter()
                run()
                best[key] = min(best[key], (time.perf_counter() - started) / len(Q))
        disagreements = int((reference.free_many(Q) != checker.free_many(Q)).sum())
    return (
        [CheckerBench(name, batch, size, seconds) for (name, batch, size), seconds in best.items()],
        edges,
        disagreements,
    )

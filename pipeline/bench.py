"""``dualarm bench``: speed measured as ratios against peers run in the same process.

Never used by the test suite: wall-clock numbers depend on the machine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: TV-GDD section 4.2: average computing time per sampling interval and total, on the ball game [s].
PAPER_T_AVE_S = 0.001
PAPER_T_SUM_S = 1.12


@dataclass(frozen=True)
class BenchRow:
    """One measured solver.

    Attributes:
        name: what was measured.
        median_s: median time per step [s].
        p99_s: 99th percentile per step [s].
        total_s: time for the whole task [s].
        steps: control steps.
    """

    name: str
    median_s: float
    p99_s: float
    total_s: float
    steps: int


def bench_tvgdd(task_file: str | Path, repeats: int = 5, progress=None) -> list[BenchRow]:
    """TV-GDD on a task: the ``casadi`` backend per step, the same QP as one mapaccum rollout
    (best of ``repeats``), and the paper's LVI solver per step."""
    from pipeline.ik.stack import hand_stack, stacked_reference
    from pipeline.ik.tvgdd import build_problem, joint_bounds, settings_for, solve_tvgdd
    from pipeline.paths import build_reference
    from pipeline.tasks import load_task

    task = load_task(task_file)
    reference = build_reference(task)
    settings = settings_for(task)
    rows = []
    for backend in ("casadi", "lvi"):
        if progress:
            progress(f"TV-GDD, {backend} backend, per step")
        path = solve_tvgdd(task, reference, settings, backend)
        times = path.solve_time_s
        rows.append(BenchRow(f"{backend}, per step", float(np.median(times)), float(np.percentile(times, 99)), float(times.sum()), len(times)))
    if progress:
        progress("TV-GDD, casadi backend, whole path in one call")
    stack = hand_stack(task)
    problem = build_problem(stack, joint_bounds(task, stack), settings)
    R, V = stacked_reference(stack, reference)
    theta0 = stack.initial
    rollout = problem.rollout(len(reference))
    U = np.vstack([reference.t, R.T, V.T])
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        rollout(theta0, U, theta0)
        best = min(best, time.perf_counter() - start)
    n = len(reference)
    rows.append(BenchRow("casadi, one call", best / n, best / n, best, n))
    return rows
